"""Importers: other tools' 2D labels -> monet_ros.labels.LabelRow lists (one module per
format). The rows keep the source's camera / keypoint names and frame indices; the one
validator, monet_ros.labels.resolve_labels, checks them against a recording.

import_labels(fmt, paths, cameras=..., camera=None, min_score=0.0, camera_map=None)
-> ImportResult(rows, keypoints, note, frame_counts, subjects). Errors are
monet_ros.labels.LabelError naming the file and the row / field.

Missing points: a reader gives an entry of its source without a position (a NaN / inf
coordinate, SLEAP's unoccupied track or invisible node, OpenPose's c = 0) as a row with
u = v = NaN; import_labels counts them (ImportResult.missing) and leaves them out, or
keeps them (keep_missing: `monet triangulate`'s reader, points2d, counts them as its NaN
rows with those of a points table): one count for every format.

Several animals (SLEAP tracks, multi-animal DeepLabCut individuals) become subjects: each
distinct track / individual name gets an id 0, 1, ... in order of first appearance (files
in the order read, tracks / individuals in the file's order), the same id for the same
name in every file; a row's `subject` is that id, its `instance` the name, its keypoint
the plain node / bodypart. ImportResult.subjects is the mapping (and the note says it).
Training takes a subject id as naming one animal in every view of an instant
(monet_ros.labels), so the names must: a SLEAP project's tracks assigned across its
camera files, a DeepLabCut project's individuals. `monet triangulate --subjects` assumes
no such thing: its reader (points2d) names a detection '<instance>/<keypoint>' per camera
as before.
"""
from dataclasses import dataclass, field, replace
import math
from pathlib import Path

from monet_ros.labels import LabelError


@dataclass
class ImportResult:
    """rows: LabelRow list; keypoints: names in the source's order; note: what was left
    out on purpose (e.g. points below --min-score), '' when nothing; frame_counts:
    {source: frames} for the files that declare their length (a SLEAP analysis file's
    frame axis, a prediction table's rows), whatever their last detection; subjects:
    {instance name: subject id} of a source with several animals ({} for one);
    instance_keypoints: the sources' '<instance>/<keypoint>' names in their order (the
    keypoints of `monet triangulate --subjects`), () for one animal; missing: entries of
    the sources without a position (NaN / inf, not placed: module docstring), left out of
    rows unless import_labels(keep_missing=True)."""
    rows: list
    keypoints: tuple
    note: str = ''
    frame_counts: dict = field(default_factory=dict)
    subjects: dict = field(default_factory=dict)
    instance_keypoints: tuple = ()
    missing: int = 0


def subject_note(subjects, what):
    """'subjects: m1=0, m2=1 (DeepLabCut individuals)' or '' for none."""
    if not subjects:
        return ''
    return ('subjects: ' + ', '.join(f'{name}={i}' for name, i in subjects.items())
            + f' ({what})')


def join_notes(*notes):
    return '; '.join(n for n in notes if n)


def camera_for(source_name, cameras=(), camera=None, camera_map=None):
    """The recording camera a source name (video folder, file name, SLEAP video path)
    belongs to: `camera` when given; else an exact name or --camera-map entry; else the
    longest map source / recording camera name contained in it (as anipose matches
    cameras to files); else the longest recording camera name contained in it ignoring case
    and separators (cam01_json -> cam_01); else the source name itself (the validator then
    names it)."""
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
    # then ignoring case and separators: Pose2Sim's cam01_json folders for its calibration's
    # cam_01 (the longest such name; none when two are equally long)
    plain = _plain(name)
    loose = sorted(((len(_plain(c)), c) for c in cameras if _plain(c) and _plain(c) in plain),
                   reverse=True)
    if loose and (len(loose) == 1 or loose[0][0] > loose[1][0]):
        return loose[0][1]
    return name


def _plain(name):
    """A camera name without case and separators: 'Cam_01' -> 'cam01'."""
    return ''.join(ch for ch in str(name).lower() if ch.isalnum())


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
                  options=None, keep_missing=False):
    """ImportResult of labels files in format `fmt` (see FORMATS). paths: a path or a list
    (files, or folders searched for the format's files); cameras: the recording's camera
    names (to match file / video names to cameras); options: the format's own keyword
    arguments (openpose: pose_model, keypoints); keep_missing: keep the rows of missing
    points (u = v = NaN; module docstring), else left out; counted in `missing` either
    way."""
    if fmt not in FORMATS:
        raise LabelError(f'unknown labels format {fmt!r}; one of {", ".join(sorted(FORMATS))}')
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    for p in paths:
        if not p.exists():
            raise LabelError(f'{p}: no such file or folder')
    result = FORMATS[fmt](paths, cameras=tuple(cameras), camera=camera,
                          min_score=float(min_score), camera_map=camera_map or {},
                          **(options or {}))
    placed = [r for r in result.rows if math.isfinite(r.u) and math.isfinite(r.v)]
    missing = len(result.rows) - len(placed)
    return replace(result, rows=result.rows if keep_missing else placed, missing=missing)


# Formats keyed to the recording's own instants (monet's tables): in the recording's pixels.
# The others come from tools that label the source videos: in the videos' pixels.
RECORDING_FORMATS = ('frames', 'stamps')


def to_recording_pixels(rows, fmt, bag, label_scale='auto', camera_map=None):
    """(rows in the recording's pixels, note or '') - labels made on the source videos of a
    recording imported with `monet import videos --resize` brought to its images.

    label_scale: 'auto' - other tools' formats (not RECORDING_FORMATS) are mapped from each
    camera's video size to its recorded size, as monet_import.yaml beside the bag records
    (io.source_sizes; nothing to do without a record or a resize); a number S > 0 - every
    row mapped as images resized by S (u' = (u + 0.5) S - 0.5; 1 = already in the
    recording's pixels). The note says what was done (or assumed, where it matters).
    Raises LabelError for a bad label_scale or a malformed record."""
    from monet_ros.io.source_sizes import (
        SourceSizeError,
        read_source_sizes,
        scale_label_rows,
        uniform_scale,
        video_to_recording,
    )
    if label_scale != 'auto':
        try:
            scale = float(label_scale)
        except (TypeError, ValueError):
            scale = float('nan')
        if not 0 < scale < float('inf'):
            raise LabelError(f'--label-scale must be auto or a number > 0, got {label_scale!r}')
        if scale == 1.0:
            return list(rows), ''
        return (scale_label_rows(rows, {None: uniform_scale(scale)}),
                f'label pixels scaled by {scale:g} (--label-scale)')
    try:
        record = read_source_sizes(bag)
    except SourceSizeError as error:
        raise LabelError(str(error)) from None
    transforms = video_to_recording(record[1]) if record else {}
    if not transforms:
        return list(rows), ''
    sizes = ', '.join(f'{name} {s[0]}x{s[1]} -> {r[0]}x{r[1]}'
                      for name, (s, r) in record[1].items() if name in transforms)
    if fmt in RECORDING_FORMATS:
        return list(rows), (f"{fmt} labels taken in the recording's pixels (its images are "
                            f'the videos resized: {sizes}); --label-scale {record[0]:g} if '
                            "they are in the videos' pixels")
    return (scale_label_rows(rows, transforms, camera_map),
            f"labels scaled from the videos' pixels to the recording's ({sizes}: imported "
            f'with --resize {record[0]:g}); --label-scale 1 if they are already in the '
            "recording's pixels")
