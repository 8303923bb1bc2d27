"""Triangulation speed and accuracy: ours (batched) vs per-keypoint baselines.

Synthetic frames: 14 keypoints in a 1 m cube seen by V pinhole cameras on a 3 m sphere
(focal ~1000-1400 px), 0.5 px Gaussian noise per coordinate, 10% of the observations are
gross outliers (moved 50 px in a random direction). Prints time per frame (median of
several runs, CPU time on one thread) and the 3D error against the ground truth.

  plain DLT:  monet triangulate (one batched eigen-solve)  vs  a per-keypoint numpy loop
              (the way Pose2Sim / EasyMocap triangulate).
  robust:     monet triangulate_robust (exclusion, ransac)  vs  exhaustive RANSAC over
              view subsets, written here as aniposelib 0.8's triangulate_ransac /
              triangulate_possible does it (every subset of >= 2 views in
              itertools.product order, DLT, mean reprojection error, keep the best,
              stop early below 0.5 px), capped in time.

usage: python bench/triangulation.py [--views 4 8 35 69] [--frames 20] [--runs 5]
"""
import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')  # one core, before numpy loads BLAS

import argparse  # noqa: E402
import itertools  # noqa: E402
from pathlib import Path  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))
from helpers.rigs import random_rig  # noqa: E402

from monet_ros.geometry import triangulate, triangulate_robust  # noqa: E402

NUM_KEYPOINTS = 14
NOISE_PX = 0.5
OUTLIER_RATE = 0.10
OUTLIER_PX = 50.0
# aniposelib 0.8.0 triangulate_ransac measured on this machine (issue 2)
ANIPOSELIB = {4: '94 ms', 8: '1.4 s', 35: 'not finished in 60 s', 69: '-'}


def make_frames(rng, cameras, frames):
    """-> ground truth (F, N, 3) metres, observations (F, V, N, 2) px."""
    truth = rng.uniform(-0.5, 0.5, size=(frames, NUM_KEYPOINTS, 3))
    obs = np.stack([np.stack([c.project(X) for c in cameras]) for X in truth])
    obs += rng.normal(scale=NOISE_PX, size=obs.shape)
    bad = rng.random(obs.shape[:3]) < OUTLIER_RATE
    angle = rng.uniform(0, 2 * np.pi, size=bad.shape)
    offset = OUTLIER_PX * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    obs[bad] += offset[bad]
    return truth, obs


# ---------------------------------------------------------------- baselines (per keypoint)

def dlt_loop(points2d, projections):
    """Per-keypoint DLT with Python loops (Pose2Sim's weighted_triangulation, weights 1)."""
    V, N, _ = points2d.shape
    out = np.full((N, 3), np.nan)
    for n in range(N):
        A = []
        for v in range(V):
            x, y = points2d[v, n]
            if np.isnan(x):
                continue
            P = projections[v]
            A.append(P[0] - x * P[2])
            A.append(P[1] - y * P[2])
        if len(A) >= 4:
            h = np.linalg.svd(np.array(A))[2][-1]
            out[n] = h[:3] / h[3]
    return out


def _reproj_mean(projections, X, pts):
    Xh = np.append(X, 1.0)
    proj = projections @ Xh
    uv = proj[:, :2] / proj[:, 2:]
    return np.mean(np.linalg.norm(uv - pts, axis=1))


def exhaustive_ransac(points2d, projections, deadline, min_cams=2, threshold=0.5):
    """aniposelib's triangulate_possible for one candidate per camera: for each keypoint,
    all subsets of cameras in itertools.product order (all cameras first), DLT, mean
    reprojection error, keep the lowest (< 200 px), stop early below `threshold`.
    Returns None when `deadline` (perf_counter) passes."""
    V, N, _ = points2d.shape
    out = np.full((N, 3), np.nan)
    for n in range(N):
        options = [[v, None] for v in range(V) if not np.isnan(points2d[v, n, 0])]
        n_max = len(options)
        best_error, best = 200.0, None
        for picked in itertools.product(*options):
            if time.perf_counter() > deadline:
                return None
            cams = [p for p in picked if p is not None]
            if len(cams) < min_cams and len(cams) != n_max:
                continue
            if len(cams) < 2:
                continue
            X = dlt_loop(points2d[cams, n:n + 1], projections[cams])[0]
            err = _reproj_mean(projections[cams], X, points2d[cams, n])
            if err < best_error:
                best_error, best = err, X
                if best_error < threshold:
                    break
        if best is not None:
            out[n] = best
    return out


