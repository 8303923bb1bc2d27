"""The paper's Table 1 on synthetic rigs, on a yardstick that can tell: every mode and an
image-blind null row, crops a deployed detector would have, ground-truth columns first.

For each synthetic rig (`monet synth`: a moving human, 14 keypoints, <1% labelled instants):
  1. the recording is rendered once per seed and decoded into memory;
  2. the labels of each labelled instant are kept in --label-views views only (chosen with
     the seed); the contiguous tail (--eval-fraction) is held out: never trained on, never
     tracked into. Labelled instants are printed as trained (those in the tail are not);
  3. every mode trains the same network from the same initialisation (seed) for the same
     number of steps and the same number of images per step, --jobs processes in parallel;
     training crops come from the labels and their spatiotemporal tracks (crop_rule,
     'pseudo_labels'), with independent per-view scale/shift jitter (+-15% / +-8%);
  4. each model, and the null detector (the mean labelled pose in the crop, whatever the
     image), is evaluated on the held-out instants with the live detector's crop rule
     (tracked: around the previous instant's fused 3D; `--eval-crop ground_truth` is the
     explicit, labelled benchmark option). Columns, ground truth first: 2D error against
     the projected ground truth (px mean, median), PCK@0.05/0.1/0.2 against it (fraction of
     the heatmap window), 3D error of the product's fusion (`monet process`'s fuse_heatmaps:
     outlier views excluded; mean, median, p90 mm, and the share it left untriangulated),
     3D error of the plain all-view triangulation (mm), reprojection error (px, agreement of
     the views, not accuracy). A cell where a mode does not beat the null
     row is marked with a dagger.
  5. with several seeds: mean ± std over seeds, and MONET paired with every baseline (per-seed
     ratio baseline / MONET, and on how many seeds MONET is better).

Forms (the lead runs the real figures; see bench/results/accuracy.md):
  quick: 1 rig, 120 instants, 40 steps, 3 modes: runs end to end in about a minute (an
      end-to-end check only: 40 steps do not beat the null row)
      .venv/bin/python bench/accuracy.py --quick --out /tmp/acc_quick
  reduced (default): ring8 + dome5, 240 instants, 300 steps, seed 0, small net 64 px
      (16x16 heatmaps, sigma 1 heatmap px = about 14 image px)
      .venv/bin/python bench/accuracy.py --out /tmp/monet_accuracy
  full: ring8 + dome5 (non-coplanar, 5 cameras, occluders), 1500 instants, 3000 steps,
      seeds 0 1 2, small net 184 px -> 46x46 heatmaps (the paper's), sigma 1 heatmap px
      (about 5 image px)
      .venv/bin/python bench/accuracy.py --full --out /tmp/monet_accuracy_full
  on CUDA: bench/accuracy_gpu.sh (the full form, --jobs for one large GPU).
Tuning is done on seeds that are not reported (use --seeds 100 101 for tuning runs).
Variants side by side: --set KEY=VALUE (any TrainConfig field) with --tag NAME --merge.
"""
import argparse
from concurrent.futures import ProcessPoolExecutor
import json
import multiprocessing
import os
from pathlib import Path
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from monet_ros.cli import main as monet_main  # noqa: E402
from monet_ros.evaluation import write_report  # noqa: E402
from monet_ros.evaluation.report import MODE_TITLES  # noqa: E402
from monet_ros.learning.config import MODES, TrainConfig  # noqa: E402

