"""The demo assets of `monet pipeline` with no arguments (not a subcommand).

What a lab would do, small: a synthetic 4-camera recording (`monet synth`) labelled at 3
instants of 90 (the subject's left limbs in their own colour, so that left and right can be
told apart), and a small detector trained on it with `monet train`'s recipe at a short
budget (600 steps, mode supervised: the labelled instants only; pseudo-labels need about
2000 steps to pay off, bench/results/accuracy.md), made
once and cached in ~/.cache/monet_ros/demo/v3 (or --workdir / $MONET_DEMO_DIR); later runs
start at once. The demo replays in lockstep (every frame fused before the next is
published: crops follow the subject; at real-time pace the frames a busy CPU drops leave
crops behind and the 3D error doubles). While it runs, GroundTruthScore compares every
fused frame with the recording's ground truth: 3D error (mm), PCK of the detections (px)
and left/right swaps, printed beside the reprojection error (which measures agreement
between the views, not accuracy).
"""
from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import sys
import threading
import time

import numpy as np

# Bump when the recording or the recipe changes: older caches are left alone, not reused.
CACHE_KEY = 'v3'
DEFAULT_WORKDIR = Path.home() / '.cache' / 'monet_ros' / 'demo'
SYNTH_ARGS = ['--cameras', '4', '--frames', '90', '--fps', '30', '--width', '320',
              '--height', '240', '--label-fraction', '0.034', '--distinct-sides', '--seed', '0',
              '--quiet']
# The default recipe (TrainConfig) with a small input for 320x240 images and a step budget
# of a few minutes on two busy cores (supervised, said explicitly: at 500 steps
# pseudo-labels cost accuracy, measured); one torch thread (two were 10x slower there).
TRAIN_ARGS = ['--mode', 'supervised', '--architecture', 'small', '--input-size', '128',
              '--steps', '600',
              '--checkpoint-every', '600', '--threads', '1', '--no-progress']
PCK_PX = (2, 5, 10)


@dataclass(frozen=True)
class DemoAssets:
    bag: Path
    rig: Path
    model: Path
    ground_truth: Path = None
    skeleton: str = 'human14'

    def scorer(self):
        """A GroundTruthScore for this recording (None without ground truth)."""
        if self.ground_truth is None or not Path(self.ground_truth).is_file():
            return None
        return GroundTruthScore(self.ground_truth, self.rig, self.skeleton)


def _say(text):
    print(f'monet pipeline: {text}', file=sys.stderr, flush=True)


def prepare_demo(workdir=None):
    """Make (once) and return the demo recording, rig, ground truth and model."""
    from monet_ros.cli import main as monet

    root = Path(workdir or os.environ.get('MONET_DEMO_DIR', DEFAULT_WORKDIR)) / CACHE_KEY
    root.mkdir(parents=True, exist_ok=True)       # OSError naming the folder when it cannot
    data = root / 'synth'
    model = root / 'model.pt'
    if not (data / 'recording' / 'metadata.yaml').is_file():
        start = time.monotonic()
        _say(f'generating a synthetic recording in {data} (once) ...')
        shutil.rmtree(data, ignore_errors=True)
        if monet(['synth', '--out', str(data), *SYNTH_ARGS]) != 0:
            raise ValueError(f'--workdir {root}: the demo recording could not be made')
        _say(f'recording ready ({time.monotonic() - start:.0f} s)')
    if not model.is_file():
        start = time.monotonic()
        train_dir = root / 'train'
        _say(f'training a small detector on its 3 labelled instants (the default recipe) '
             f'in {train_dir} (once, a few minutes) ...')
        shutil.rmtree(train_dir, ignore_errors=True)
        if monet(['train', str(data), '--out', str(train_dir), *TRAIN_ARGS]) != 0:
            raise ValueError(f'--workdir {root}: the demo model could not be trained')
        shutil.copyfile(train_dir / 'model.pt', root / '.model.pt.tmp')
        os.replace(root / '.model.pt.tmp', model)
        _say(f'model ready ({time.monotonic() - start:.0f} s)')
    return DemoAssets(bag=data / 'recording', rig=data / 'rig.yaml', model=model,
                      ground_truth=data / 'ground_truth.npz')


