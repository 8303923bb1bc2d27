"""Several subjects live: the fusion node's core (subjects.detection.SubjectsCore.live_frame)
fed the crop slots a detector node publishes, in a lockstep loop, for 2 and 3 subjects.

Data: the subjects, rig and occlusion of bench/subjects.py (human14 subjects walking rings
of 0.7 / 1.4 / 2.1 m that pass each other, --cameras synthetic 640x480 cameras, --frames
frames at 30/s). Each frame the detector's part is simulated as the node does it: the crop
slots from the previous frame's output (crop_rule.TrackedSubjects over the published
subjects, at float32 like the topic; the full frame while fewer than N are published),
each box grown to the heatmap grid's aspect (48 x 64 px subject crops, 64 x 48 full
frame), and a "perfect detector": every subject's visible keypoints (not hidden by a limb,
inside the image) rendered as Gaussians (sigma 1.5 heatmap px, peak 0.9 whichever subject
the crop is for) at their projection plus --noise source px of Gaussian noise. So it
measures what fusion adds live (crop-to-track matching, instance decoding, association,
duplicates, tracking) and the cost per frame, not a network's accuracy.

Rows, with SubjectsConfig.rival_peaks off and on (the default): identity switches and IDF1
(subjects.metrics, match within --match-m), 3D error per subject (mm, matched frames),
live_frame per frame (wall median and p90, CPU of the thread median; heatmap peak decoding
included), crops per frame and the discovery runs. One subject through the same loop (N =
2) is the single-subject reference.

usage: python bench/subjects_live.py [--frames 300] [--cameras 8] [--noise 1] [--seed 0]
"""
import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')  # one core, before numpy loads BLAS

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from monet_ros.cores import cpu_model  # noqa: E402
from monet_ros.crop_rule import TrackedSubjects  # noqa: E402
from monet_ros.skeleton import load_skeleton  # noqa: E402
from monet_ros.subjects.detection import (  # noqa: E402
    SubjectsConfig,
    SubjectsCore,
    subject_keypoints,
)
from monet_ros.subjects.metrics import identity_scores  # noqa: E402
from monet_ros.synth.rig import RigConfig, make_rig  # noqa: E402
from monet_ros.synth.subjects import make_subjects, subjects_occlusion  # noqa: E402

CROP, FULL = (48, 64), (64, 48)     # heatmap grids (w, h)
SIGMA = 1.5


def to_aspect(box, grid):
    """A box grown about its centre to the grid's aspect (what Detector.boxes_for does)."""
    x0, y0, x1, y1 = box
    aspect = grid[0] / grid[1]
    w, h = x1 - x0, y1 - y0
    w, h = max(w, h * aspect), max(h, w / aspect)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    return np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2])


def render(cam, box, grid, uv, visible):
    """(C, h, w) maps of the crop `box` of camera `cam` with Gaussians at the source pixels
    uv (S, C, 2) where visible (S, C)."""
    crop = cam.crop(box, grid)
    S_ = np.diag([crop.K[0, 0] / cam.K[0, 0], crop.K[1, 1] / cam.K[1, 1]])
    offset = crop.K[:2, 2] - S_ @ cam.K[:2, 2]
    p = uv @ S_.T + offset                                          # heatmap px (S, C, 2)
    v, u = np.mgrid[0:grid[1], 0:grid[0]]
    d2 = (u - p[..., 0, None, None]) ** 2 + (v - p[..., 1, None, None]) ** 2
    maps = np.where(visible[..., None, None], 0.9 * np.exp(-d2 / (2 * SIGMA ** 2)), 0.0)
    return maps.max(0).astype(np.float32), crop.K