# ---------------------------------------------------------------- timing

def time_method(fn, obs, runs):
    """Median over runs of the CPU time per frame (s) and the last run's outputs (F, N, 3).

    CPU time of this process (time.process_time, one BLAS thread) rather than wall time:
    the development machine is shared, and waiting for a core is not our cost."""
    times, outputs = [], None
    for _ in range(runs):
        start = time.process_time()
        outputs = [fn(o) for o in obs]
        times.append((time.process_time() - start) / len(obs))
    return float(np.median(times)), np.stack(outputs)


def errors_mm(X, truth):
    d = np.linalg.norm(X - truth, axis=-1) * 1000.0
    return float(np.nanmean(d)), float(np.nanmedian(d)), int(np.isnan(d).sum())


def fmt_time(seconds):
    if seconds is None:
        return 'not finished'
    return f'{seconds * 1e3:.3f} ms' if seconds < 1 else f'{seconds:.2f} s'


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--views', type=int, nargs='+', default=[4, 8, 35, 69])
    parser.add_argument('--frames', type=int, default=20)
    parser.add_argument('--runs', type=int, default=5)
    parser.add_argument('--cap-s', type=float, default=60.0,
                        help='wall-time cap of the exhaustive RANSAC baseline per view count')
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)

    rows = []
    for V in args.views:
        rng = np.random.default_rng(args.seed + V)
        cameras = random_rig(rng, V, distortion=False)
        projections = np.stack([c.P for c in cameras])
        truth, obs = make_frames(rng, cameras, args.frames)
        print(f'{V} views: {args.frames} frames x {NUM_KEYPOINTS} keypoints ...',
              file=sys.stderr, flush=True)
        methods = [
            ('DLT', 'ours: batched, 1 eigen-solve', lambda o, c=cameras: triangulate(o, c)),
            ('DLT', 'per-keypoint loop', lambda o, p=projections: dlt_loop(o, p)),
            ('robust', 'ours: exclusion 1 px', lambda o, c=cameras: triangulate_robust(
                o, c, threshold_px=1.0, method='exclusion')[0]),
            ('robust', 'ours: ransac 2 px', lambda o, c=cameras: triangulate_robust(
                o, c, threshold_px=2.0, method='ransac')[0]),
        ]
        for kind, name, fn in methods:
            t, X = time_method(fn, obs, args.runs)
            rows.append((V, kind, name, fmt_time(t), *errors_mm(X, truth)))
        # exhaustive RANSAC baseline: one run, capped; frames done before the cap count
        deadline = time.perf_counter() + args.cap_s
        start, done = time.process_time(), []
        for o in obs:
            X = exhaustive_ransac(o, projections, deadline)
            if X is None:
                break
            done.append(X)
        if done:
            t = (time.process_time() - start) / len(done)
            rows.append((V, 'robust', f'exhaustive RANSAC ({len(done)}/{args.frames} fr)',
                         fmt_time(t), *errors_mm(np.stack(done), truth[:len(done)])))
        else:
            rows.append((V, 'robust', f'exhaustive RANSAC (cap {args.cap_s:.0f} s)',
                         'not finished', float('nan'), float('nan'), 0))
        rows.append((V, 'robust', 'aniposelib 0.8.0 (issue 2)', ANIPOSELIB.get(V, '-'),
                     float('nan'), float('nan'), 0))

    header = (f'{"views":>5}  {"kind":<6}  {"method":<36}  {"time/frame":>14}  '
              f'{"3D err mean":>11}  {"median":>8}  {"NaN":>4}')
    print(f'triangulation: {NUM_KEYPOINTS} keypoints, noise {NOISE_PX} px, '
          f'{OUTLIER_RATE:.0%} outliers +{OUTLIER_PX:.0f} px, {args.frames} frames, '
          f'median of {args.runs} runs; CPU time per frame, 1 thread (shared machine)')
    print(header)
    print('-' * len(header))
    for V, kind, name, t, mean, median, nans in rows:
        mean_s = f'{mean:8.2f} mm' if np.isfinite(mean) else f'{"-":>11}'
        med_s = f'{median:5.2f} mm' if np.isfinite(median) else f'{"-":>8}'
        print(f'{V:>5}  {kind:<6}  {name:<36}  {t:>14}  {mean_s:>11}  {med_s:>8}  {nans:>4}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
