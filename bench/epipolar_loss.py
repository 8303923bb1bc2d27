"""Which L_E is lowest where the keypoints are right: candidate formulations side by side.

Heatmaps are not network outputs but maps with a known answer: B instants of C random 3D
keypoints (+-0.5 m around the target) seen by a non-coplanar 6-camera ring (`monet synth`'s
rig: ring, height spread 0.8 m, no distortion), each view's 32x32 heatmap window a crop
around the subject. Cases (every view unless said):
  ideal       Gaussians of sigma 1 heatmap px (peak 1) at the true projections
  floor       ideal + 0.02 everywhere
  broadened   sigma 5 (peak 1) at the truth
  shifted     ideal, but view 0's keypoints 2 heatmap px off (a random direction per point)
  uniform     0.5 everywhere
Candidates (a good one scores ideal lowest):
  old         multiview_epipolar_loss (rectified row max normalised over rows, KL, both
              directions, line weights) on min-shifted maps: what the trainer applied before
  KL rowmax softmax   the same on a spatial softmax of temperature 0.1 (a distribution)
  KL rowmax floor     the same on heatmap_distribution (relu(heat - 0.1), normalised)
  KL rowsum floor     rectified row sums (the distribution's marginal over epipolar planes)
              of heatmap_distribution, KL both directions, mean over pairs and keypoints
  E dist softmax      expected symmetric epipolar distance (symmetric_epipolar_terms) on the
              softmax distribution (shift invariant: floor = ideal)
  E dist floor        symmetric_epipolar_loss (the trainer's L_E until issue 36)
  anchored            monet_ros.learning.losses.epipolar_loss (L_E now: one-sided, anchored
              on confident views that agree; all maps here have peak 1, so no view is
              less confident than another and it scores 0 throughout: it only ranks views
              of different confidence, test/learning/test_epipolar_anchored.py)
Also: the share of view pairs each candidate uses (the rectified ones skip pairs whose
epipole is within 10 degrees of a window).

usage: python bench/epipolar_loss.py [--instants 4] [--keypoints 14] [--seed 0]
"""
import argparse
from pathlib import Path
import sys

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from monet_ros.learning.epipolar import (  # noqa: E402
    multiview_epipolar_loss,
    rectify_pair,
    valid_view_pairs,
)
from monet_ros.learning.losses import epipolar_loss, heatmap_distribution  # noqa: E402
from monet_ros.learning.symmetric_epipolar import (  # noqa: E402
    symmetric_epipolar_loss,
    symmetric_epipolar_terms,
)
from monet_ros.learning.trainer import nonnegative  # noqa: E402
from monet_ros.models import render_heatmaps  # noqa: E402
from monet_ros.synth.rig import RigConfig, make_rig  # noqa: E402

SIZE = (32, 32)


def heatmap_rig(num_views, seed):
    """Heatmap-grid cameras (K, R, t tensors (V, ...)) of a non-coplanar ring."""
    config = RigConfig(num_cameras=num_views, layout='ring', image_width=320,
                       image_height=240, hfov_deg=60.0, distortion=(0.0,),
                       height_spread=0.8)
    cams = []
    target = np.asarray(config.target)
    for cam in make_rig(config, seed):
        uv = cam.project(target[None])[0]
        depth = (cam.R @ target + cam.t)[2]
        half = cam.K[0, 0] * 0.9 / depth
        cams.append(cam.crop((uv[0] - half, uv[1] - half, uv[0] + half, uv[1] + half),
                             (SIZE[1], SIZE[0])))
    return cams, [torch.tensor(np.stack([getattr(c, a) for c in cams]), dtype=torch.float32)
                  for a in ('K', 'R', 't')]


