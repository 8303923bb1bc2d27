"""Another tool's 2D detections as arrays for triangulation (`monet triangulate`; no ROS).

Reads any 2D table `monet labels import` reads (the same readers): DeepLabCut / Lightning
Pose prediction CSV / H5 (likelihood = score), SLEAP analysis H5 (point_scores = score),
anipose pose-2d folders, OpenPose / Pose2Sim JSON folders (c = score; labels_import.
openpose), and the frame-indexed points table frame,camera,keypoint,u,v
[,score] (monet_ros.labels, read_label_rows(points=True)). A detection without a score (a
source without scores, an empty / NaN likelihood or score cell beside a point) gets score
1, counted in the notes. Frames are the tables' frame indices (0-based video frames, kept
as numbered: a table that starts at frame 10 starts there); the arrays cover every frame
from the first to the last with a detection (a point with a position). Missing points
(NaN / empty u, v of a points table; the readers' missing points, labels_import) are
counted as NaN rows, one count for every format. Per-camera files of one recording must have one
length: a file's declared frame count (a SLEAP file's frame axis, a prediction table's
rows), else its last frame + 1.
"""
from dataclasses import dataclass, replace
import math
from pathlib import Path

import numpy as np

from monet_ros.cores import available_memory
from monet_ros.labels import LabelError, read_label_rows
from monet_ros.labels_import import ImportResult, import_labels

FORMATS = ('auto', 'dlc', 'lightning-pose', 'sleap', 'anipose', 'openpose', 'frames')
# `monet triangulate --subjects 2` peaked at ~125 bytes of memory per (frame, camera,
# keypoint) of the frame span (2.4 GB for 200 001 frames x 4 cameras x 24 keypoints, 4.6 GB
# for 400 001), every frame of the span held whether detected or not
BYTES_PER_ENTRY = 128
READ = ('DeepLabCut / Lightning Pose prediction .csv or .h5 per camera, SLEAP analysis .h5 '
        'or .slp per camera, an anipose pose-2d folder, OpenPose / Pose2Sim JSON folders (one per '
        'camera), or a frame,camera,keypoint,u,v[,score][,subject] .csv')


@dataclass
class Points2D:
    """frames (T,) int frame indices (the source's numbers); cameras (V,) names; keypoints
    (C,); points (T, V, C, 2) px (NaN = missing); score (T, V, C) (NaN = missing); fmt: the
    format read; rows: rows read (detections and missing points); nan_rows: rows with NaN
    / inf u / v: a points table's, and the readers' missing points (NaN / inf coordinates,
    SLEAP's unoccupied tracks and invisible nodes, OpenPose's c = 0: labels_import),
    counted here for every format, also those outside the span of frames with
    detections;
    unscored: detections without a score (given score 1); notes: what the reader left out
    or decided, one line each."""
    frames: np.ndarray
    cameras: tuple
    keypoints: tuple
    points: np.ndarray
    score: np.ndarray
    fmt: str
    rows: int
    nan_rows: int
    unscored: int = 0
    notes: tuple = ()


def _h5_is_sleap(path):
    import h5py
    try:
        with h5py.File(path, 'r') as f:
            return 'tracks' in f
    except (OSError, ValueError):
        return False


def detect_format(paths):
    """The format of 2D table paths (list of Path): dlc, sleap, anipose, openpose or
    frames. Raises LabelError naming the file and the formats read when it is none."""
    first = paths[0]
    if first.is_dir():
        h5 = sorted(first.rglob('*.h5'))
        if h5:
            return 'sleap' if _h5_is_sleap(h5[0]) else 'anipose'
        if any(f.suffix.lower() == '.csv' and ('DLC' in f.name or
                                               f.name.startswith('CollectedData'))
               for f in first.rglob('*')):
            return 'dlc'
        if next(first.rglob('*.json'), None) is not None:
            return 'openpose'
        raise LabelError(f'{first}: no 2D tables found in the folder; read: {READ}')
    suffix = first.suffix.lower()
    if suffix == '.json':
        return 'openpose'
    if suffix in ('.h5', '.hdf5'):
        return 'sleap' if _h5_is_sleap(first) else 'dlc'
    if suffix == '.slp':
        return 'sleap'
    if suffix == '.csv':
        try:
            with open(first, encoding='utf-8-sig') as f:
                line = f.readline()
        except (OSError, UnicodeDecodeError) as error:
            raise LabelError(f'{first}: cannot read ({error})') from None
        if not line:
            raise LabelError(f'{first}: the file is empty (no header line)')
        if not line.strip():
            raise LabelError(f'{first}:1: the header line is blank')
        head = line.split(',')[0].strip()
        if head == 'scorer':
            return 'dlc'
        if head == 'frame':
            return 'frames'
        raise LabelError(f'{first}:1: first field {head!r}: neither a DeepLabCut table '
                         "('scorer') nor a points table "
                         "('frame,camera,keypoint,u,v[,score][,subject]')")
    raise LabelError(f'{first}: not a 2D table; read: {READ}')


