"""Epipolar loss L_E speed: rectified (ours) vs brute-force line sampling, and vs a CPM step.

Batch: B instants of a V-camera ring (3 m radius, 1.5 m high, looking at the subject; the
heatmap windows are 46x46 crops around a subject that moves between instants), C keypoints
rendered as Gaussians (sigma 1.5 px) at their projections plus a little noise; all the
non-degenerate pairs of valid_view_pairs. Times are forward + backward (gradient w.r.t. the
heatmaps), median of --runs runs, each column measured in the same process:

  rectified    monet_ros.learning.multiview_epipolar_loss (spherical rectification, every
               pair in one grid_sample call, both KL directions per pair)
  brute force  the paper's definition without rectification, batched torch: for the same
               epipolar planes as the rectified rows, sample each plane's epipolar line in the
               original heatmap every <= --spacing px (bilinear, one grid_sample call for all
               pairs, planes and samples), max, normalise, KL both directions
  CPM step     forward + MSE to Gaussian targets on all 5 stages + backward + Adam step of
               build_model('cpm', C) on the B*V images (368x368) of the same batch

Accuracy: mean |Q - Q_ref| / max Q_ref over rows, keypoints and views against line sampling
every 0.05 px (the row maxima before normalisation), on the first instant's pairs.

usage: python bench/epipolar.py [--batch 8] [--views 8] [--keypoints 14] [--runs 7]
       [--cpm-runs 3] [--threads N] [--device cpu|cuda] [--no-cpm]
"""
import argparse
import math
from pathlib import Path
import statistics
import sys
import time

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))
from helpers.epipolar_reference import (  # noqa: E402
    crop_to_subject,
    line_row_max_torch,
    rect_row_normals,
    ring_rig,
)

from monet_ros.learning import multiview_epipolar_loss  # noqa: E402
from monet_ros.learning.epipolar import _kl, _multiview_pairs, _rectify  # noqa: E402
from monet_ros.models import build_model, render_heatmaps  # noqa: E402

SIZE = (46, 46)


def make_batch(rng, B, V, C, device, dtype=torch.float32):
    """heat (B, V, C, h, w), K, R, t of a moving subject seen by a V-camera ring."""
    full = [cam for cam in ring_rig(V, size=SIZE)]  # heatmap cameras for the origin
    Ks, Rs, ts, heats = [], [], [], []
    for _ in range(B):
        centre = rng.uniform(-0.3, 0.3, size=3)
        X = centre + rng.uniform(-0.6, 0.6, size=(C, 3))
        cams = [crop_to_subject(_uncrop(c), SIZE, centre=centre) for c in full]
        pts = np.stack([c.project(X) for c in cams]) + rng.normal(scale=0.5, size=(V, C, 2))
        heats.append(render_heatmaps(torch.tensor(pts), SIZE, 1.5))
        Ks.append(np.stack([c.K for c in cams]))
        Rs.append(np.stack([c.R for c in cams]))
        ts.append(np.stack([c.t for c in cams]))
    heat = torch.stack(heats).to(device=device, dtype=dtype)
    heat = heat + 0.01 * torch.rand_like(heat)
    tens = [torch.tensor(np.stack(a), device=device, dtype=torch.float64) for a in (Ks, Rs, ts)]
    return heat, *tens


def _uncrop(cam):
    """The full-image camera a ring heatmap camera was cropped from (ring_rig's intrinsics)."""
    from monet_ros.geometry import Camera
    K = np.array([[1000.0, 0.0, 640.0], [0.0, 1000.0, 480.0], [0.0, 0.0, 1.0]])
    return Camera(cam.name, K, np.zeros(5), cam.R, cam.t, 1280, 960)


def brute_force_loss(heat, K, R, t, spacing, rows=None, eps=1e-6):
    """L_E by line sampling in the original heatmaps, same pairs and planes as rectified."""
    size = tuple(heat.shape[-2:])
    b, i, j, geom = _multiview_pairs(K, R, t, size, None, 10.0, 1.0)
    rows, _ = geom.grid_size(rows, None, 4 * max(size))
    normals = rect_row_normals(geom.R_rect, geom.row_angles(rows))
    N = b.numel()
    both = torch.cat([heat[b, i], heat[b, j]])
    q = line_row_max_torch(both, torch.cat([K[b, i], K[b, j]]), torch.cat([R[b, i], R[b, j]]),
                           torch.cat([normals, normals]), spacing)
    q = q / q.sum(-1, keepdim=True).clamp_min(1e-12)
    return torch.cat([_kl(q[:N], q[N:], eps), _kl(q[N:], q[:N], eps)]).mean(), rows


def timed(fn, runs, device):
    """Medians over runs of (wall seconds, process CPU seconds)."""
    wall, cpu = [], []
    for _ in range(runs):
        if device.type == 'cuda':
            torch.cuda.synchronize()
        start, start_cpu = time.perf_counter(), time.process_time()
        fn()
        if device.type == 'cuda':
            torch.cuda.synchronize()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return statistics.median(wall), statistics.median(cpu)


