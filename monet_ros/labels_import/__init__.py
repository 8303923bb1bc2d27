"""Importers: other tools' 2D labels -> monet_ros.labels.LabelRow lists (one module per
format). The rows keep the source's camera / keypoint names and frame indices; the one
validator, monet_ros.labels.resolve_labels, checks them against a recording.

import_labels(fmt, paths, cameras=..., camera=None, min_score=0.0, camera_map=None)
-> ImportResult(rows, keypoints, note). Errors are monet_ros.labels.LabelError naming the
file and the row / field.
"""
from dataclasses import dataclass, field
from pathlib import Path

from monet_ros.labels import LabelError


@dataclass
class ImportResult:
    """rows: LabelRow list; keypoints: names in the source's order; note: what was left
    out on purpose (e.g. points below --min-score), '' when nothing; frame_counts:
    {source: frames} for the files that declare their length (a SLEAP analysis file's
    frame axis, a prediction table's rows), whatever their last detection."""
    rows: list
    keypoints: tuple
    note: str = ''
    frame_counts: dict = field(default_factory=dict)


def camera_for(source_name, cameras=(), camera=None, camera_map=None):
    """The recording camera a source name (video folder, file name, SLEAP video path)
    belongs to: `camera` when given; else an exact name or --camera-map entry; else the
    longest map source / recording camera name contained in it (as anipose matches
    cameras to files); else the source name itself (the validator then names it)."""
    if camera:
        return camera
    camera_map = dict(camera_map or {})
    name = Path(str(source_name)).stem if '/' in str(source_name) else str(source_name)
    if name in cameras:
        return name
    if name in camera_map:
        return camera_map[name]
    candidates = [(len(src), dst) for src, dst in camera_map.items() if src in name]
    candidates += [(len(c), c) for c in cameras if c in name]
    if candidates:
        return max(candidates)[1]
    return name


def _frames_csv(paths, **_):
    from monet_ros.labels import read_label_rows
    rows = [row for path in paths for row in read_label_rows(path)]
    return ImportResult(rows, tuple(dict.fromkeys(r.keypoint for r in rows)))


def _load(module, function):
    def call(paths, **kwargs):
        import importlib
        return getattr(importlib.import_module(f'monet_ros.labels_import.{module}'),
                       function)(paths, **kwargs)
    return call


FORMATS = {
    'dlc': _load('dlc', 'import_dlc'),            # DeepLabCut / Lightning Pose
    'lightning-pose': _load('dlc', 'import_dlc'),
    'anipose': _load('anipose', 'import_anipose'),
    'sleap': _load('sleap', 'import_sleap'),
    'dannce': _load('dannce', 'import_dannce'),
    'openpose': _load('openpose', 'import_openpose'),   # OpenPose / Pose2Sim JSON folders
    'frames': _frames_csv,
    'stamps': _frames_csv,
}


def import_labels(fmt, paths, cameras=(), camera=None, min_score=0.0, camera_map=None,
                  options=None):
    """ImportResult of labels files in format `fmt` (see FORMATS). paths: a path or a list
    (files, or folders searched for the format's files); cameras: the recording's camera
    names (to match file / video names to cameras); options: the format's own keyword
    arguments (openpose: pose_model, keypoints)."""
    if fmt not in FORMATS:
        raise LabelError(f'unknown labels format {fmt!r}; one of {", ".join(sorted(FORMATS))}')
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    for p in paths:
        if not p.exists():
            raise LabelError(f'{p}: no such file or folder')
    return FORMATS[fmt](paths, cameras=tuple(cameras), camera=camera,
                        min_score=float(min_score), camera_map=camera_map or {},
                        **(options or {}))
