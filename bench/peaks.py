"""Several hypotheses per view: fusion with peaks_per_view K = 1, 2, 3 on two-peak heatmaps.

Synthetic frames with a known 3D answer: the human14 `monet synth` subject (walking on a
1 m circle, 0.5 s apart) seen by 4 cameras on a 4 m ring (640x480, f = 600 px, the test
helpers' ring rig), one 48x64 heatmap crop per view around the subject, Gaussian peaks
(sigma 1.5 heatmap px, 0.3 px noise). Three sets:

  clean     one peak per map (amplitude 0.6-1.0)
  two-peak  a second peak on each map at the confusable joint (the left/right partner,
            the nearest other joint for head/neck), 0.3-0.8 of the true one's height
  swapped   two-peak, and in SWAP_RATE of the (view, joint) maps the confusable joint is
            the HIGHER peak (the true one 0.5-0.9 of it): the wrong limb wins the argmax

For each K: 3D error against the truth (mm: median / mean / p90 / share > 50 mm), share
triangulated, and fuse_heatmaps' time per frame (median of --runs; decode + candidates +
triangulation), with os.getloadavg(). K = 1 is the single-peak fusion of before. Each set
at the default threshold_px (15) and at 8 px (the wrong peak is then an outlier more often,
so candidates are tried more often).

--demo WORKDIR adds a trained model: `monet pipeline`'s demo assets (its synthetic
4-camera recording, 90 instants with ground truth, and the small detector trained on 3
labelled instants; made once in WORKDIR/v2 by commands.pipeline_demo.prepare_demo), the
detector run over every instant with crops around the ground truth, and the same heatmaps
fused with each K, scored against the ground-truth 3D.

usage: python bench/peaks.py [--frames 100] [--runs 30] [--demo WORKDIR]
"""
import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')  # one core, before numpy loads BLAS

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))
from helpers.scenes import gaussian_heatmaps, ring_rig, subject_box, to_crop  # noqa: E402

from monet_ros.fusion import FusionConfig, fuse_heatmaps  # noqa: E402
from monet_ros.skeleton import load_skeleton  # noqa: E402
from monet_ros.synth.subject import Subject  # noqa: E402

GRID = (48, 64)      # heatmap (w, h)
SIGMA = 1.5
NOISE = 0.3          # heatmap px
SWAP_RATE = 0.15
SETS = ('clean', 'two-peak', 'swapped')


def confusers(skeleton, uv):
    """(C,) the joint each joint is confused with: its left/right partner, else the nearest
    other joint in the image uv (C, 2)."""
    partner = np.array(skeleton.flip_permutation)
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    return np.where(partner != np.arange(len(partner)), partner, d.argmin(axis=1))


def make_frames(rng, rig, skeleton, frames, kind):
    """-> truth (F, C, 3) m, [(heatmaps (V, C, h, w), K_heat (V, 3, 3))] per frame."""
    truth = Subject(skeleton, seed=3).keypoints3d(np.arange(frames) * 0.5)
    out = []
    for X in truth:
        heat, K_heat = [], []
        for cam in rig:
            uv = cam.project(X)
            box = subject_box(uv, cam.width, cam.height, GRID[0] / GRID[1])
            p = to_crop(uv, box, GRID) + rng.normal(0, NOISE, (len(X), 2))
            amp = rng.uniform(0.6, 1.0, len(X))                 # the true joint's peak
            other_amp = np.zeros(len(X))                          # the confusable joint's
            if kind != 'clean':
                other_amp = amp * rng.uniform(0.3, 0.8, len(X))
            if kind == 'swapped':
                swap = rng.random(len(X)) < SWAP_RATE
                other_amp = np.where(swap, amp, other_amp)
                amp = np.where(swap, amp * rng.uniform(0.5, 0.9, len(X)), amp)
            maps = gaussian_heatmaps(p, GRID[::-1], SIGMA, amp)
            if kind != 'clean':
                other = p[confusers(skeleton, uv)] + rng.normal(0, NOISE, (len(X), 2))
                maps = np.maximum(maps, gaussian_heatmaps(other, GRID[::-1], SIGMA, other_amp))
            heat.append(maps)
            K_heat.append(cam.crop(box, GRID).K)
        out.append((np.stack(heat), np.stack(K_heat)))
    return truth, out


