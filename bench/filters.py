"""3D filters side by side on synthetic 2D with known 3D: frame-by-frame robust
triangulation (raw) vs the Kalman / RTS smoother and the spatiotemporal optimisation of
monet_ros.temporal, and aniposelib's optimisation as a reference when it is importable.

Data: a `monet synth` human14 subject (monet_ros.synth.Subject, constant bone lengths)
walking for --frames frames at --fps, projected into a synthetic ring of --cameras
cameras (make_rig, 640x480, 60 deg) with 1 px Gaussian noise per coordinate, then 10% of
the (frame, view, keypoint) detections made gross outliers (half moved onto another
joint's projection, half moved 50-150 px) and 5% dropped (monet_ros.synth.noisy2d).
"clean raw" is frame-by-frame triangulation of the same projections without outliers or
drops: the target is filtered p90 <= 1.5x its p90.

Rows: clean raw / raw = fusion.fuse_points per frame (exclusion rule, 15 px, confidence
0.1) batched; kalman / optim = temporal.smooth_points on raw (defaults of temporal.FilterConfig);
aniposelib = aniposelib 0.8 CameraGroup.optim_points (the optimisation of its
triangulate_optim: smoothness + bone-length constraints on the skeleton's bones, soft_l1
reprojection, its defaults) started from a plain DLT of the same 2D, as triangulate_optim
does with init_ransac=False (its own triangulate needs jax, not installed here), scores
passed; and the same started from raw (interpolated by aniposelib over raw's gaps), to
compare the optimisers on one start. aniposelib is a bench-only reference, not a
dependency: install it beside the repository with
    .venv/bin/python -m pip install --no-deps --target .bench_deps aniposelib numba \
        llvmlite toml
(--no-deps: its opencv-contrib-python requirement would replace the venv's OpenCV); the
bench looks in .bench_deps (or --aniposelib-path) and skips the row when it cannot import.

Speed: frames/s of each offline method over the whole recording (median of --runs runs,
one BLAS thread; aniposelib rows --anipose-runs runs), with os.getloadavg(). The kalman,
optim and "started from raw" rows include raw's triangulation time.

usage: python bench/filters.py [--frames 300] [--cameras 8] [--fps 30] [--runs 3]
       [--per-joint] [--out bench/results/filters.md]
"""
import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')  # one core, before numpy loads BLAS

import argparse  # noqa: E402
import io  # noqa: E402
from pathlib import Path  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from monet_ros.fusion import FusionConfig, fuse_frames  # noqa: E402
from monet_ros.geometry import triangulate  # noqa: E402
from monet_ros.skeleton import load_skeleton  # noqa: E402
from monet_ros.synth import RigConfig, Subject, make_rig  # noqa: E402
from monet_ros.synth.noisy2d import noisy_detections  # noqa: E402
from monet_ros.temporal import FilterConfig, smooth_points  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def fuse(points2d, score, cameras):
    """Frame-by-frame fusion of (T, V, C, 2) at once -> X (T, C, 3), confidence, error."""
    r = fuse_frames(points2d, score, cameras, FusionConfig())
    return r['X'], r['score'], r['error']


def load_aniposelib(path):
    if path and Path(path).is_dir():
        sys.path.insert(0, str(path))
    try:
        import aniposelib  # noqa: F401
        from aniposelib.cameras import Camera as ACamera
        from aniposelib.cameras import CameraGroup
    except Exception as error:  # noqa: BLE001 - any import failure skips the row
        return None, f'aniposelib not importable ({type(error).__name__}: {error})'
    import importlib.metadata as md
    try:
        version = md.version('aniposelib')
    except md.PackageNotFoundError:
        version = '?'
    return (ACamera, CameraGroup), f'aniposelib {version}'


def aniposelib_optim(lib, cameras, points2d, score, edges, start=None):
    """aniposelib's optim_points from `start` (T, C, 3) or, None, a plain DLT of the same
    2D (triangulate_optim's init_ransac=False); -> X (T, C, 3)."""
    import cv2
    ACamera, CameraGroup = lib
    group = CameraGroup([ACamera(matrix=c.K, dist=np.asarray(c.dist)[:5], size=(c.width,
                                 c.height), rvec=cv2.Rodrigues(c.R)[0].ravel(),
                                 tvec=np.asarray(c.t), name=c.name) for c in cameras])
    T, V, C = score.shape
    pts = points2d.transpose(1, 0, 2, 3)                               # (V, T, C, 2)
    if start is None:
        start = triangulate(pts.reshape(V, T * C, 2), cameras).reshape(T, C, 3)
    import warnings
    quiet = io.StringIO()
    stdout, sys.stdout = sys.stdout, quiet                             # its progress prints
    try:
        with warnings.catch_warnings():            # numba's object-mode fallback warnings
            warnings.simplefilter('ignore')
            return group.optim_points(pts, start, constraints=[list(e) for e in edges],
                                      scores=score.transpose(1, 0, 2))
    finally:
        sys.stdout = stdout


def stats(X, truth):
    e = np.linalg.norm(X - truth, axis=-1) * 1000                      # (T, C) mm
    f = e[np.isfinite(e)]
    return e, dict(median=np.median(f), mean=f.mean(), p90=np.percentile(f, 90),
                   max=f.max(), coverage=f.size / e.size)


