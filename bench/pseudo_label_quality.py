"""How good were the pseudo-labels a training run used? (needs synthetic ground truth)

For every run under OUT/runs/<dataset>/<mode> written by bench/accuracy.py, reads the final
pseudo-labels from trainer_state.pt and compares them with the ground-truth 2D keypoints of
OUT/data/<dataset>/ground_truth.npz on the unlabeled training instants: coverage (share of
views x keypoints with a pseudo-label), mean / median error (px), share of gross errors
(> --gross-px, e.g. a left/right swap) and the error on keypoints hidden by another limb.

    .venv/bin/python bench/pseudo_label_quality.py /tmp/monet_accuracy_full
"""
import argparse
from pathlib import Path
import sys

import numpy as np
import torch


def quality(pseudo, gt2d, occluded, labelled, train_instants, gross_px):
    """Figures of (T, V, C, 2) pseudo-labels against (T, V, C, 2) ground truth on the
    unlabeled training instants."""
    unlabeled = np.setdiff1d(train_instants, np.flatnonzero(labelled))
    p, g, occ = pseudo[unlabeled], gt2d[unlabeled], occluded[unlabeled]
    has = np.isfinite(p[..., 0]) & np.isfinite(g[..., 0])
    err = np.linalg.norm(p - g, axis=-1)[has]
    hidden = np.linalg.norm(p - g, axis=-1)[has & occ]
    return {'coverage': float(np.isfinite(p[..., 0]).mean()),
            'mean': float(err.mean()) if err.size else np.nan,
            'median': float(np.median(err)) if err.size else np.nan,
            'gross': float((err > gross_px).mean()) if err.size else np.nan,
            'hidden_mean': float(hidden.mean()) if hidden.size else np.nan}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('out', help='the --out folder of bench/accuracy.py')
    parser.add_argument('--gross-px', type=float, default=10.0)
    parser.add_argument('--eval-fraction', type=float, default=0.2,
                        help='held-out tail used by the runs (TrainConfig.eval_fraction)')
    args = parser.parse_args(argv)
    out = Path(args.out)
    states = sorted(out.glob('runs/*/*/trainer_state.pt'))
    if not states:
        print(f'{out}: no runs/*/*/trainer_state.pt', file=sys.stderr)
        return 1
    print(f'| dataset | mode | pseudo-labelled | mean error (px) | median (px) '
          f'| > {args.gross_px:g} px | hidden keypoints mean (px) |')
    print('|---|---|---|---|---|---|---|')
    for path in states:
        dataset, mode = path.parent.parent.name, path.parent.name
        truth = np.load(out / 'data' / dataset / 'ground_truth.npz')
        state = torch.load(path, map_location='cpu', weights_only=True)
        pseudo = state['pseudo'].numpy()
        T = pseudo.shape[0]
        n_eval = int(np.ceil(T * args.eval_fraction))
        q = quality(pseudo, truth['keypoints2d'], truth['occluded'], truth['labelled'],
                    np.arange(T - n_eval), args.gross_px)
        if q['coverage'] == 0:
            continue
        print(f'| {dataset} | {mode} | {100 * q["coverage"]:.1f}% | {q["mean"]:.2f} '
              f'| {q["median"]:.2f} | {100 * q["gross"]:.1f}% | {q["hidden_mean"]:.2f} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
