"""A multiview recording in memory: cameras, decoded frames, labels and ground truth.

Frames are decoded once and kept in memory (fine for the small recordings used for
training on one machine). Points are in original image pixels; labels are (T, V, C, 2)
with NaN for "not labelled": subject 0's. A labels table with several subjects per instant
(monet_ros.labels, the `subject` column) adds the other subjects' labels as a list of
(instant, subject) entries: other_labels (J, V, C, 2), other_instants (J,), other_subjects
(J,), empty for a single-subject table.
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np


class RecordingError(ValueError):
    """A recording, labels or ground-truth file is unusable; the message names it."""


@dataclass
class Recording:
    """name; cameras (V Camera); stamps (T,) int64 ns; frames: V arrays (T, H_v, W_v, 3) uint8
    rgb; keypoints (C names); labels (T, V, C, 2) px NaN = none, subject 0's; gt3d (T, C, 3)
    or None; other_labels (J, V, C, 2) px: the labels of every other labelled subject
    (subject id other_subjects[j] >= 1 at instant other_instants[j]), None = none (J = 0)."""
    name: str
    cameras: list
    stamps: np.ndarray
    frames: list
    keypoints: tuple
    labels: np.ndarray
    gt3d: np.ndarray = None
    other_labels: np.ndarray = None
    other_instants: np.ndarray = None
    other_subjects: np.ndarray = None

    def __post_init__(self):
        V, C = len(self.cameras), len(self.keypoints)
        if self.other_labels is None:
            self.other_labels = np.full((0, V, C, 2), np.nan)
            self.other_instants = np.zeros(0, np.int64)
            self.other_subjects = np.zeros(0, np.int64)
        self.other_instants = np.asarray(self.other_instants, np.int64)
        self.other_subjects = np.asarray(self.other_subjects, np.int64)
        J = len(self.other_instants)
        if self.other_labels.shape != (J, V, C, 2) or self.other_subjects.shape != (J,):
            raise RecordingError(f"{self.name}: other subjects' labels "
                                 f'{self.other_labels.shape} / {self.other_subjects.shape}, '
                                 f'expected {(J, V, C, 2)} / {(J,)}')
        if J and not (0 <= self.other_instants.min() and
                      self.other_instants.max() < len(self.stamps)):
            raise RecordingError(f"{self.name}: other subjects' instants out of range")
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
        """(L,) indices of instants with at least one label (of any subject)."""
        mask = np.isfinite(self.labels[..., 0]).any(axis=(1, 2))
        mask[self.other_instants[np.isfinite(self.other_labels[..., 0]).any(axis=(1, 2))]] = True
        return np.flatnonzero(mask)

    @property
    def num_subjects(self):
        """Most subjects labelled at one instant (1 for a single-subject table)."""
        if not len(self.other_instants):
            return 1
        return 1 + int(np.bincount(self.other_instants).max())

    def subset(self, instants, name=None):
        """A recording of some instants (views and frames shared as array slices; the other
        subjects' labels of those instants kept, their instants renumbered)."""
        idx = np.arange(len(self.stamps))[np.asarray(instants)]
        where = {int(t): i for i, t in enumerate(idx)}
        keep = np.array([int(t) in where for t in self.other_instants], bool)
        return Recording(name or self.name, self.cameras, self.stamps[idx],
                         [f[idx] for f in self.frames], self.keypoints, self.labels[idx],
                         None if self.gt3d is None else self.gt3d[idx],
                         self.other_labels[keep],
                         np.array([where[int(t)] for t in self.other_instants[keep]],
                                  np.int64),
                         self.other_subjects[keep])


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


def find_recording_parts(path):
    """A `monet synth` output folder (recording/, rig.yaml, labels.csv, ground_truth.npz)
    or a bag path -> dict bag, rig, labels, ground_truth (None where absent). The folder
    rule is io.reader.recording_bag, which open_bag follows too."""
    from monet_ros.io.reader import recording_bag

    path = Path(path)
    parts = {'bag': recording_bag(path), 'rig': None, 'labels': None, 'ground_truth': None}
    if parts['bag'] != path:
        for key, name in (('rig', 'rig.yaml'), ('labels', 'labels.csv'),
                          ('ground_truth', 'ground_truth.npz')):
            if (path / name).is_file():
                parts[key] = path / name
    return parts


def load_recording(path, rig=None, labels=None, ground_truth=None, skeleton='human14',
                   slop_ns=0, max_instants=None, name=None, label_options=None,
                   shared_labels=False, rig_units=None):
    """Decode a recording (rosbag2 folder, .mcap, or a `monet synth` output folder) into memory.

    rig: rig file (default: the folder's rig.yaml, else CameraInfo + /tf_static of the bag);
    labels: labels CSV (default: the folder's labels.csv; none = no labels); ground_truth:
    ground_truth.npz (default: the folder's). Instants that lack a view are skipped (and
    counted in the returned recording's `skipped`). skeleton: keypoint names / preset.
    labels may also be a list of monet_ros.labels.LabelRow (an importer's output); they are
    checked by monet_ros.labels.resolve_labels with label_options (LabelOptions: name maps,
    skip_bad); a frame index counts every instant of the bag, incomplete ones included.
    The returned recording's `label_report` says how many rows were used / skipped.
    shared_labels: the labels file covers several recordings (the learner's bags): rows
    whose stamp lies outside this recording's time span are left to the others (counted as
    'other recordings', not errors). rig_units: the length unit of a rig file that states
    none (geometry.read_rig).
    A rig file's cameras are renamed by label_options.camera_map and fitted to the images
    (monet_ros.io.rig_fit: a full-resolution calibration for a half-resolution recording is
    scaled); `rig_notes` says what was adapted.
    Raises RecordingError (or LabelError, a ValueError) naming the file, line and field.
    """
    from monet_ros.io import iter_multiview_frames, open_bag, rig_from_bag
    from monet_ros.io.images import to_rgb8
    from monet_ros.io.multiview import image_topics
    from monet_ros.labels import LabelOptions, read_label_rows, resolve_labels
    from monet_ros.skeleton import load_skeleton

    parts = find_recording_parts(path)
    rig = rig or parts['rig']
    labels = labels or parts['labels']
    ground_truth = ground_truth or parts['ground_truth']
    keypoints = tuple(load_skeleton(skeleton).keypoints) if isinstance(skeleton, (str, Path)) \
        else tuple(skeleton)
    reader = open_bag(parts['bag'])
    cameras = rig_from_bag(reader, rig_file=rig, units=rig_units)
    rig_notes = []
    if rig is not None:       # a calibration file: names mapped, size fitted to the images
        from monet_ros.io.rig_fit import fit_rig_to_bag
        cameras, rig_notes = fit_rig_to_bag(
            cameras, reader, (label_options or LabelOptions()).camera_map)
    names = [c.name for c in cameras]
    topics = image_topics(reader, cameras, parts['bag'])
    stamps, frames, skipped = [], {n: [] for n in names}, 0
    all_stamps, complete = [], []          # every instant (labels' frame indices count these)
    for frame in iter_multiview_frames(reader, topics, slop_ns=slop_ns):
        all_stamps.append(int(frame.stamp_ns))
        complete.append(not frame.missing)
        if frame.missing:
            skipped += 1
            continue
        for cam in cameras:
            image = to_rgb8(frame.images[cam.name])    # grey / 16-bit -> rgb8, as live
            if image.shape[:2] != (cam.height, cam.width):
                raise RecordingError(f'{parts["bag"]}: camera {cam.name} image at '
                                     f'{frame.stamp_ns} is {image.shape} {image.dtype}, rig '
                                     f'says {cam.width}x{cam.height} uint8')
            frames[cam.name].append(image)
        stamps.append(int(frame.stamp_ns))
        if max_instants and len(stamps) >= max_instants:
            break
    if not stamps:
        raise RecordingError(f'{parts["bag"]}: no complete multiview instant on {topics}')
    stamps = np.array(stamps, dtype=np.int64)
    label_array = np.full((len(stamps), len(names), len(keypoints), 2), np.nan)
    label_report = None
    other_labels, other_instants, other_subjects = [], [], []
    if labels is not None:
        rows = read_label_rows(labels) if isinstance(labels, (str, Path)) else list(labels)
        truncated = bool(max_instants) and len(stamps) >= max_instants
        beyond = 0
        if shared_labels:
            half = (all_stamps[-1] - all_stamps[0]) // max(len(all_stamps) - 1, 1) // 2
            mine = [r for r in rows if r.stamp_ns is None
                    or all_stamps[0] - half <= r.stamp_ns <= all_stamps[-1] + half]
            others, rows = len(rows) - len(mine), mine
        if truncated:                     # rows after the last instant read are not errors
            limit = all_stamps[-1] + (all_stamps[-1] - all_stamps[0]) // max(
                len(all_stamps) - 1, 1) // 2
            keep = [r for r in rows if (r.frame is not None and r.frame < len(all_stamps))
                    or (r.stamp_ns is not None and r.stamp_ns <= limit)]
            beyond, rows = len(rows) - len(keep), keep
        table, label_report = resolve_labels(rows, all_stamps, cameras, keypoints,
                                             label_options or LabelOptions(), valid=complete)
        if shared_labels and others:
            label_report.skipped['other recordings'] = others
            label_report.first.setdefault('other recordings', f'{others} rows outside this '
                                          "recording's time span")
            label_report.rows += others
        if beyond:
            label_report.skipped['beyond --max-instants'] = beyond
            label_report.first.setdefault('beyond --max-instants',
                                          f'{beyond} rows after instant {max_instants}')
            label_report.rows += beyond
        if label_report.rows and not label_report.kept and not shared_labels:
            raise RecordingError(f'{labels if isinstance(labels, (str, Path)) else "labels"}:'
                                 f' no label matches the recording: {label_report.summary()}')
        index = {int(s): i for i, s in enumerate(stamps)}
        for stamp in table.stamps:
            label_array[index[int(stamp)]] = table.points(stamp, names)
            for subject in table.instant_subjects(stamp):
                if subject:
                    other_labels.append(table.points(stamp, names, subject))
                    other_instants.append(index[int(stamp)])
                    other_subjects.append(subject)
    gt = load_ground_truth(ground_truth, stamps, len(keypoints)) if ground_truth else None
    recording = Recording(
        name or Path(path).name, cameras, stamps, [np.stack(frames[n]) for n in names],
        keypoints, label_array, gt,
        np.array(other_labels).reshape(-1, len(names), len(keypoints), 2),
        np.array(other_instants, np.int64), np.array(other_subjects, np.int64))
    recording.skipped = skipped
    recording.read_report = reader.report      # what the bag read skipped (ok False: print)
    recording.label_report = label_report
    recording.rig_notes = rig_notes
    return recording