def cases(cams, instants, keypoints, rng):
    target = np.array([0.0, 0.0, 0.9])
    X = target + rng.uniform(-0.5, 0.5, (instants, keypoints, 3))
    pts = np.stack([np.stack([c.project(x) for c in cams]) for x in X])   # (B, V, C, 2)

    def render(points, sigma):
        flat = torch.tensor(points.reshape(-1, keypoints, 2), dtype=torch.float32)
        return render_heatmaps(flat, SIZE, sigma).reshape(*points.shape[:3], *SIZE)
    ideal = render(pts, 1.0)
    shifted = pts.copy()
    angle = rng.uniform(0, 2 * np.pi, (instants, keypoints))
    shifted[:, 0] += 2.0 * np.stack([np.cos(angle), np.sin(angle)], -1)
    return {'ideal': ideal, 'floor': ideal + 0.02, 'broadened': render(pts, 5.0),
            'shifted': render(shifted, 1.0), 'uniform': torch.full_like(ideal, 0.5)}


def softmax(heat, temperature=0.1):
    return torch.softmax((heat / temperature).flatten(-2), -1).reshape(heat.shape)


def kl_rowsum(heat, K, R, t):
    """Rectified row sums of each pair, normalised over rows, KL both directions (mean)."""
    B, V = heat.shape[:2]
    b, i, j = valid_view_pairs(K, R, t, SIZE)
    rect = rectify_pair(heat[b, i], heat[b, j], K[b, i], R[b, i], t[b, i], K[b, j], R[b, j],
                        t[b, j], overlap=True)
    q_i, q_j = rect.heat_i.sum(-1), rect.heat_j.sum(-1)
    q_i = q_i / q_i.sum(-1, keepdim=True).clamp_min(1e-12)
    q_j = q_j / q_j.sum(-1, keepdim=True).clamp_min(1e-12)

    def kl(p, q):
        return (p * ((p + 1e-6).log() - (q + 1e-6).log())).sum(-1)
    return float(0.5 * (kl(q_i, q_j) + kl(q_j, q_i)).mean())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--instants', type=int, default=4)
    parser.add_argument('--keypoints', type=int, default=14)
    parser.add_argument('--views', type=int, default=6)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    cams, (K, R, t) = heatmap_rig(args.views, args.seed)
    B = args.instants
    K, R, t = (a.expand(B, *a.shape) for a in (K, R, t))
    maps = cases(cams, B, args.keypoints, rng)

    def e_dist(heat, distribution=None):
        terms = symmetric_epipolar_terms(heat, K, R, t, distribution=distribution)
        w = terms['weight']
        return float((w * terms['distance']).sum() / w.sum())
    candidates = {
        'old': lambda h: float(multiview_epipolar_loss(nonnegative(h), K, R, t)),
        'KL rowmax softmax': lambda h: float(multiview_epipolar_loss(softmax(h), K, R, t)),
        'KL rowmax floor': lambda h: float(multiview_epipolar_loss(heatmap_distribution(h),
                                                                   K, R, t)),
        'KL rowsum floor': lambda h: kl_rowsum(heatmap_distribution(h), K, R, t),
        'E dist softmax': lambda h: e_dist(h, softmax),
        'E dist floor (symmetric_epipolar_loss)':
            lambda h: float(symmetric_epipolar_loss(h, K, R, t)),
        'anchored (epipolar_loss, L_E)': lambda h: float(epipolar_loss(h, K, R, t)),
    }
    names = list(maps)
    print(f'{args.views}-camera non-coplanar ring, {B} instants x {args.keypoints} keypoints, '
          f'{SIZE[0]}x{SIZE[1]} heatmaps, seed {args.seed}\n')
    print('| candidate | ' + ' | '.join(names) + ' | ideal lowest |')
    print('|---' * (len(names) + 2) + '|')
    for label, fn in candidates.items():
        with torch.no_grad():
            scores = [fn(maps[n]) for n in names]
        best = all(scores[0] < s for s in scores[1:])
        print(f'| {label} | ' + ' | '.join(f'{s:.4g}' for s in scores) +
              f' | {"yes" if best else "no"} |')
    V = args.views
    b, _, _ = valid_view_pairs(K[:1], R[:1], t[:1], SIZE)
    used = symmetric_epipolar_terms(maps['ideal'][:1], K[:1], R[:1], t[:1])['pair_used']
    print(f'\nview pairs used: rectified (10 degree rule) {len(b)} of {V * (V - 1) // 2}; '
          f'symmetric_epipolar_loss {int(used.sum())} of {V * (V - 1) // 2}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