def demo_frames(workdir):
    """The demo detector's heatmaps of every instant of the demo recording (crops around
    the ground truth) -> truth (T, C, 3), [(heatmaps, K_heat)], cameras."""
    from monet_ros.commands.pipeline_demo import prepare_demo
    from monet_ros.learning.dataset import boxes_from_points
    from monet_ros.learning.pseudo_labels import project_to_views
    from monet_ros.learning.recording import load_recording
    from monet_ros.models import Detector

    assets = prepare_demo(workdir)
    recording = load_recording(assets.bag, rig=assets.rig, ground_truth=assets.ground_truth)
    detector = Detector.from_checkpoint(assets.model, device='cpu')
    cams = recording.cameras
    frames = []
    for t in range(len(recording.stamps)):
        uv = project_to_views(recording.gt3d[t], cams)                   # (V, C, 2)
        boxes = detector.boxes_for(cams, boxes_from_points(uv))
        heat, heat_cams = detector.predict(recording.images(t), cams, boxes, keep_aspect=False)
        frames.append((heat, np.stack([c.K for c in heat_cams])))
    return recording.gt3d, frames, cams


def evaluate(truth, frames, rig, k, runs, threshold_px=15.0):
    config = FusionConfig(peaks_per_view=k, threshold_px=threshold_px)
    X = np.stack([fuse_heatmaps(h, K, rig, config).X for h, K in frames])
    err = 1e3 * np.linalg.norm(X - truth, axis=-1).reshape(-1)
    seen = np.isfinite(err)
    e = err[seen]
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        for h, K in frames[:10]:
            fuse_heatmaps(h, K, rig, config)
        times.append((time.perf_counter() - start) / min(10, len(frames)))
    return dict(median=np.median(e), mean=e.mean(), p90=np.percentile(e, 90),
                gross=100 * (e > 50).mean(), seen=100 * seen.mean(),
                ms=1e3 * float(np.median(times)))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--frames', type=int, default=100)
    parser.add_argument('--runs', type=int, default=30)
    parser.add_argument('--peaks', type=int, nargs='+', default=[1, 2, 3])
    parser.add_argument('--demo', help="workdir of monet pipeline's demo assets (made there "
                        'once, a few minutes of CPU)')
    args = parser.parse_args(argv)
    rig = ring_rig(4, radius=4.0, target=(0.0, 0.0, 0.9))
    skeleton = load_skeleton('human14')
    print(f'load average {os.getloadavg()}; {args.frames} frames x 4 views x 14 joints')
    print('| set | K | median mm | mean mm | p90 mm | > 50 mm % | triangulated % | '
          'ms/frame |')
    print('|---|---|---|---|---|---|---|---|')
    for kind in SETS:
        truth, frames = make_frames(np.random.default_rng(0), rig, skeleton, args.frames,
                                    kind)
        for threshold in (15.0, 8.0):
            for k in args.peaks:
                r = evaluate(truth, frames, rig, k, args.runs, threshold)
                print(f'| {kind} ({threshold:g} px) | {k} | {r["median"]:.1f} | '
                      f'{r["mean"]:.1f} | {r["p90"]:.1f} | {r["gross"]:.1f} | '
                      f'{r["seen"]:.1f} | {r["ms"]:.3f} |')
    if args.demo:
        truth, frames, rig = demo_frames(args.demo)
        for threshold in (15.0, 8.0):
            for k in args.peaks:
                r = evaluate(truth, frames, rig, k, args.runs, threshold)
                print(f'| demo model ({threshold:g} px) | {k} | {r["median"]:.1f} | '
                      f'{r["mean"]:.1f} | {r["p90"]:.1f} | {r["gross"]:.1f} | '
                      f'{r["seen"]:.1f} | {r["ms"]:.3f} |')
    print(f'load average {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