# Rigs: different camera count, layout, image size and field of view (intrinsics). ring
# rigs have every centre at about head height (epipolar lines of the upper body nearly
# parallel: the paper's degenerate case); the dome rigs are non-coplanar.
RIGS = {
    'ring8': ['--cameras', '8', '--layout', 'ring', '--width', '320', '--height', '240',
              '--hfov', '60'],
    'dome6': ['--cameras', '6', '--layout', 'dome', '--width', '288', '--height', '224',
              '--hfov', '75'],
    # non-coplanar, few views, two pillars hiding legs from some views
    'dome5': ['--cameras', '5', '--layout', 'dome', '--width', '320', '--height', '240',
              '--hfov', '70', '--occluders', '2'],
    # non-coplanar ring (centres 0.4-0.8 m above / below head height), left/right limbs in
    # their own colours (bootstrapping's symmetric ambiguity removed)
    'ring6h': ['--cameras', '6', '--layout', 'ring', '--width', '320', '--height', '240',
               '--hfov', '60', '--height-spread', '0.8', '--distinct-sides'],
    # ring6h with the two pillars of dome5 (issue 22's rig): non-coplanar, distinct sides,
    # occluders
    'ring6ho': ['--cameras', '6', '--layout', 'ring', '--width', '320', '--height', '240',
                '--hfov', '60', '--height-spread', '0.8', '--distinct-sides',
                '--occluders', '2'],
    # few views: RANSAC bootstrapping needs 3 agreeing views of 4, so it labels less
    'ring4': ['--cameras', '4', '--layout', 'ring', '--width', '320', '--height', '240',
              '--hfov', '60'],
}
DEFAULT_RIGS = ['ring8', 'dome5']
ALL_MODES = ['null'] + list(MODES)
QUICK = dict(frames=120, label_fraction=0.02, steps=40, seeds=[0], input_size=64,
             sigma=1.0, rigs=['dome5'], modes=['null', 'supervised', 'monet'])
REDUCED = dict(frames=240, label_fraction=0.008, steps=300, seeds=[0], input_size=64,
               sigma=1.0, rigs=DEFAULT_RIGS, modes=ALL_MODES)
FULL = dict(frames=1500, label_fraction=0.004, steps=3000, seeds=[0, 1, 2], input_size=184,
            sigma=1.0, rigs=DEFAULT_RIGS, modes=ALL_MODES)
# ground-truth columns first: (key, title, format, lower is better)
COLUMNS = (('error2d_mean', '2D err. (px)', '.2f', True),
           ('error2d_median', '2D med. (px)', '.2f', True),
           ('pck@0.05', 'PCK@0.05', '.3f', False), ('pck@0.1', 'PCK@0.1', '.3f', False),
           ('pck@0.2', 'PCK@0.2', '.3f', False),
           ('fused3d_mm', '3D fused (mm)', '.0f', True),
           ('fused3d_median_mm', '3D fused med. (mm)', '.0f', True),
           ('fused3d_p90_mm', '3D fused p90 (mm)', '.0f', True),
           ('fused3d_missing', 'untriangulated', '.3f', True),
           ('error3d_mm', '3D all-view DLT (mm)', '.0f', True),
           ('reprojection', 'reproj. (px)', '.2f', True))

_DATA = {}          # rig -> TrainingData inputs, filled before forking
_ORACLE = []        # [True]: --pseudo-oracle (a diagnostic control, see oracle_pseudo_labels)
EVAL_FRACTION = 0.2  # the held-out tail of every recording (evaluation only, never trained)


def synthesise(out, name, rig, frames, label_fraction, seed):
    folder = Path(out) / 'data' / name
    if not (folder / 'ground_truth.npz').exists():
        code = monet_main(['synth', '--out', str(folder), '--frames', str(frames),
                           '--label-fraction', str(label_fraction), '--seed', str(seed),
                           '--quiet', *RIGS[rig]])
        if code:
            raise SystemExit(f'monet synth failed for {rig}')
    return folder


def keep_label_views(recording, count, seed):
    """Keep the labels of `count` random views per labelled instant (0 = all views)."""
    if count <= 0:
        return []
    rng = np.random.default_rng(seed)
    kept = []
    for t in recording.labelled_instants:
        views = np.sort(rng.choice(recording.num_views, size=count, replace=False))
        drop = np.setdiff1d(np.arange(recording.num_views), views)
        recording.labels[t, drop] = np.nan
        kept.append([int(t), views.tolist()])
    return kept


