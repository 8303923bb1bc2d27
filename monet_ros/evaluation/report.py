"""Result tables in the paper's shape (rows = modes, columns = datasets): Markdown and CSV."""
import csv
from dataclasses import dataclass, field
import io
import json
from pathlib import Path

import numpy as np

from monet_ros import json_text
from monet_ros.evaluation.pck import PCKResult

# The paper's rows, in its order.
MODE_ORDER = ('null', 'supervised', 'spatial', 'spatiotemporal', 'bootstrap1', 'bootstrap2',
              'monet', 'bootstrap2_epipolar', 'epipolar')
MODE_TITLES = {'null': 'Null (mean pose in the crop)', 'supervised': 'Supervised',
               'spatial': 'Spatial aug.', 'spatiotemporal': 'Spatiotemporal aug.',
               'bootstrap1': 'Bootstrapping I', 'bootstrap2': 'Bootstrapping II',
               'monet': 'MONET', 'bootstrap2_epipolar': 'Bootstrapping II + L_E (ablation)',
               'epipolar': 'Supervised + L_E (ablation)',
               'temporal_difference': 'Spatiotemporal + L_T (temporal difference)',
               'reprojection': 'Spatiotemporal + L_R (reprojection consistency)'}
REPORT_PCK = (0.05, 0.1, 0.2)


@dataclass(frozen=True)
class EvalSummary:
    """One model (mode) evaluated on one dataset.

    reprojection: consistency error (px) mean/std; gt_reprojection: error of the fused 3D
    reprojected vs ground-truth 2D (px); pck: PCKResult; extra: JSON-able details.
    """
    mode: str
    dataset: str
    reprojection_mean: float
    reprojection_std: float
    gt_reprojection_mean: float
    gt_reprojection_std: float
    pck: PCKResult
    instants: int
    extra: dict = field(default_factory=dict)

    def row(self):
        out = {'mode': self.mode, 'dataset': self.dataset, 'instants': self.instants,
               'reproj_mean_px': self.reprojection_mean, 'reproj_std_px': self.reprojection_std,
               'gt_reproj_mean_px': self.gt_reprojection_mean,
               'gt_reproj_std_px': self.gt_reprojection_std}
        for alpha in self.pck.thresholds:
            out[f'pck@{alpha:.2f}'] = self.pck.at(alpha)
        return out

    def to_json(self):
        data = {k: v for k, v in self.row().items()}
        data['pck'] = self.pck.as_dict()
        data['extra'] = self.extra
        return data

    @classmethod
    def from_json(cls, data):
        p = data['pck']
        names = tuple(p['per_keypoint'].keys())
        per_kp = np.array([p['per_keypoint'][n] for n in names], dtype=np.float64).T
        # null: a figure that was not finite (json_text writes NaN / inf as null)
        result = PCKResult(np.array(p['thresholds']), per_kp,
                           np.array(p['overall'], dtype=np.float64), np.array(p['counts']),
                           names)
        figures = [np.nan if data[k] is None else data[k] for k in (
            'reproj_mean_px', 'reproj_std_px', 'gt_reproj_mean_px', 'gt_reproj_std_px')]
        return cls(data['mode'], data['dataset'], *figures, result, int(data['instants']),
                   data.get('extra', {}))


def _ordered(values, order):
    known = [v for v in order if v in values]
    return known + sorted(v for v in values if v not in order)


def _fmt(mean, std, failures=None):
    """'mean ± std', with ' (+N failed)' when N errors beyond the image diagonal were left
    out (EvalSummary.extra *_failures)."""
    text = 'n/a' if not np.isfinite(mean) else f'{mean:.2f} ± {std:.2f}'
    return text + (f' (+{failures} failed)' if failures else '')


def markdown_table(summaries, pck_levels=REPORT_PCK):
    """Markdown table: one row per mode, per dataset the reprojection error (mean ± std px;
    '(+N failed)': errors beyond the image diagonal, left out), the ground-truth
    reprojection error and PCK at `pck_levels`."""
    modes = _ordered({s.mode for s in summaries}, MODE_ORDER)
    datasets = _ordered({s.dataset for s in summaries}, ())
    cell = {(s.mode, s.dataset): s for s in summaries}
    header = ['Mode']
    for d in datasets:
        header += [f'{d} reproj. (px)', f'{d} vs GT (px)']
        header += [f'{d} PCK@{a:g}' for a in pck_levels]
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    for m in modes:
        row = [MODE_TITLES.get(m, m)]
        for d in datasets:
            s = cell.get((m, d))
            if s is None:
                row += ['—'] * (2 + len(pck_levels))
                continue
            row += [_fmt(s.reprojection_mean, s.reprojection_std,
                         s.extra.get('reprojection_failures')),
                    _fmt(s.gt_reprojection_mean, s.gt_reprojection_std,
                         s.extra.get('gt_reprojection_failures'))]
            row += [f'{s.pck.at(a):.3f}' for a in pck_levels]
        lines.append('| ' + ' | '.join(row) + ' |')
    return '\n'.join(lines) + '\n'


def csv_table(summaries):
    """CSV text, one line per (mode, dataset), every PCK threshold as a column."""
    rows = [s.row() for s in summaries]
    if not rows:
        return ''
    fields = list(rows[0].keys())
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator='\n')
    writer.writeheader()
    for r in rows:
        writer.writerow({k: (f'{v:.6g}' if isinstance(v, float) else v) for k, v in r.items()})
    return buffer.getvalue()


def write_report(out_dir, summaries, name='results'):
    """Write <name>.md, <name>.csv, <name>.json and pck_<dataset>.png under out_dir.

    Returns a dict of the written paths."""
    from monet_ros.evaluation.plots import plot_pck_curves

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {'markdown': out / f'{name}.md', 'csv': out / f'{name}.csv',
             'json': out / f'{name}.json'}
    paths['markdown'].write_text(markdown_table(summaries))
    paths['csv'].write_text(csv_table(summaries))
    paths['json'].write_text(json_text.dumps([s.to_json() for s in summaries], indent=1))
    for dataset in _ordered({s.dataset for s in summaries}, ()):
        png = out / f'pck_{dataset}.png'
        plot_pck_curves([s for s in summaries if s.dataset == dataset], png,
                        title=f'PCK on {dataset}')
        paths[f'pck_{dataset}'] = png
    return paths


def load_summaries(path):
    return [EvalSummary.from_json(d) for d in json.loads(Path(path).read_text())]