class GroundTruthScore:
    """Accuracy of fused frames against a recording's ground truth (thread-safe listener).

    ground_truth: ground_truth.npz (stamps (T,) ns, keypoints3d (T, C, 3) world metres,
    as `monet synth` writes it); rig:
    the rig file (cameras in the fusion node's order); skeleton: preset or YAML (symmetric
    pairs). A looped replay's shifted stamps (player: span + one period per pass) are mapped
    back to the recording's. on_fused(stamp_ns, FusionResult, filtered=None) accumulates, per
    keypoint, the 3D error (mm; NaN = not triangulated) of the raw fusion result and, when
    the fusion node's live filter is on (filtered (C, 3) m: what it publishes on
    keypoints3d), of the filtered keypoints too; for frames with every view, the 2D distance
    of each view's decoded peak to the ground truth's projection (px), and counts left/right
    swaps (raw): symmetric pairs whose crossed assignment is closer to the truth than the
    direct one.
    """

    def __init__(self, ground_truth, rig, skeleton='human14'):
        from monet_ros.geometry import load_rig
        from monet_ros.geometry.units import rig_units, to_mm
        from monet_ros.skeleton import load_skeleton

        data = np.load(ground_truth, allow_pickle=False)
        stamp_key = next(k for k in ('stamps_ns', 'stamp_ns', 'stamps') if k in data)
        point_key = next(k for k in ('points3d', 'keypoints3d', 'X') if k in data)
        self.stamps = np.asarray(data[stamp_key], np.int64)
        self.points = np.asarray(data[point_key], np.float64)
        self.cameras = load_rig(rig)
        self.mm = to_mm(1.0, rig_units(self.cameras))      # ground truth in the rig's unit
        self.skeleton = load_skeleton(skeleton)
        self.keypoints = list(self.skeleton.keypoints)
        index = {k: i for i, k in enumerate(self.keypoints)}
        self.pairs = np.array([[index[a], index[b]] for a, b in self.skeleton.symmetric],
                              dtype=int).reshape(-1, 2)
        period = int(np.median(np.diff(self.stamps))) if len(self.stamps) > 1 else 1
        self.span = int(self.stamps[-1] - self.stamps[0]) + period
        self.lookup = {int(s): i for i, s in enumerate(self.stamps)}
        self.lock = threading.Lock()
        self.err3d, self.err2d, self.swapped, self.filtered3d = [], [], [], []
        self.unmatched = 0

    def instant(self, stamp_ns):
        """Index of the ground-truth instant of a (possibly loop-shifted) stamp, or None."""
        first = int(self.stamps[0])
        return self.lookup.get(first + (int(stamp_ns) - first) % self.span)

    def on_fused(self, stamp_ns, result, filtered=None):
        from monet_ros.geometry import project_views

        t = self.instant(stamp_ns)
        if t is None:
            with self.lock:
                self.unmatched += 1
            return
        truth = self.points[t]
        err = np.linalg.norm(result.X - truth, axis=1) * self.mm           # (C,) NaN = none
        d_direct = err[self.pairs].sum(axis=1)
        d_cross = (np.linalg.norm(result.X[self.pairs] - truth[self.pairs[:, ::-1]], axis=2)
                   * self.mm).sum(axis=1)
        swapped = np.where(np.isfinite(d_direct), d_cross < d_direct, np.nan)
        err2d = None
        if len(result.points2d) == len(self.cameras):
            uv = project_views(self.cameras, truth)                        # (V, C, 2)
            err2d = np.linalg.norm(result.points2d - uv, axis=-1)          # NaN = no peak
        with self.lock:
            self.err3d.append(err)
            if filtered is not None:
                self.filtered3d.append(np.linalg.norm(np.asarray(filtered) - truth, axis=1)
                                       * self.mm)
            self.swapped.append(swapped)
            if err2d is not None:
                self.err2d.append(err2d)

    def figures(self):
        """dict: frames, median_mm, mean_mm, triangulated (share), pck{px} (share of views x
        keypoints), swapped (share of symmetric pairs), per-keypoint arrays (C,) (all of the
        raw fusion result); filtered_frames, filtered_median_mm, filtered_mean_mm (the live
        filter's output, over the frames it was on; NaN when never)."""
        with self.lock:
            err3d = np.array(self.err3d).reshape(-1, len(self.keypoints))
            filt = np.array(self.filtered3d).reshape(-1, len(self.keypoints))
            err2d = np.array(self.err2d).reshape(-1, len(self.cameras), len(self.keypoints))
            swapped = np.array(self.swapped).reshape(-1, len(self.pairs))
        ok = np.isfinite(err3d)
        d2 = np.where(np.isfinite(err2d), err2d, np.inf)
        with np.errstate(invalid='ignore'):
            out = {'frames': len(err3d),
                   'median_mm': float(np.median(err3d[ok])) if ok.any() else float('nan'),
                   'mean_mm': float(np.mean(err3d[ok])) if ok.any() else float('nan'),
                   'triangulated': float(ok.mean()) if ok.size else float('nan'),
                   'filtered_frames': len(filt),
                   'filtered_median_mm': float(np.nanmedian(filt)) if np.isfinite(filt).any()
                   else float('nan'),
                   'filtered_mean_mm': float(np.nanmean(filt)) if np.isfinite(filt).any()
                   else float('nan'),
                   'swapped': float(np.nanmean(swapped)) if swapped.size else float('nan'),
                   'keypoint_median_mm': np.array([np.median(e[np.isfinite(e)])
                                                   if np.isfinite(e).any() else np.nan
                                                   for e in err3d.T]),
                   'keypoint_pck5': (d2 <= 5).mean(axis=(0, 1)) if d2.size else None}
            for px in PCK_PX:
                out[f'pck{px}'] = float((d2 <= px).mean()) if d2.size else float('nan')
        return out

    def line(self):
        """One line: accuracy against the ground truth so far."""
        f = self.figures()
        if not f['frames']:
            return 'vs ground truth: no frame yet'
        filtered = ''
        if f['filtered_frames']:
            filtered = (f'; filtered (keypoints3d, {f["filtered_frames"]} frames) median '
                        f'{f["filtered_median_mm"]:.0f} mm (mean {f["filtered_mean_mm"]:.0f})')
        return (f'vs ground truth: raw 3D error median {f["median_mm"]:.0f} mm (mean '
                f'{f["mean_mm"]:.0f}){filtered}, {f["triangulated"]:.0%} triangulated, 2D PCK@'
                + '/'.join(str(px) for px in PCK_PX) + ' px '
                + '/'.join(f'{100 * f[f"pck{px}"]:.0f}' for px in PCK_PX)
                + f'%, left/right swapped {f["swapped"]:.0%}')

    def table(self):
        """Per keypoint: median 3D error (mm) and 2D PCK@5 px over the frames fused."""
        f = self.figures()
        lines = ['accuracy (raw fusion result) against the synthetic ground truth '
                 '(reprojection error measures '
                 'agreement between the views, not accuracy):',
                 f'  {"keypoint":<16}{"3D median mm":>14}{"PCK@5 px":>10}']
        for c, name in enumerate(self.keypoints):
            pck = f['keypoint_pck5']
            lines.append(f'  {name:<16}{f["keypoint_median_mm"][c]:14.0f}'
                         f'{100 * pck[c] if pck is not None else float("nan"):9.0f}%')
        lines.append(f'  over {f["frames"]} frames: {self.line()}')
        return '\n'.join(lines)