def train_and_evaluate(job):
    """Worker: train one mode (or build the null detector) on one dataset, evaluate on the
    held-out tail with the eval crop rule -> summary JSON."""
    import torch

    from monet_ros.evaluation.evaluate import evaluate_detector
    from monet_ros.evaluation.null_detector import null_detector
    from monet_ros.learning.trainer import Trainer, TrainingData
    from monet_ros.models import build_model
    from monet_ros.models.detector import Detector

    torch.set_num_threads(1)
    rig, mode, config_dict, out, tag, eval_crop = job
    config = TrainConfig.from_dict(config_dict)
    recording = _DATA[rig]          # rig = the dataset name (rig, or rig-sSEED)
    probe = build_model(config.architecture, recording.num_keypoints, **config.model_options())
    data = TrainingData(recording, config, probe.input_size, probe.heatmap_size)
    start = time.monotonic()
    label = mode + (f'+{tag}' if tag else '')
    extra = {}
    if mode == 'null':
        detector = null_detector(data, config.sigma, device=config.device
                                 if config.device != 'auto' else None)
        summary = {'steps': 0, 'pseudo_labels': 0, 'last': {}}
    else:
        trainer = Trainer(config, data, Path(out) / 'runs' / rig / label)
        if trainer.pseudo_label_count and recording.gt3d is not None:
            extra['pseudo_label_precision'] = pseudo_label_precision(trainer, recording)
        if _ORACLE:
            oracle_pseudo_labels(trainer, recording)
        extra['pseudo_labels_initial'] = trainer.pseudo_label_count
        # share of the unlabeled train views x keypoints pseudo-labelled at the start
        extra['pseudo_label_coverage'] = trainer.pseudo_label_coverage
        if config.distill_rounds:     # as `monet train --distill-rounds` runs them
            from monet_ros.commands.train_distill import train_with_distillation
            from monet_ros.learning.distill import label_errors
            folder = Path(out) / 'data' / rig
            summary = train_with_distillation(
                trainer, folder / 'recording', rig=folder / 'rig.yaml', skeleton='human14',
                progress=False, say=lambda line: print(f'[{rig} {label}] {line}',
                                                       file=sys.stderr, flush=True))
            # the last round's pseudo-labels against the projected ground truth
            _, truth = pseudo_label_truth(trainer, recording)
            extra['distill'] = summary['distill']
            extra['distill_precision'] = label_errors(trainer.distilled, truth)
            print(f'[{rig} {label}] distilled pseudo-labels vs ground truth: '
                  f'{extra["distill_precision"]}', file=sys.stderr, flush=True)
        else:
            summary = trainer.run(progress=False)
        extra['images_per_step'] = int(sum(len(p[1]) for p in trainer._batch_plan()))
        detector = Detector(trainer.model, trainer.metadata(), device=trainer.device)
    train_s = time.monotonic() - start
    boxes = data.boxes
    if eval_crop == 'ground_truth':
        from monet_ros.crop_rule import recording_boxes
        h, w = detector.input_size
        boxes = recording_boxes(recording, 'ground_truth', w / h, config.box_margin)
    result = evaluate_detector(detector, recording, data.held_out, boxes, label, rig,
                               crop='boxes' if eval_crop == 'ground_truth' else 'tracked')
    if eval_crop == 'tracked':
        # detection quality beside the product's figure: the same model on ground-truth crops
        from monet_ros.crop_rule import recording_boxes
        h, w = detector.input_size
        gt_boxes = recording_boxes(recording, 'ground_truth', w / h, config.box_margin)
        gt = evaluate_detector(detector, recording, data.held_out, gt_boxes, label, rig,
                               crop='boxes')
        extra['gt_crop'] = {k: gt.extra[k] for k in ('error2d_mean', 'error2d_median',
                                                     'error3d_mean', 'error3d_median',
                                                     'fused3d_mean', 'fused3d_median',
                                                     'fused3d_p90', 'fused3d_missing',
                                                     'mean_confidence')}
        extra['gt_crop']['pck@0.1'] = gt.pck.at(0.1)
    if mode != 'null':
        extra['fit'] = summary.get('fit')
        extra['labelled_peak_median'] = float(np.median(trainer.labelled_peaks()))
    result.extra.update(extra)
    result.extra.update({'train_seconds': round(train_s, 1), 'steps': summary['steps'],
                         'pseudo_labels_final': summary['pseudo_labels'],
                         'labelled_instants_trained': int(len(data.labelled_instants)),
                         'eval_crop': eval_crop, 'seed': config.seed, 'eval_seconds':
                         round(time.monotonic() - start - train_s, 1),
                         'last_terms': summary['last'], 'config': config.to_dict()})
    print(f'[{rig} {label}] {summary["steps"]} steps in {train_s:.0f} s, 2D error '
          f'{result.extra["error2d_mean"]:.2f} px, PCK@0.1 {result.pck.at(0.1):.3f}, 3D fused '
          f'{1000 * result.extra["fused3d_mean"]:.1f} mm, reproj {result.reprojection_mean:.2f} '
          'px', file=sys.stderr, flush=True)
    return result.to_json()