def timed(fn, runs):
    times, out = [], None
    for _ in range(runs):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return out, float(np.median(times))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--frames', type=int, default=300)
    parser.add_argument('--cameras', type=int, default=8)
    parser.add_argument('--fps', type=float, default=30.0)
    parser.add_argument('--runs', type=int, default=3)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--outliers', type=float, default=0.1)
    parser.add_argument('--drop', type=float, default=0.05)
    parser.add_argument('--per-joint', action='store_true', help='per-joint table')
    parser.add_argument('--aniposelib-path', default=str(ROOT / '.bench_deps'))
    parser.add_argument('--no-aniposelib', action='store_true')
    parser.add_argument('--anipose-runs', type=int, default=1,
                        help='runs of the (slow) aniposelib rows')
    parser.add_argument('--out', help='also write the tables to this markdown file')
    args = parser.parse_args(argv)

    skeleton = load_skeleton('human14')
    cameras = make_rig(RigConfig(num_cameras=args.cameras), seed=args.seed)
    stamps = np.round(np.arange(args.frames) * 1e9 / args.fps).astype(np.int64)
    truth = Subject(skeleton, seed=args.seed).keypoints3d(stamps / 1e9)
    clean = noisy_detections(truth, cameras, 1.0, 0.0, 0.0, seed=args.seed + 1)
    noisy = noisy_detections(truth, cameras, 1.0, args.outliers, args.drop,
                             seed=args.seed + 1)
    edges = skeleton.bone_indices
    rows, errors = {}, {}

    def add(name, X, seconds):
        errors[name], rows[name] = stats(X, truth)
        rows[name]['fps'] = args.frames / seconds if seconds else float('nan')

    (Xc, _, _), sec = timed(lambda: fuse(clean.points2d, clean.score, cameras), args.runs)
    add('clean raw (no outliers)', Xc, sec)
    (X, conf, err), sec_raw = timed(lambda: fuse(noisy.points2d, noisy.score, cameras),
                                    args.runs)
    add('raw (frame by frame)', X, sec_raw)
    for method in ('kalman', 'optim'):
        config = FilterConfig(method=method)
        s, sec = timed(lambda config=config: smooth_points(
            X, conf, noisy.points2d, noisy.score, cameras, stamps, edges, config, error=err),
            args.runs)
        add(method, s.X, sec + sec_raw)      # frames/s include the triangulation
    note = 'aniposelib: skipped (--no-aniposelib)'
    if not args.no_aniposelib:
        lib, note = load_aniposelib(args.aniposelib_path)
        if lib is not None:
            Xa, sec = timed(lambda: aniposelib_optim(lib, cameras, noisy.points2d,
                                                     noisy.score, edges), args.anipose_runs)
            add('aniposelib, DLT start (its triangulate_optim)', Xa, sec)
            Xa, sec = timed(lambda: aniposelib_optim(lib, cameras, noisy.points2d,
                                                     noisy.score, edges, X), args.anipose_runs)
            add('aniposelib, started from raw', Xa, sec + sec_raw)
            note = f'{note}: imported from {args.aniposelib_path}'
    lines = [f'# bench/filters.py: {args.frames} frames at {args.fps:g} Hz, '
             f'{args.cameras} cameras, 1 px noise, {100 * args.outliers:.0f}% gross outliers, '
             f'{100 * args.drop:.0f}% dropped; loadavg {os.getloadavg()}', '',
             '| method | median mm | mean mm | p90 mm | max mm | points | frames/s |',
             '|---|---|---|---|---|---|---|']
    for name, r in rows.items():
        lines.append(f'| {name} | {r["median"]:.1f} | {r["mean"]:.1f} | {r["p90"]:.1f} | '
                     f'{r["max"]:.0f} | {100 * r["coverage"]:.1f}% | {r["fps"]:.0f} |')
    target = 1.5 * rows['clean raw (no outliers)']['p90']
    lines += ['', f'target: filtered p90 <= 1.5 x clean raw p90 = {target:.1f} mm: '
              + ', '.join(f'{m} {rows[m]["p90"]:.1f} mm '
                          f'{"ok" if rows[m]["p90"] <= target else "MISSED"}'
                          for m in ('kalman', 'optim')), note]
    for name in [k for k in rows if k.startswith('aniposelib')]:
        a = rows[name]
        lines.append(f'optim vs {name}: p90 {rows["optim"]["p90"]:.1f} vs {a["p90"]:.1f} mm, '
                     f'{rows["optim"]["fps"] / a["fps"]:.1f}x its frames/s')
    if args.per_joint:
        names = list(rows)
        lines += ['', '| joint | ' + ' | '.join(f'{n} median / p90' for n in names) + ' |',
                  '|---|' + '---|' * len(names)]
        for c, k in enumerate(skeleton.keypoints):
            cells = []
            for n in names:
                e = errors[n][:, c]
                e = e[np.isfinite(e)]
                cells.append(f'{np.median(e):.1f} / {np.percentile(e, 90):.1f}' if e.size
                             else '-')
            lines.append(f'| {k} | ' + ' | '.join(cells) + ' |')
    text = '\n'.join(lines)
    print(text)
    if args.out:
        Path(args.out).write_text(text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
