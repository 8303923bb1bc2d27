"""Per-seed paired table of a bench/accuracy.py output: every row against a baseline row.

For each (mode[+tag]) row and seed: 2D error against the ground truth (px mean) with the
live tracked crops and with ground-truth crops, 3D error of the product's fusion (mm mean and
p90, tracked crops: `monet process`'s fuse_heatmaps; older results without it: '–'), of the
plain all-view triangulation, and of the fusion on ground-truth crops, the
detector's median heatmap peak on its labelled views and its fit to them; then the mean
over seeds and, paired per seed, the difference to --baseline (negative = better) and on
how many seeds the row beats it.

usage: python bench/accuracy_paired.py OUT [--baseline supervised] [--control ROW=CONTROL]
       [--plot PNG] [--rows ROW ...]     (PNG: per-seed bars of the first three columns)
"""
import argparse
import json
from pathlib import Path
import sys

import numpy as np


def _mm(value):
    return None if value is None else 1000 * value


# the first PAIRED columns are also compared per seed
FIELDS = (('tracked 2D (px)', lambda e: e['error2d_mean']),
          ('GT-crop 2D (px)', lambda e: e.get('gt_crop', {}).get('error2d_mean')),
          ('3D fused (mm)', lambda e: _mm(e.get('fused3d_mean'))),
          ('3D fused p90 (mm)', lambda e: _mm(e.get('fused3d_p90'))),
          ('3D all-view DLT (mm)', lambda e: 1000 * e['error3d_mean']),
          ('GT-crop 3D fused (mm)', lambda e: _mm(e.get('gt_crop', {}).get('fused3d_mean'))))
PAIRED = 4


def load(out):
    rows = {}
    for r in json.loads((Path(out) / 'results.json').read_text()):
        rows.setdefault(r['mode'], {})[r['dataset']] = r['extra']
    return rows


def _diff(a, b):
    return np.nan if a is None or b is None else a - b


def _precision_text(p):
    text = (f'{p["cells"]} cells, median {p["median_px"]:.2f} px, '
            f'{100 * p["beyond10"]:.1f}% beyond 10 px')
    if 'median3d_mm' in p:
        text += f', their 3D points median {p["median3d_mm"]:.0f} mm'
    return text


def cell(values):
    v = [x for x in values if x is not None]
    return ' / '.join(f'{x:.1f}' for x in v) if v else '–'


def table(rows, baseline, controls):
    datasets = sorted({d for r in rows.values() for d in r})
    lines = [f'Seeds (datasets): {", ".join(datasets)}. Cells: per seed, then mean; '
             f'paired: mean of (row - {baseline}) per seed and seeds where the row is better.',
             '', '| row | ' + ' | '.join(name for name, _ in FIELDS) +
             f' | paired vs {baseline}: ' + ', '.join(n for n, _ in FIELDS[:PAIRED]) +
             ' | labelled peak | '
             'fit (heat px) |',
             '|---' * (len(FIELDS) + 4) + '|']
    for mode in rows:
        cells = []
        for _, get in FIELDS:
            vals = [get(rows[mode][d]) if d in rows[mode] else None for d in datasets]
            known = [v for v in vals if v is not None]
            cells.append(f'{cell(vals)} (mean {np.mean(known):.1f})' if known else '–')
        paired = []
        for _, get in FIELDS[:PAIRED]:
            diffs = [get(rows[mode][d]) - get(rows[baseline][d]) for d in datasets
                     if d in rows[mode] and d in rows.get(baseline, {})
                     and get(rows[mode][d]) is not None and get(rows[baseline][d]) is not None]
            paired.append(f'{np.mean(diffs):+.1f} ({sum(x < 0 for x in diffs)}/{len(diffs)})'
                          if diffs and mode != baseline else '–')
        peak = [rows[mode][d].get('labelled_peak_median') for d in datasets if d in rows[mode]]
        fit = [(rows[mode][d].get('fit') or {}).get('median_heat') for d in datasets
               if d in rows[mode]]
        lines.append(f'| {mode} | ' + ' | '.join(cells) + f' | {", ".join(paired)} | '
                     f'{cell(peak and [p for p in peak if p is not None])} | '
                     f'{cell(fit and [f for f in fit if f is not None])} |')
    for mode in rows:
        precision = [rows[mode][d].get('pseudo_label_precision') for d in datasets
                     if d in rows[mode]]
        precision = [p for p in precision if p and p.get('cells')]
        if precision:
            lines.append(f'\n{mode}: pseudo-labels against the ground truth, per seed: '
                         + '; '.join(_precision_text(p) for p in precision))
    for row, control in controls:
        if row not in rows or control not in rows:
            continue
        diffs = [[_diff(get(rows[row][d]), get(rows[control][d])) for _, get in
                  FIELDS[:PAIRED]] for d in datasets if d in rows[row] and d in rows[control]]
        diffs = np.array(diffs, dtype=float)
        lines.append(f'\n{row} vs its exact control {control} (same batch plan), paired: '
                     + ', '.join(f'{name} {np.nanmean(diffs[:, k]):+.1f} '
                                 f'({int((diffs[:, k] < 0).sum())}/{len(diffs)} better)'
                                 for k, (name, _) in enumerate(FIELDS[:PAIRED])))
    return '\n'.join(lines)


def plot(rows, path, names=None):
    """PNG: one panel per column of FIELDS[:3], a bar per (row, seed)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    names = names or [m for m in rows if m.split('+')[0] != 'null']
    datasets = sorted({d for r in rows.values() for d in r})
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    width = 0.8 / len(datasets)
    for ax, (title, get) in zip(axes, FIELDS[:3]):
        for k, d in enumerate(datasets):
            vals = [get(rows[m][d]) if d in rows[m] else np.nan for m in names]
            ax.bar(np.arange(len(names)) + (k - (len(datasets) - 1) / 2) * width, vals, width,
                   label=d)
        ax.set_xticks(np.arange(len(names)), names, rotation=20, ha='right', fontsize=8)
        ax.set_title(f'{title}, lower is better', fontsize=9)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('out')
    parser.add_argument('--baseline', default='supervised')
    parser.add_argument('--control', action='append', default=[], metavar='ROW=CONTROL')
    parser.add_argument('--plot', default=None, metavar='PNG')
    parser.add_argument('--rows', nargs='+', default=None, help='rows of the plot, in order')
    args = parser.parse_args(argv)
    controls = [tuple(c.split('=', 1)) for c in args.control]
    rows = load(args.out)
    print(table(rows, args.baseline, controls))
    if args.plot:
        plot(rows, args.plot, args.rows)
        print(f'\nwritten {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