def pseudo_label_truth(trainer, recording):
    """((T, V, C) bool cells holding a pseudo-label (not a label), (T, V, C, 2) projected
    ground truth): the cells L_B trains on and their true positions."""
    from monet_ros.learning.pseudo_labels import project_to_views

    T, V, C = recording.num_instants, recording.num_views, recording.num_keypoints
    truth = project_to_views(recording.gt3d.reshape(-1, 3), recording.cameras)
    truth = truth.reshape(V, T, C, 2).transpose(1, 0, 2, 3)
    cells = np.isfinite(trainer.pseudo[..., 0]) & ~np.isfinite(trainer.data.labels[..., 0])
    return cells, truth


def pseudo_label_precision(trainer, recording):
    """Pseudo-labels against the ground truth: cells, error median (px), share beyond 10 and
    20 px (cells whose truth projects outside the image are left out)."""
    cells, truth = pseudo_label_truth(trainer, recording)
    err = np.linalg.norm(trainer.pseudo - truth, axis=-1)[cells & np.isfinite(truth[..., 0])]
    if not err.size:
        return {'cells': 0}
    out = {'cells': int(cells.sum()), 'median_px': float(np.median(err)),
           'beyond10': float((err > 10).mean()), 'beyond20': float((err > 20).mean())}
    if trainer.spec.temporal:
        # the 3D points the tracked labels project: their 2D errors are consistent across
        # views, so a small 2D error can be a large 3D one
        used = cells.any(axis=1)                                              # (T, C)
        e3 = np.linalg.norm(trainer.data.tracks().points3d - recording.gt3d, axis=-1)
        e3 = e3[used & np.isfinite(e3)]
        if e3.size:
            out.update(median3d_mm=1000 * float(np.median(e3)),
                       mean3d_mm=1000 * float(e3.mean()))
    return out


def oracle_pseudo_labels(trainer, recording):
    """Diagnostic control (--pseudo-oracle): every pseudo-label replaced by the projected
    ground truth of the same (instant, view, keypoint) cell: the same cells, crops and batch
    plans, what L_B would give with noise-free labels."""
    cells, truth = pseudo_label_truth(trainer, recording)
    keep = cells & np.isfinite(truth[..., 0])
    trainer.pseudo = np.where(keep[..., None], truth, trainer.pseudo)
    trainer._update_pools()


def value(summary, key):
    """A column's value of an EvalSummary (see COLUMNS)."""
    if key.startswith('pck@'):
        return summary.pck.at(float(key[4:]))
    if key == 'error3d_mm':
        return 1000 * summary.extra['error3d_mean']
    if key == 'error3d_median_mm':
        return 1000 * summary.extra['error3d_median']
    if key.startswith('fused3d_') and key.endswith('_mm'):
        name = 'fused3d_' + (key[8:-3] or 'mean') if key != 'fused3d_mm' else 'fused3d_mean'
        return 1000 * summary.extra.get(name, float('nan'))
    if key == 'reprojection':
        return summary.reprojection_mean
    return summary.extra[key]


def shown(v, fmt):
    """A cell: the value, or '> 1e4' for an absurd one (an image-blind detector's mean
    reprojection error is dominated by a few points triangulated next to a camera centre)."""
    return '> 1e4' if abs(v) > 1e4 else f'{v:{fmt}}'


def beats(a, b, lower):
    return a < b if lower else a > b