def accuracy(heat, K, R, t):
    """Mean |Q - Q_ref| / max(Q_ref) of rectified rows and 1 px / 0.5 px line sampling."""
    size = tuple(heat.shape[-2:])
    b, i, j, geom = _multiview_pairs(K[:1], R[:1], t[:1], size, None, 10.0, 1.0)
    rows, cols = geom.grid_size(None, None, 4 * max(size))
    normals = rect_row_normals(geom.R_rect, geom.row_angles(rows))
    h = heat[:1].detach().double()
    rect_i, rect_j, _ = _rectify(h[b, i], h[b, j], geom, rows, cols)
    out = {'rectified': torch.cat([rect_i.amax(-1), rect_j.amax(-1)])}
    ref = None
    for spacing in (0.05, 1.0, 0.5):
        q = torch.cat([line_row_max_torch(h[b, i], K[b, i], R[b, i], normals, spacing),
                       line_row_max_torch(h[b, j], K[b, j], R[b, j], normals, spacing)])
        if ref is None:
            ref = q
        else:
            out[f'brute {spacing:g} px'] = q
    scale = ref.amax(-1, keepdim=True).clamp_min(1e-12)
    return {k: float(((v - ref).abs() / scale).mean()) for k, v in out.items()}, rows, cols


def cpm_step_time(B, V, C, runs, device):
    model = build_model('cpm', C).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    images = torch.rand(B * V, 3, *model.input_size, device=device)
    target = torch.rand(B * V, C, *model.heatmap_size, device=device)

    def step():
        opt.zero_grad(set_to_none=True)
        loss = sum(torch.nn.functional.mse_loss(s, target) for s in model(images))
        loss.backward()
        opt.step()
    step()  # warm-up
    return timed(step, runs, device)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--batch', type=int, default=8)
    parser.add_argument('--views', type=int, default=8)
    parser.add_argument('--keypoints', type=int, default=14)
    parser.add_argument('--runs', type=int, default=7)
    parser.add_argument('--cpm-runs', type=int, default=3)
    parser.add_argument('--spacing', type=float, default=0.5,
                        help='brute-force sample spacing along lines (px); the rectified '
                        'columns are ~0.5 px apart')
    parser.add_argument('--threads', type=int, default=None)
    parser.add_argument('--device', default='cpu')
    parser.add_argument('--no-cpm', action='store_true')
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    rng = np.random.default_rng(0)
    heat, K, R, t = make_batch(rng, args.batch, args.views, args.keypoints, device)
    b, _, _, geom = _multiview_pairs(K, R, t, SIZE, None, 10.0, 1.0)
    rows, cols = geom.grid_size(None, None, 4 * max(SIZE))
    pairs = math.comb(args.views, 2) * args.batch

    def rectified():
        h = heat.detach().requires_grad_()
        multiview_epipolar_loss(h, K, R, t).backward()

    def brute():
        h = heat.detach().requires_grad_()
        brute_force_loss(h, K, R, t, args.spacing)[0].backward()

    rectified()
    brute()   # warm-up
    t_rect = timed(rectified, args.runs, device)
    t_brute = timed(brute, args.runs, device)
    with torch.no_grad():
        value_rect = float(multiview_epipolar_loss(heat, K, R, t))
        value_brute = float(brute_force_loss(heat, K, R, t, args.spacing)[0])
    acc, _, _ = accuracy(heat, K, R, t)
    t_cpm = None if args.no_cpm else cpm_step_time(args.batch, args.views, args.keypoints,
                                                  args.cpm_runs, device)

    samples = math.ceil(math.hypot(*SIZE) / args.spacing) + 1
    print(f'L_E forward+backward, B={args.batch} instants x {args.views} views, '
          f'{args.keypoints} keypoints, {SIZE[0]}x{SIZE[1]} heatmaps, {b.numel()} of {pairs} '
          f'pairs valid (x2 directions), {rows} planes; device {device}, '
          f'{torch.get_num_threads()} threads; median of {args.runs} runs')
    print(f'{"method":<34}{"grid per heatmap":>17}{"wall ms":>10}{"CPU ms":>10}{"L_E":>9}'
          f'{"row err":>9}{"% of CPM":>10}')
    for name, grid, sec, val, err in (
            ('rectified (ours)', f'{rows}x{cols}', t_rect, value_rect, acc['rectified']),
            (f'brute force, lines every {args.spacing:g} px', f'{rows}x{samples}', t_brute,
             value_brute, acc[f'brute {args.spacing:g} px'])):
        frac = f'{100 * sec[1] / t_cpm[1]:.2f}' if t_cpm else '-'
        print(f'{name:<34}{grid:>17}{1e3 * sec[0]:>10.1f}{1e3 * sec[1]:>10.1f}{val:>9.4f}'
              f'{err:>9.4f}{frac:>10}')
    print(f'speed-up rectified vs brute force: {t_brute[0] / t_rect[0]:.2f}x wall, '
          f'{t_brute[1] / t_rect[1]:.2f}x CPU (target >= 10x)')
    other = 'brute 1 px' if args.spacing != 1.0 else 'brute 0.5 px'
    print(f'row error of the {other[6:]} brute force for reference: {acc[other]:.4f}')
    if t_cpm:
        print(f'CPM training step (B*V = {args.batch * args.views} images 368x368, fwd+bwd+Adam, '
              f'median of {args.cpm_runs}): {t_cpm[0]:.1f} s wall, {t_cpm[1]:.1f} s CPU; L_E = '
              f'{100 * t_rect[1] / t_cpm[1]:.2f}% of it in CPU time (target <= 10%)')
    print('row err: mean |Q - Q_ref| / max Q_ref vs line sampling every 0.05 px, instant 0.')
    print('The machine is shared with other helpers: absolute times are noisy.')


if __name__ == '__main__':
    main()
