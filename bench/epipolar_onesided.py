"""Issue 36 item 1: which one-sided, anchored L_E, (a) the paper's rectified row-max
divergence made one-sided or (b) the robust point-to-epipolar-line distance of the
soft-argmax (learning.losses.epipolar_loss, the trainer's L_E), measured on the same
descents.

Each candidate is descended alone on free Gaussian centres (sigma 2 heatmap px, peak = the
view's confidence) of B instants x 14 keypoints in 6 views of a non-coplanar ring (the
scenes of test/learning/test_epipolar_anchored.py), Adam lr 0.1, --steps steps:
  mixed      3 accurate views (0.5 px noise, peaks 1 / 0.95 / 0.9) and 3 poor ones (3 px,
             peak 0.6)
  outlier    every view 0.5 px off, view 3 8 px off (peak 0.6)
  collapsed  the 3 poor views start with every keypoint on the projection of the body's
             centroid (a configuration consistent across views)
(a) and (b) use the same anchors and pairs (anchored_epipolar_terms: anchors are confident
views that agree; gradient only into the less confident view); (a) is the KL divergence of
the target view's rectified row-max distribution from the anchor's detached one
(learning.epipolar's rectification, grid capped at --grid), weighted like (b).
Reported: mean / median error (heatmap px) of the poor views and the mean of the accurate
ones before and after, the accurate views' drift, and seconds per step.

usage: python bench/epipolar_onesided.py [--instants 4] [--steps 300] [--grid 64]
"""
import argparse
import os
from pathlib import Path
import sys
import time

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / 'test'))

from helpers.epipolar_reference import ring_rig, stack  # noqa: E402

from monet_ros.learning.epipolar import _prepare, _row_distribution, _row_max  # noqa: E402
from monet_ros.learning.losses import anchored_epipolar_terms, epipolar_loss  # noqa: E402
from monet_ros.models import render_heatmaps  # noqa: E402

SIZE = (46, 46)
V, C = 6, 14
ACCURATE, POOR = [0, 2, 4], [1, 3, 5]
MIXED_PEAKS = [1.0, 0.6, 0.95, 0.6, 0.9, 0.6]


def scene(B):
    cams = [ring_rig(V, SIZE, height=1.5 + (0.5 if k % 2 else -0.3))[k] for k in range(V)]
    rng = np.random.default_rng(0)
    X = rng.uniform(-0.45, 0.45, (B, C, 3))
    truth = np.stack([np.stack([c.project(x) for c in cams]) for x in X])
    centroid = np.stack([np.stack([c.project(x.mean(0)[None])[0] for c in cams]) for x in X])
    K, R, t = (a.expand(B, *a.shape).float() for a in stack(cams))
    return truth, centroid, K, R, t


def maps(centres, peaks, B):
    pk = torch.as_tensor(peaks, dtype=torch.float32)[None, :, None, None, None]
    return render_heatmaps(centres.reshape(-1, C, 2), SIZE, 2.0).reshape(B, V, C, *SIZE) * pk


def rowmax_onesided(outputs, K, R, t, grid=64, eps=1e-6):
    """(a): weighted mean over the anchored (anchor, target) pairs of KL(P_anchor || Q_target)
    of the rectified row-max distributions, the anchor's map detached."""
    e = anchored_epipolar_terms(outputs, K, R, t)
    pairs = e['pairs']
    a, g = pairs[:, 0], pairs[:, 1]
    B, _, _, h, w = outputs.shape
    P = len(pairs)
    heat_a = outputs[:, a].detach().clamp_min(0).reshape(B * P, C, h, w)
    heat_g = outputs[:, g].clamp_min(0).reshape(B * P, C, h, w)
    cams = [x[:, idx].reshape(B * P, *x.shape[2:]) for idx in (a, g) for x in (K, R, t)]
    geom, (rows, cols) = _prepare(heat_a, heat_g, *cams, None, None, eps, 10.0, 1.0, grid)
    max_a, max_g = _row_max(heat_a, heat_g, geom, rows, cols)
    p, q = _row_distribution(max_a), _row_distribution(max_g)
    kl = (p * (torch.log(p + eps) - torch.log(q + eps))).sum(-1)            # (B P, C)
    kl = torch.where(geom.valid[:, None], kl, torch.zeros_like(kl)).reshape(B, P, C)
    weight = e['weight'] * e['used']
    return (kl * weight).sum() / weight.sum().clamp_min(1e-12)


def descend(start, peaks, K, R, t, loss, steps, B):
    centres = torch.tensor(start, dtype=torch.float32, requires_grad=True)
    opt = torch.optim.Adam([centres], lr=0.1)
    tic = time.perf_counter()
    for _ in range(steps):
        value = loss(maps(centres, peaks, B), K, R, t)
        opt.zero_grad()
        value.backward()
        opt.step()
    return centres.detach().numpy().astype(np.float64), (time.perf_counter() - tic) / steps


def starts(truth, centroid, B):
    rng = np.random.default_rng(1)
    mixed = truth + rng.normal(0, 0.5, truth.shape)
    mixed[:, POOR] = truth[:, POOR] + rng.normal(0, 3.0, truth[:, POOR].shape)
    rng = np.random.default_rng(2)
    outlier = truth + rng.normal(0, 0.5, truth.shape)
    d = rng.normal(size=(B, C, 2))
    outlier[:, 3] = truth[:, 3] + 8.0 * d / np.linalg.norm(d, axis=-1, keepdims=True)
    rng = np.random.default_rng(3)
    collapsed = truth + rng.normal(0, 0.5, truth.shape)
    collapsed[:, POOR] = np.repeat(centroid[:, POOR, None], C, 2)
    return {'mixed': (mixed, MIXED_PEAKS, POOR, ACCURATE),
            'outlier': (outlier, [1.0, 0.95, 0.9, 0.6, 0.85, 0.8], [3], [0, 1, 2, 4, 5]),
            'collapsed': (collapsed, MIXED_PEAKS, POOR, ACCURATE)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--instants', type=int, default=4)
    parser.add_argument('--steps', type=int, default=300)
    parser.add_argument('--grid', type=int, default=64, help='(a): most rectified rows/cols')
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    B = args.instants
    truth, centroid, K, R, t = scene(B)
    candidates = {'(b) point-to-line, Cauchy (epipolar_loss)': epipolar_loss,
                  '(a) rectified row-max KL, one-sided':
                      lambda o, K, R, t: rowmax_onesided(o, K, R, t, args.grid)}
    print(f'# one-sided anchored L_E candidates: {B} instants x {C} keypoints x {V} views, '
          f'{args.steps} Adam steps; load average {os.getloadavg()[0]:.1f} on '
          f'{os.cpu_count()} cores\n')
    print('| scene | candidate | poor views: start -> end mean (median) px | accurate views: '
          'start -> end mean px | accurate drift px | s/step |')
    print('|---|---|---|---|---|---|')
    for name, (start, peaks, poor, accurate) in starts(truth, centroid, B).items():
        for label, loss in candidates.items():
            end, per_step = descend(start, peaks, K, R, t, loss, args.steps, B)
            e0 = np.linalg.norm(start - truth, axis=-1)
            e1 = np.linalg.norm(end - truth, axis=-1)
            drift = np.linalg.norm(end - start, axis=-1)[:, accurate].mean()
            print(f'| {name} | {label} | {e0[:, poor].mean():.2f} -> {e1[:, poor].mean():.2f} '
                  f'({np.median(e1[:, poor]):.2f}) | {e0[:, accurate].mean():.2f} -> '
                  f'{e1[:, accurate].mean():.2f} | {drift:.2f} | {per_step:.3f} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