def result_table(summaries):
    """Markdown: one row per (dataset, mode), ground-truth columns first; a dagger marks a
    cell that does not beat the null row of its dataset."""
    null = {s.dataset: s for s in summaries if s.mode.split('+')[0] == 'null'}
    lines = ['| dataset | mode | ' + ' | '.join(c[1] for c in COLUMNS)
             + ' | labelled instants trained | pseudo-labelled | images/step | train s |',
             '|---|---|' + '---|' * (len(COLUMNS) + 4)]
    for s in summaries:
        cells = []
        for key, _, fmt, lower in COLUMNS:
            v = value(s, key)
            mark = ''
            if s.dataset in null and s is not null[s.dataset] and not beats(
                    v, value(null[s.dataset], key), lower):
                mark = ' †'
            cells.append(f'{shown(v, fmt)}{mark}')
        e = s.extra
        lines.append(f'| {s.dataset} | {MODE_TITLES.get(s.mode, s.mode)} | '
                     + ' | '.join(cells)
                     + f' | {e.get("labelled_instants_trained", "")} '
                     f'| {100 * e.get("pseudo_label_coverage", 0):.0f}% '
                     f'| {e.get("images_per_step", "-")} | {e.get("train_seconds", 0):.0f} |')
    lines.append('\n† = not better than the null row (mean pose in the crop) of that dataset.')
    return '\n'.join(lines)


def parse_overrides(pairs):
    """--set KEY=VALUE pairs -> dict of TrainConfig fields (values parsed as YAML scalars)."""
    import yaml

    known = set(TrainConfig.__dataclass_fields__)
    overrides = {}
    for pair in pairs:
        key, sep, value = pair.partition('=')
        if not sep or key not in known:
            raise SystemExit(f'--set {pair!r}: expected KEY=VALUE with KEY a TrainConfig field '
                             f'(one of {sorted(known)})')
        overrides[key] = yaml.safe_load(value)
    return overrides


def dataset_name(rig, seed, seeds):
    return rig if len(seeds) == 1 else f'{rig}-s{seed}'


def across_seeds(summaries, rigs, seeds):
    """Markdown: per rig, mean ± std over seeds of every column per mode (dagger: the mean
    does not beat the null row's), then MONET paired with every baseline per seed."""
    cell = {(s.mode, s.dataset): s for s in summaries}
    present = {s.mode for s in summaries}
    modes = [m for m in ALL_MODES if m in present] + sorted(present - set(ALL_MODES))
    lines = []
    for rig in rigs:
        names = [dataset_name(rig, seed, seeds) for seed in seeds]
        complete = [n for n in names if all((m, n) in cell for m in modes)]
        if not complete:
            continue
        lines += [f'### {rig}: {len(complete)} seeds (mean ± std over seeds)', '',
                  '| Mode | ' + ' | '.join(c[1] for c in COLUMNS) + ' |',
                  '|---|' + '---|' * len(COLUMNS)]
        means = {m: {key: np.mean([value(cell[(m, n)], key) for n in complete])
                     for key, *_ in COLUMNS} for m in modes}
        for m in modes:
            cells = []
            for key, _, fmt, lower in COLUMNS:
                v = np.array([value(cell[(m, n)], key) for n in complete])
                mark = (' †' if 'null' in means and m != 'null'
                        and not beats(v.mean(), means['null'][key], lower) else '')
                cells.append(f'{shown(v.mean(), fmt)} ± {shown(v.std(), fmt)}{mark}')
            lines.append(f'| {MODE_TITLES.get(m, m)} | ' + ' | '.join(cells) + ' |')
        lines.append('')
        if 'monet' in modes:
            lines += [f'#### {rig}: MONET paired with each baseline, per seed '
                      '(ratio baseline / MONET for errors, MONET / baseline for PCK: > 1 = '
                      'MONET better; wins = seeds where MONET is better)', '',
                      '| baseline | ' + ' | '.join(c[1] for c in COLUMNS) + ' |',
                      '|---|' + '---|' * len(COLUMNS)]
            for m in modes:
                if m == 'monet':
                    continue
                cells = []
                for key, _, _, lower in COLUMNS:
                    ours = np.array([value(cell[('monet', n)], key) for n in complete])
                    theirs = np.array([value(cell[(m, n)], key) for n in complete])
                    ratio = theirs / ours if lower else ours / theirs
                    wins = int(sum(beats(o, t, lower) for o, t in zip(ours, theirs)))
                    cells.append(' '.join(shown(r, '.2f') for r in ratio)
                                 + f' ({wins}/{len(complete)})')
                lines.append(f'| {MODE_TITLES.get(m, m)} | ' + ' | '.join(cells) + ' |')
            lines.append('')
    return '\n'.join(lines)


