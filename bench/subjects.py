"""Several subjects: association across cameras + identity tracking (monet_ros.subjects) on
synthetic 2D with known 3D and identities, for 1, 2 and 3 subjects.

Data: human14 subjects of monet_ros.synth.subjects walking rings of 0.7 / 1.4 / 2.1 m
(they pass each other again and again) for --frames frames at 30 frames/s, seen by a
synthetic ring of --cameras cameras (make_rig, 640x480, 60 deg); keypoints hidden by any
subject's limbs (another subject's body included) or outside the image are dropped, the
rest get --noise px Gaussian noise per coordinate, and the instance order is shuffled in
every camera and frame (synth.subjects.shuffled_instances).

Rows per subject count: identity switches and IDF1 (subjects.metrics, match within
--match-m), 3D error per subject (mean keypoint distance, mm; matched frames), and the
single-subject baseline on the same 2D: each subject's own instances (ground-truth
association) triangulated alone with the same robust triangulation
(geometry.triangulate_robust, 15 px exclusion); ratio = associated / baseline.
Speed: association + tracking per frame (wall clock: median and p90 over frames, ms; and
the CPU time of the thread, time.thread_time, median: on a shared machine the wall clock
includes waiting for a core), one BLAS thread, with os.getloadavg() and the CPU; the
target's setting is 2 subjects x 14 keypoints x 8 cameras (the default --cameras).

usage: python bench/subjects.py [--frames 300] [--cameras 8] [--noise 1] [--seed 0]
"""
import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')  # one core, before numpy loads BLAS

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from monet_ros.cores import cpu_model  # noqa: E402
from monet_ros.geometry import triangulate_robust  # noqa: E402
from monet_ros.skeleton import load_skeleton  # noqa: E402
from monet_ros.subjects import associate  # noqa: E402
from monet_ros.subjects.metrics import identity_scores  # noqa: E402
from monet_ros.subjects.tracking import SubjectTracker  # noqa: E402
from monet_ros.synth.rig import RigConfig, make_rig  # noqa: E402
from monet_ros.synth.subjects import (  # noqa: E402
    make_subjects,
    shuffled_instances,
    subjects_occlusion,
)


def run(points, cameras, times, C):
    """(X (T, H, C, 3), ids (T, H), per-frame wall seconds (T,), per-frame CPU seconds of
    this thread (T,)) of association + tracking."""
    T, V, N = points.shape[:3]
    tracker = SubjectTracker(C)
    H = max(1, N * V // 2)                       # most subjects a frame can hold
    X = np.full((T, H, C, 3), np.nan)
    ids = np.full((T, H), -1)
    spent = np.zeros(T)
    cpu = np.zeros(T)
    for t in range(T):
        start, start_cpu = time.perf_counter(), time.thread_time()
        a = associate(points[t], cameras)
        got = tracker.step(a.X, round(times[t] * 1e9))
        spent[t] = time.perf_counter() - start
        cpu[t] = time.thread_time() - start_cpu
        X[t, :len(got)], ids[t, :len(got)] = a.X, got
    used = max(1, int((ids >= 0).sum(1).max()))
    return X[:, :used], ids[:, :used], spent, cpu


def baseline(points, owner, cameras, S, C):
    """(T, S, C, 3): each subject's own instances triangulated alone (GT association)."""
    T, V = points.shape[:2]
    out = np.full((T, S, C, 3), np.nan)
    for g in range(S):
        slot = np.argmax(owner == g, axis=-1)                            # (T, V)
        seen = (owner == g).any(-1)
        pts = points[np.arange(T)[:, None], np.arange(V)[None], slot]    # (T, V, C, 2)
        pts = np.where(seen[..., None, None], pts, np.nan)
        flat = pts.transpose(1, 0, 2, 3).reshape(V, T * C, 2)
        X, _ = triangulate_robust(flat, cameras, threshold_px=15.0)
        out[:, g] = X.reshape(T, C, 3)
    return out


def mean_error_mm(X, truth):
    d = np.linalg.norm(X - truth, axis=-1).reshape(-1)
    return 1000 * float(np.nanmean(d))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--frames', type=int, default=300)
    parser.add_argument('--cameras', type=int, default=8)
    parser.add_argument('--noise', type=float, default=1.0)
    parser.add_argument('--match-m', type=float, default=0.2)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    sk = load_skeleton('human14')
    C = sk.num_keypoints
    times = np.arange(args.frames) / 30.0
    cameras = make_rig(RigConfig(num_cameras=args.cameras), seed=args.seed)
    print(f'# bench/subjects.py: {args.frames} frames at 30/s, {args.cameras} cameras, '
          f'human14, noise {args.noise} px, occluded keypoints dropped, instances '
          f'shuffled per camera and frame')
    print(f'# CPU: {cpu_model()}; loadavg at start {os.getloadavg()}')
    print('| subjects | closest pass (m) | hidden kp | IDSW | IDF1 | 3D error per subject '
          '(mm) | single-subject baseline (mm) | ratio | assoc+track ms/frame median '
          '(p90) | CPU ms/frame median | frames/s |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    for S in (1, 2, 3):
        subjects = make_subjects(sk, S, seed=args.seed)
        truth, hidden = subjects_occlusion(subjects, times, cameras)
        points, owner = shuffled_instances(truth, cameras, args.noise, seed=args.seed + S,
                                           hidden=hidden)
        X, ids, spent, cpu = run(points, cameras, times, C)
        scores = identity_scores(truth, X, ids, args.match_m)
        base = baseline(points, owner, cameras, S, C)
        base_err = [mean_error_mm(base[:, g], truth[:, g]) for g in range(S)]
        err = 1000 * scores.error
        ratio = ', '.join(f'{e / b:.2f}' for e, b in zip(err, base_err))
        if S > 1:
            root = truth[..., :2].mean(2)                                 # (T, S, 2)
            gaps = np.linalg.norm(root[:, :, None] - root[:, None], axis=-1)
            closest = f'{gaps[:, ~np.eye(S, dtype=bool)].min():.2f}'
        else:
            closest = '-'
        ms = 1e3 * spent
        print(f'| {S} | {closest} | {100 * hidden.mean():.1f}% | {scores.switches} | '
              f'{scores.idf1:.3f} | {", ".join(f"{e:.1f}" for e in err)} | '
              f'{", ".join(f"{b:.1f}" for b in base_err)} | {ratio} | '
              f'{np.median(ms):.2f} ({np.percentile(ms, 90):.2f}) | '
              f'{1e3 * np.median(cpu):.2f} | {1 / np.median(spent):.0f} |')
    print(f'# loadavg at end {os.getloadavg()}')


if __name__ == '__main__':
    main()