def read_points2d(paths, cameras, fmt='auto', keypoints=None, camera_map=None,
                  pose_model=None):
    """Points2D of 2D tables.

    paths: a path or list (files, or a folder); cameras: the rig's camera names (V, in
    rig order: the output's order; cameras with no detection stay NaN); fmt: one of
    FORMATS; keypoints: names fixing the output's keypoints and order (a detection of
    another keypoint is an error), None = the sources' keypoints in their order;
    camera_map: {source camera: rig camera}; pose_model: the keypoint names of OpenPose
    JSON (a name of geometry.pose2sim.POSE_MODELS; labels_import.openpose).
    Raises LabelError (one line naming the file and field) for an unknown camera or
    keypoint, a wrong column set, a (frame, camera, keypoint) given twice, per-camera
    files of different lengths, or nothing to read."""
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    for p in paths:
        if not p.exists():
            raise LabelError(f'{p}: no such file or folder')
    if fmt not in FORMATS:
        raise LabelError(f'unknown 2D format {fmt!r}; one of {", ".join(FORMATS)}')
    if fmt == 'auto':
        fmt = detect_format(paths)
    cameras = tuple(cameras)
    camera_map = dict(camera_map or {})
    if fmt == 'frames':
        rows = [r for p in paths for r in read_label_rows(p, points=True)]
        rows = [replace(r, camera=camera_map.get(r.camera, r.camera)) for r in rows]
        result = ImportResult(rows, tuple(dict.fromkeys(r.keypoint for r in rows)))
    else:
        options = dict(pose_model=pose_model, keypoints=keypoints) if fmt == 'openpose' \
            else None
        result = import_labels(fmt, paths, cameras=cameras, camera_map=camera_map,
                               options=options, keep_missing=True)
    rows = result.rows
    if not any(math.isfinite(r.u) and math.isfinite(r.v) for r in rows):
        raise LabelError(f'{", ".join(map(str, paths))}: no 2D detections found')
    if result.instance_keypoints:    # several animals: '<instance>/<keypoint>' per camera
        rows = [replace(r, keypoint=f'{r.instance}/{r.keypoint}') if r.instance else r
                for r in rows]
        result = replace(result, rows=rows, keypoints=result.instance_keypoints)
    for r in rows:
        if r.camera not in cameras:
            raise LabelError(f'{r.place}: field camera: {r.camera!r} is not a camera of the '
                             f'rig ({", ".join(cameras)}); --camera-map SRC=DST renames')
    names = tuple(keypoints) if keypoints is not None else result.keypoints
    kindex = {k: i for i, k in enumerate(names)}
    for r in rows:
        if r.keypoint not in kindex and '/' in r.keypoint and keypoints is not None:
            # '<instance>/<keypoint>' (module docstring of labels): the one-subject read
            instances = {k.split('/', 1)[0] for k in result.keypoints if '/' in k}
            raise LabelError(f'{r.place}: holds {len(instances)} instances per camera (a '
                             'subject column, SLEAP tracks or DeepLabCut individuals: '
                             f'{r.keypoint.split("/", 1)[0]!r}, ...): give --subjects N '
                             '(the most subjects in a frame)')
        if r.keypoint not in kindex:
            raise LabelError(f'{r.place}: field keypoint: {r.keypoint!r} is not a keypoint '
                             f'of the skeleton ({", ".join(names)})')
    _check_lengths(rows, result.frame_counts)
    uv = np.array([(r.u, r.v) for r in rows], np.float64)
    present = np.isfinite(uv).all(-1)
    # every missing point of every format counted here: a NaN / inf row of a points
    # table, and the rows of the readers' missing points (labels_import, keep_missing)
    nan_rows = int((~present).sum())
    uv[~present] = np.nan
    frame = np.array([r.frame for r in rows], np.int64)
    first, last = int(frame[present].min()), int(frame[present].max())
    T, V, C = last - first + 1, len(cameras), len(names)
    inside = np.flatnonzero((frame >= first) & (frame <= last))   # the span of detections
    rows = [rows[i] for i in inside]
    frame, uv, present = frame[inside], uv[inside], present[inside]
    _check_span(rows, frame, T, V, C)
    cindex = {c: i for i, c in enumerate(cameras)}
    t = frame - first
    v = np.array([cindex[r.camera] for r in rows])
    c = np.array([kindex[r.keypoint] for r in rows])
    flat = (t * V + v) * C + c
    unique, counts = np.unique(flat, return_counts=True)
    if (counts > 1).any():
        twice = unique[counts > 1][0]
        r = rows[int(np.flatnonzero(flat == twice)[1])]
        raise LabelError(f'{r.place}: frame {r.frame} camera {r.camera} keypoint '
                         f'{r.keypoint} is given twice')
    points = np.full((T, V, C, 2), np.nan)
    score = np.full((T, V, C), np.nan)
    s = np.array([np.nan if r.score is None else r.score for r in rows], np.float64)
    unscored = present & np.isnan(s)
    s[unscored] = 1.0                   # no score: as a source without scores
    points[t, v, c] = uv
    score[t, v, c] = s
    notes = [result.note] if result.note else []
    if unscored.any():
        notes.append(f'{int(unscored.sum())} of {int(present.sum())} detections have no score '
                     '(no score column, or an empty / NaN likelihood or score cell): score 1 '
                     'used')
    return Points2D(frames=np.arange(first, last + 1), cameras=cameras, keypoints=names,
                    points=points, score=score, fmt=fmt, rows=len(result.rows),
                    nan_rows=nan_rows,
                    unscored=int(unscored.sum()), notes=tuple(notes))