def report_only(out):
    """Tables of an earlier run from OUT/results.json and OUT/bench_meta.json."""
    from monet_ros.evaluation import load_summaries

    try:
        summaries = load_summaries(out / 'results.json')
        meta = json.loads((out / 'bench_meta.json').read_text())
    except (OSError, ValueError) as error:
        print(f'accuracy: {out}: no earlier run to report ({error})', file=sys.stderr)
        return 2
    paths = write_report(out, summaries, name='results')
    print(f'## Held-out figures of `{meta["command"]}` (eval crops: {meta["eval_crop"]})\n')
    print(result_table(summaries))
    seeds = meta['seeds']
    if len(seeds) > 1:
        aggregate = across_seeds(summaries, meta['preset']['rigs'], seeds)
        (out / 'across_seeds.md').write_text(aggregate)
        print('\n' + aggregate)
    print(f'\nwritten {", ".join(str(p) for p in paths.values())}')
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', default='/tmp/monet_accuracy')
    form = parser.add_mutually_exclusive_group()
    form.add_argument('--full', action='store_true', help='the full benchmark (long)')
    form.add_argument('--quick', action='store_true',
                      help='a minute end to end: 1 rig, 120 instants, 40 steps, 3 modes')
    parser.add_argument('--rigs', nargs='+', default=None, choices=list(RIGS))
    parser.add_argument('--modes', nargs='+', default=None, choices=ALL_MODES)
    parser.add_argument('--steps', type=int, default=0, help='override the step budget')
    parser.add_argument('--frames', type=int, default=0, help='override the frame count')
    parser.add_argument('--label-fraction', type=float, default=0.0,
                        help='override the labelled share of the instants')
    parser.add_argument('--label-views', type=int, default=3,
                        help='labelled views per labelled instant (0 = all)')
    parser.add_argument('--seeds', nargs='+', type=int, default=None,
                        help="seeds (scene, labels, initialisation); default: the preset's")
    parser.add_argument('--jobs', type=int, default=2, help='parallel training processes')
    parser.add_argument('--input-size', type=int, default=0,
                        help="network input side (default: the preset's; 184 -> 46x46 "
                        'heatmaps)')
    parser.add_argument('--sigma', type=float, default=0.0,
                        help="target sigma in heatmap px (default: the preset's)")
    parser.add_argument('--width', type=int, default=24)
    parser.add_argument('--lr', type=float, default=1e-3)
    parser.add_argument('--device', default='auto')
    parser.add_argument('--eval-crop', choices=('tracked', 'ground_truth'), default='tracked',
                        help="evaluation crops: the live detector's tracked rule (default) or "
                        'ground-truth boxes (a benchmark option, labelled in the output)')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE', help='any TrainConfig field, for every mode')
    parser.add_argument('--tag', default='',
                        help='suffix of the mode names (rows "MODE+TAG"): variants side by side '
                        'with --merge')
    parser.add_argument('--merge', action='store_true',
                        help='keep the (mode, dataset) results of OUT/results.json not rerun now')
    parser.add_argument('--pseudo-oracle', action='store_true',
                        help='diagnostic control: pseudo-labels replaced by the projected '
                        'ground truth on the same cells (use with --tag oracle)')
    parser.add_argument('--report', action='store_true',
                        help='train nothing: the tables again from OUT/results.json (and the '
                        'rigs and seeds of OUT/bench_meta.json)')
    args = parser.parse_args(argv)
    if args.report:
        return report_only(Path(args.out))
    preset = dict(FULL if args.full else QUICK if args.quick else REDUCED)
    for key in ('steps', 'frames', 'label_fraction', 'input_size', 'sigma', 'rigs', 'modes'):
        if getattr(args, key):
            preset[key] = getattr(args, key)
    seeds = args.seeds if args.seeds is not None else preset['seeds']
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    wall = time.monotonic()

    from monet_ros.learning.recording import load_recording
    from monet_ros.learning.trainer import split_instants

    overrides = parse_overrides(args.overrides)
    if args.pseudo_oracle:
        _ORACLE.append(True)
    # the held-out tail every mode is evaluated on (base below): labelled instants in it are
    # not trained, and the counts printed here are those trained
    eval_fraction = overrides.get('eval_fraction', EVAL_FRACTION)
    setup = {}
    for seed in seeds:
        for rig in preset['rigs']:
            name = dataset_name(rig, seed, seeds)
            folder = synthesise(out, name, rig, preset['frames'], preset['label_fraction'],
                                seed)
            recording = load_recording(folder, name=name)
            labelled_all = recording.labelled_instants.tolist()
            train, _ = split_instants(recording.num_instants, eval_fraction)
            trained = [t for t in labelled_all if t <= train[-1]]
            kept = keep_label_views(recording, args.label_views, seed)
            _DATA[name] = recording
            setup[name] = {'folder': str(folder), 'seed': seed,
                           'instants': recording.num_instants, 'views': recording.num_views,
                           'labelled_instants': labelled_all,
                           'labelled_instants_trained': trained,
                           'labelled_fraction_trained': len(trained) / len(train),
                           'label_views_kept': kept}
            print(f'{name}: {recording.num_instants} instants x {recording.num_views} views; '
                  f'labelled instants trained: {len(trained)} {trained} of {len(train)} '
                  f'training instants ({100 * len(trained) / len(train):.2f}%); '
                  f'{len(labelled_all) - len(trained)} more fall in the held-out tail and are '
                  'not trained', file=sys.stderr)
    base = dict(architecture='small', input_size=preset['input_size'], width=args.width,
                steps=preset['steps'], checkpoint_every=preset['steps'], lr=args.lr,
                device=args.device, sigma=preset['sigma'], eval_fraction=EVAL_FRACTION)
    base.update(overrides)
    jobs = [(name, mode, TrainConfig(mode='supervised' if mode == 'null' else mode,
                                     **dict(base, seed=setup[name]['seed'])).to_dict(),
             str(out), args.tag, args.eval_crop)
            for name in setup for mode in preset['modes']]
    context = multiprocessing.get_context('fork')
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=context) as pool:
        results = list(pool.map(train_and_evaluate, jobs))
    from monet_ros.evaluation import EvalSummary
    summaries = [EvalSummary.from_json(r) for r in results]
    previous = out / 'results.json'
    if args.merge and previous.exists():
        from monet_ros.evaluation import load_summaries
        rerun = {(s.mode, s.dataset) for s in summaries}
        summaries = [s for s in load_summaries(previous)
                     if (s.mode, s.dataset) not in rerun] + summaries
    wall = time.monotonic() - wall
    paths = write_report(out, summaries, name='results')
    heat = TrainConfig(**dict(base, mode='supervised')).model_options()
    print(f'## Held-out figures (eval crops: {args.eval_crop}; input {preset["input_size"]} px,'
          f' sigma {preset["sigma"]} heatmap px; {heat})\n')
    print(result_table(summaries))
    if len(seeds) > 1:
        aggregate = across_seeds(summaries, preset['rigs'], seeds)
        (out / 'across_seeds.md').write_text(aggregate)
        print('\n' + aggregate)
    command = 'bench/accuracy.py ' + ' '.join(sys.argv[1:] if argv is None else argv)
    meta = {'command': command, 'wall_seconds': round(wall, 1), 'preset': preset,
            'label_views': args.label_views, 'seeds': seeds, 'jobs': args.jobs,
            'eval_crop': args.eval_crop, 'config': base, 'datasets': setup,
            'cpu_count': os.cpu_count(), 'load_average': os.getloadavg()}
    (out / 'bench_meta.json').write_text(json.dumps(meta, indent=1))
    print(f'\nwall time {wall:.0f} s ({args.jobs} jobs, load average '
          f'{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores); seeds {seeds}; '
          f'written {", ".join(str(p) for p in paths.values())}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
