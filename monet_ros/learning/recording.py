"""A multiview recording in memory: cameras, decoded frames, labels and ground truth.

Frames are decoded once and kept in memory (fine for the small recordings used for
training on one machine). Points are in original image pixels; labels are (T, V, C, 2)
with NaN for "not labelled".
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np


class RecordingError(ValueError):
    """A recording, labels or ground-truth file is unusable; the message names it."""


@dataclass
class Recording:
    """name; cameras (V Camera); stamps (T,) int64 ns; frames: V arrays (T, H_v, W_v, 3) uint8
    rgb; keypoints (C names); labels (T, V, C, 2) px NaN = none; gt3d (T, C, 3) or None."""
    name: str
    cameras: list
    stamps: np.ndarray
    frames: list
    keypoints: tuple
    labels: np.ndarray
    gt3d: np.ndarray = None

    def __post_init__(self):
        T, V, C = len(self.stamps), len(self.cameras), len(self.keypoints)
        if len(self.frames) != V:
            raise RecordingError(f'{self.name}: {len(self.frames)} frame arrays for {V} cameras')
        for cam, f in zip(self.cameras, self.frames):
            if f.shape != (T, cam.height, cam.width, 3) or f.dtype != np.uint8:
                raise RecordingError(
                    f'{self.name}: frames of {cam.name} are {f.shape} {f.dtype}, expected '
                    f'({T}, {cam.height}, {cam.width}, 3) uint8')
        if self.labels.shape != (T, V, C, 2):
            raise RecordingError(f'{self.name}: labels {self.labels.shape} != {(T, V, C, 2)}')
        if self.gt3d is not None and self.gt3d.shape != (T, C, 3):
            raise RecordingError(f'{self.name}: ground truth {self.gt3d.shape} != {(T, C, 3)}')

    @property
    def num_instants(self):
        return len(self.stamps)

    @property
    def num_views(self):
        return len(self.cameras)

    @property
    def num_keypoints(self):
        return len(self.keypoints)

    def images(self, t):
        """The V images of instant t (list of (H, W, 3) uint8)."""
        return [f[t] for f in self.frames]

    @property
    def labelled_instants(self):
        """(L,) indices of instants with at least one label."""
        return np.flatnonzero(np.isfinite(self.labels[..., 0]).any(axis=(1, 2)))

    def subset(self, instants, name=None):
        """A recording of some instants (views and frames shared as array slices)."""
        idx = np.asarray(instants)
        return Recording(name or self.name, self.cameras, self.stamps[idx],
                         [f[idx] for f in self.frames], self.keypoints, self.labels[idx],
                         None if self.gt3d is None else self.gt3d[idx])


def labels_array(rows, stamps, camera_names, keypoints, source='labels'):
    """Label rows (stamp_ns, camera, keypoint, u, v) -> (T, V, C, 2) array, NaN elsewhere.

    Rows naming an unknown stamp, camera or keypoint raise a RecordingError naming the row;
    accepts tuples/lists or objects with those attributes / dict keys."""
    t_index = {int(s): i for i, s in enumerate(stamps)}
    v_index = {n: i for i, n in enumerate(camera_names)}
    c_index = {n: i for i, n in enumerate(keypoints)}
    out = np.full((len(stamps), len(camera_names), len(keypoints), 2), np.nan)
    for n, row in enumerate(rows):
        if isinstance(row, dict):
            values = [row[k] for k in ('stamp_ns', 'camera', 'keypoint', 'u', 'v')]
        elif hasattr(row, 'stamp_ns'):
            values = [getattr(row, k) for k in ('stamp_ns', 'camera', 'keypoint', 'u', 'v')]
        else:
            values = list(row)
        stamp, camera, keypoint, u, v = values
        where = f'{source}: row {n + 1} ({stamp}, {camera}, {keypoint})'
        if int(stamp) not in t_index:
            raise RecordingError(f'{where}: stamp not in the recording')
        if camera not in v_index:
            raise RecordingError(f'{where}: camera not in the rig {list(camera_names)}')
        if keypoint not in c_index:
            raise RecordingError(f'{where}: keypoint not in the skeleton')
        out[t_index[int(stamp)], v_index[camera], c_index[keypoint]] = (float(u), float(v))
    return out


def load_ground_truth(path, stamps, num_keypoints):
    """ground_truth.npz (stamps_ns (T',), points3d (T', C, 3)) -> (T, C, 3) for `stamps`."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as error:
        raise RecordingError(f'{path}: cannot read ground truth ({error})') from None
    stamp_key = next((k for k in ('stamps_ns', 'stamp_ns', 'stamps') if k in data), None)
    point_key = next((k for k in ('points3d', 'keypoints3d', 'X') if k in data), None)
    if stamp_key is None or point_key is None:
        raise RecordingError(f'{path}: expected arrays stamps_ns and points3d, '
                             f'found {sorted(data.keys())}')
    gt_stamps = np.asarray(data[stamp_key]).astype(np.int64)
    points = np.asarray(data[point_key], dtype=np.float64)
    if points.ndim != 3 or points.shape[1:] != (num_keypoints, 3):
        raise RecordingError(f'{path}: field {point_key} is {points.shape}, '
                             f'expected (T, {num_keypoints}, 3)')
    lookup = {int(s): i for i, s in enumerate(gt_stamps)}
    out = np.full((len(stamps), num_keypoints, 3), np.nan)
    for i, s in enumerate(stamps):
        j = lookup.get(int(s))
        if j is not None:
            out[i] = points[j]
    return out