def _check_span(rows, frame, T, V, C, available=None):
    """The arrays cover every frame of the span (T frames): refuse a span whose
    triangulation would not fit in the memory available (BYTES_PER_ENTRY per frame, camera
    and keypoint; cores.available_memory, or `available` bytes), e.g. one mistyped frame
    number far beyond the others. LabelError naming the row whose frame lies farthest from
    the median frame, the span, how many frames have detections, and the sizes."""
    available = available_memory() if available is None else available
    need = T * V * C * BYTES_PER_ENTRY
    if available is None or need <= available:
        return
    far = int(np.argmax(np.abs(frame - np.median(frame))))
    r = rows[far]
    raise LabelError(f'{r.place}: field frame: {r.frame} makes the frames span '
                     f'{int(frame.min())}..{int(frame.max())} ({T} frames, '
                     f'{len(np.unique(frame))} with detections), about {need / 1e9:.3g} GB to '
                     f'triangulate, more than the {available / 1e9:.3g} GB of memory '
                     'available: fix the frame number, or split the table')


def _check_lengths(rows, frame_counts=None):
    """Per-camera files (each file one camera) must cover the same frames: LabelError
    naming two files whose frame counts differ. A file's count is its declared one
    (frame_counts {source: frames}: a SLEAP file's frame axis, a prediction table's rows),
    else its last frame + 1."""
    frame_counts = frame_counts or {}
    by_source = {}
    for r in rows:
        entry = by_source.setdefault(r.source, [set(), -1])
        entry[0].add(r.camera)
        entry[1] = max(entry[1], r.frame)
    if len(by_source) < 2 or any(len(cams) > 1 for cams, _ in by_source.values()):
        return
    lengths = {src: frame_counts.get(src, last + 1) for src, (_, last) in by_source.items()}
    if len(set(lengths.values())) > 1:
        (a, na), (b, nb) = sorted(lengths.items(), key=lambda kv: kv[1])[::len(lengths) - 1]
        raise LabelError(f'{a}: {na} frames but {b}: {nb} frames; the per-camera files of '
                         'one recording must cover the same frames')