def run(truth, hidden, cameras, noise, seed, N, rival_peaks=False):
    T, S, C, _ = truth.shape
    V = len(cameras)
    rng = np.random.default_rng(seed)
    core = SubjectsCore(C, 'm', SubjectsConfig(subjects=N, rival_peaks=rival_peaks))
    tracks = TrackedSubjects(units='m')
    size = np.array([[c.width, c.height] for c in cameras], np.float64)
    X_out, ids_out = np.full((T, N, C, 3), np.nan), np.full((T, N), -1)
    wall, cpu, crops, discoveries = np.zeros(T), np.zeros(T), 0, 0
    for t in range(T):
        stamp = int(round(t / 30.0 * 1e9))
        boxes = tracks.boxes(cameras, stamp, N)                       # (V, N + 1, 4)
        uv = np.stack([c.project(truth[t].reshape(-1, 3)).reshape(S, C, 2) for c in cameras])
        uv = uv + rng.normal(0.0, noise, uv.shape)                    # (V, S, C, 2)
        inside = ((uv >= -0.5) & (uv <= size[:, None, None] - 0.5)).all(-1)
        visible = inside & ~hidden[t].transpose(1, 0, 2)              # (V, S, C)
        sub, full, present = [], [], []
        for v in range(V):
            for k in range(N + 1):
                if not np.isfinite(boxes[v, k]).all():
                    continue
                grid = FULL if k == N else CROP
                heat, K = render(cameras[v], to_aspect(boxes[v, k], grid), grid, uv[v],
                                 visible[v])
                if v not in present:
                    present.append(v)
                (full if k == N else sub).append((present.index(v), heat, K))
        crops += len(sub) + len(full)
        start, start_cpu = time.perf_counter(), time.thread_time()
        r = core.live_frame([cameras[v] for v in present], stamp, sub, full)
        wall[t], cpu[t] = time.perf_counter() - start, time.thread_time() - start_cpu
        discoveries += r.discovered >= 0
        ids, X, *_ = subject_keypoints(r)
        X_out[t, :len(ids)], ids_out[t, :len(ids)] = X, ids
        # what the detector reads back from /monet/keypoints3d (float32 metres)
        tracks.update(X.reshape(-1, 3).astype(np.float32), np.repeat(ids, C),
                      np.tile(np.arange(C), len(ids)), stamp, C)
    return X_out, ids_out, wall, cpu, crops / T, discoveries


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--frames', type=int, default=300)
    parser.add_argument('--cameras', type=int, default=8)
    parser.add_argument('--noise', type=float, default=1.0)
    parser.add_argument('--match-m', type=float, default=0.2)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    sk = load_skeleton('human14')
    times = np.arange(args.frames) / 30.0
    cameras = make_rig(RigConfig(num_cameras=args.cameras), seed=args.seed)
    print(f'# bench/subjects_live.py: {args.frames} frames at 30/s, {args.cameras} cameras, '
          f'human14, noise {args.noise} px, occluded keypoints not rendered, lockstep')
    print(f'# CPU: {cpu_model()}; loadavg at start {os.getloadavg()}')
    print('| subjects | rival_peaks | closest pass (m) | IDSW | IDF1 | 3D error per subject '
          '(mm) | crops/frame | discovery runs | live_frame ms/frame median (p90) | CPU '
          'ms/frame median |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for S in (1, 2, 3):
        subjects = make_subjects(sk, S, seed=args.seed)
        truth, hidden = subjects_occlusion(subjects, times, cameras)
        for rival in ((False,) if S == 1 else (False, True)):
            X, ids, wall, cpu, crops, discoveries = run(
                truth, hidden, cameras, args.noise, args.seed + S, max(S, 2), rival)
            scores = identity_scores(truth, X, ids, args.match_m)
            closest = '-'
            if S > 1:
                root = truth[..., :2].mean(2)
                gaps = np.linalg.norm(root[:, :, None] - root[:, None], axis=-1)
                closest = f'{gaps[:, ~np.eye(S, dtype=bool)].min():.2f}'
            err = ', '.join(f'{1000 * e:.1f}' for e in scores.error)
            ms = 1e3 * wall
            print(f'| {S} | {"on" if rival else "off"} | {closest} | {scores.switches} | '
                  f'{scores.idf1:.3f} | {err} | {crops:.1f} | {discoveries} | '
                  f'{np.median(ms):.2f} ({np.percentile(ms, 90):.2f}) | '
                  f'{1e3 * np.median(cpu):.2f} |')
    print(f'# loadavg at end {os.getloadavg()}')


if __name__ == '__main__':
    main()
