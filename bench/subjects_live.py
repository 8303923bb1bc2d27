"""Several subjects live: the fusion node's core (subjects.detection.SubjectsCore.live_frame)
fed the crop slots a detector node publishes, in a lockstep loop, for 2 and 3 subjects.

Data: the subjects, rig and occlusion of bench/subjects.py (human14 subjects walking rings
of 0.7 / 1.4 / 2.1 m that pass each other, --cameras synthetic 640x480 cameras, --frames
frames at 30/s). Each frame the detector's part is simulated as the node does it
(nodes/detector.py process_subjects; published_slots here): the crop slots from the
previous frame's output (crop_rule.TrackedSubjects over the published subjects, at float32
like the topic), slots 0..N-1 the subject crops (Detector.boxes_for: grown to the
network's aspect), and while fewer than N are published slots N.. the discovery maps
(subjects.detection.discovery_boxes with --discovery-tiles, the node's default 2: a
640x480 frame, which would go into the network shrunk 3.3 times, as 6 square tiles of 320
px, neighbours overlapping by half; --discovery-tiles 0: one map of the whole frame padded
to the network's aspect), in the first frame of each --discovery-period-s window of the
stamps (the node's discovery_period_s, default 0.25 s: crop_rule.discovery_due; 0: every
frame). The boxes and heatmap grids are those of a real network of the
bench's input size (bench_detector: `small`, input 256 x 192 (H, W) -> 64 x 48 heatmaps,
random weights, never run; every slot is a 48 x 64 (w x h) map with its virtual camera
Camera.crop(box, (48, 64)), as Detector.predict's). The network's output is a "perfect
detector": every subject's visible keypoints (not hidden by a limb, inside the image)
rendered as Gaussians (sigma 1.5 heatmap px, peak 0.9 whichever subject the crop is for)
at their projection plus --noise source px of Gaussian noise. So it measures what fusion
adds live (crop-to-track matching, discovery on the tiles, instance decoding, association,
duplicates, tracking) and the cost per frame, not a network's accuracy.

Rows, with SubjectsConfig.rival_peaks off and on (the default): identity switches and IDF1
(subjects.metrics, match within --match-m), 3D error per subject (mm, matched frames),
live_frame per frame (wall median and p90, CPU of the thread median; heatmap peak decoding
included), crops per frame (the maps published: subject crops and discovery maps) and
the discovery runs. One subject through the same loop (N = 2, so discovery maps in every
discovery_period_s window) is the single-subject reference.

usage: python bench/subjects_live.py [--frames 300] [--cameras 8] [--noise 1] [--seed 0]
                                     [--discovery-tiles 2] [--discovery-period-s 0.25]
"""
import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')  # one core, before numpy loads BLAS

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from monet_ros.cores import cpu_model  # noqa: E402
from monet_ros.crop_rule import DISCOVERY_PERIOD_S, TrackedSubjects  # noqa: E402
from monet_ros.models import Detector, build_model  # noqa: E402
from monet_ros.skeleton import load_skeleton  # noqa: E402
from monet_ros.subjects.detection import (  # noqa: E402
    SubjectsConfig,
    SubjectsCore,
    discovery_boxes,
    subject_keypoints,
)
from monet_ros.subjects.metrics import identity_scores  # noqa: E402
from monet_ros.synth.rig import RigConfig, make_rig  # noqa: E402
from monet_ros.synth.subjects import make_subjects, subjects_occlusion  # noqa: E402

INPUT = (256, 192)      # the network's input (H, W) -> heatmaps (64, 48)
SIGMA = 1.5


def bench_detector(keypoints):
    """The detector whose boxes and heatmap grids the node would use: a real `small`
    network of input INPUT with random weights (never run: only its input_size,
    heatmap_size and boxes_for are used), for the keypoint names `keypoints`."""
    model = build_model('small', len(keypoints), width=8, input_size=INPUT)
    return Detector(model, {'keypoints': list(keypoints)}, device='cpu', fuse=False)


def published_slots(detector, cameras, boxes, tiles):
    """The crop slots a detector node publishes for one instant (nodes/detector.py
    process_subjects without `box`, the same functions): boxes (V, N + 1, 4) of
    crop_rule.TrackedSubjects.boxes (NaN: no crop). -> [(v, k, box)] with box (4,) the
    pixel edges the network crops (keep_aspect False): k < N the subject crops
    (Detector.boxes_for), k = N.. a view's discovery maps (discovery_boxes with
    discovery_tiles `tiles`, in its order) where boxes[v, N] is a crop; by view, then
    slot."""
    N = boxes.shape[1] - 1
    out = []
    for v, camera in enumerate(cameras):
        k = np.flatnonzero(np.isfinite(boxes[v, :N]).all(-1))
        out += [(v, int(j), box) for j, box in zip(k, detector.boxes_for([camera] * len(k),
                                                                         boxes[v, k]))]
        if np.isfinite(boxes[v, N]).all():
            found, = discovery_boxes(detector, [camera], tiles)
            out += [(v, N + j, box) for j, box in enumerate(found)]
    return out


def render(cam, box, grid, uv, visible):
    """(C, h, w) maps of the crop `box` (pixel edges) of camera `cam` on the heatmap grid
    (w, h) with Gaussians at the source pixels uv (S, C, 2) where visible (S, C), and the
    maps' K (3, 3) (Camera.crop(box, grid): Detector.predict's virtual camera)."""
    crop = cam.crop(box, grid)
    S_ = np.diag([crop.K[0, 0] / cam.K[0, 0], crop.K[1, 1] / cam.K[1, 1]])
    offset = crop.K[:2, 2] - S_ @ cam.K[:2, 2]
    p = uv @ S_.T + offset                                          # heatmap px (S, C, 2)
    v, u = np.mgrid[0:grid[1], 0:grid[0]]
    d2 = (u - p[..., 0, None, None]) ** 2 + (v - p[..., 1, None, None]) ** 2
    maps = np.where(visible[..., None, None], 0.9 * np.exp(-d2 / (2 * SIGMA ** 2)), 0.0)
    return maps.max(0).astype(np.float32), crop.K


def frame_maps(detector, cameras, boxes, tiles, uv, visible):
    """The maps the fusion node gives live_frame for one instant: the slots of
    published_slots rendered by the perfect detector on the network's heatmap grid.
    uv (V, S, C, 2) source px, visible (V, S, C). -> present (the views with a map, in
    increasing order), sub and full: [(index into present, heat (C, h, w), K_heat (3, 3))]
    of the subject crops and the discovery maps (a view's in discovery_boxes' order)."""
    grid = detector.heatmap_size[::-1]                                # (w, h)
    sub, full, present = [], [], []
    for v, k, box in published_slots(detector, cameras, boxes, tiles):
        heat, K = render(cameras[v], box, grid, uv[v], visible[v])
        if v not in present:
            present.append(v)
        (full if k >= boxes.shape[1] - 1 else sub).append((present.index(v), heat, K))
    return present, sub, full


def run(truth, hidden, cameras, noise, seed, N, rival_peaks=False, tiles=2, detector=None,
        period_s=0.0):
    T, S, C, _ = truth.shape
    rng = np.random.default_rng(seed)
    detector = detector or bench_detector(load_skeleton('human14').keypoints)
    core = SubjectsCore(C, 'm', SubjectsConfig(subjects=N, rival_peaks=rival_peaks,
                                               discovery_tiles=tiles))
    tracks = TrackedSubjects(units='m', discovery_period_s=period_s)
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
        present, sub, full = frame_maps(detector, cameras, boxes, tiles, uv, visible)
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
    parser.add_argument('--discovery-tiles', type=int, default=SubjectsConfig.discovery_tiles,
                        help="the detector node's discovery_tiles (default: its default; 0: "
                             'one discovery map of the whole frame per view)')
    parser.add_argument('--discovery-period-s', type=float, default=DISCOVERY_PERIOD_S,
                        help="the detector node's discovery_period_s (default: its default; "
                             '0: discovery maps in every frame with fewer than N subjects)')
    args = parser.parse_args(argv)
    if not args.discovery_period_s >= 0:
        parser.error(f'--discovery-period-s must be >= 0, got {args.discovery_period_s}')
    if args.discovery_tiles < 0:
        parser.error(f'--discovery-tiles must be >= 0, got {args.discovery_tiles}')
    sk = load_skeleton('human14')
    detector = bench_detector(sk.keypoints)
    times = np.arange(args.frames) / 30.0
    cameras = make_rig(RigConfig(num_cameras=args.cameras), seed=args.seed)
    print(f'# bench/subjects_live.py: {args.frames} frames at 30/s, {args.cameras} cameras, '
          f'human14, noise {args.noise} px, occluded keypoints not rendered, lockstep')
    slots = discovery_boxes(detector, cameras[:1], args.discovery_tiles)[0]
    print(f'# network input {INPUT[0]}x{INPUT[1]} (H x W) -> heatmaps '
          f'{detector.heatmap_size[0]}x{detector.heatmap_size[1]}; discovery_tiles '
          f'{args.discovery_tiles}: {len(slots)} discovery map(s) per '
          f'{cameras[0].width}x{cameras[0].height} view, sent in the first frame of each '
          f'{args.discovery_period_s:g} s window')
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
                truth, hidden, cameras, args.noise, args.seed + S, max(S, 2), rival,
                args.discovery_tiles, detector, args.discovery_period_s)
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
