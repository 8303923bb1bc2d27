"""Pairing frames across cameras by their times (no ROS).

A timestamps CSV has a header `camera,frame,time_s` and one row per frame (frame: the
0-based index in that camera's video or sorted image folder; time_s: seconds on a clock
shared by the cameras). Each frame of the reference camera (the first) is an instant; every
other camera contributes its nearest frame within the tolerance, else nothing.
"""
import csv
from pathlib import Path

import numpy as np


def read_timestamps(path, names, counts):
    """{camera: times (frames,) s, NaN for frames not listed} from a timestamps CSV.

    names: the input cameras; counts: {camera: frames}. Raises ValueError naming the file
    and line for a bad header, an unknown camera, a frame out of range, a repeated frame,
    a time that is not a finite number, or a camera with no row."""
    path = Path(path)
    times = {n: np.full(counts[n], np.nan) for n in names}
    with open(path, newline='') as handle:
        reader = csv.DictReader(handle)
        if reader.fieldnames is None or not {'camera', 'frame', 'time_s'} <= set(
                reader.fieldnames):
            raise ValueError(f'{path}: header must have camera,frame,time_s (got '
                             f'{",".join(reader.fieldnames or [])})')
        for line, row in enumerate(reader, start=2):
            cam = row['camera']
            if cam not in times:
                raise ValueError(f'{path}: line {line}: camera {cam!r} is not an input '
                                 f'camera ({", ".join(names)})')
            try:
                frame, time = int(row['frame']), float(row['time_s'])
            except (TypeError, ValueError):
                raise ValueError(f'{path}: line {line}: frame must be an integer and time_s '
                                 f'a number, got {row["frame"]!r}, {row["time_s"]!r}') from None
            if not 0 <= frame < counts[cam]:
                raise ValueError(f'{path}: line {line}: frame {frame} of camera {cam!r} is '
                                 f'out of range (it has {counts[cam]} frames)')
            if not np.isfinite(time):
                raise ValueError(f'{path}: line {line}: time_s must be finite, got {time}')
            if np.isfinite(times[cam][frame]):
                raise ValueError(f'{path}: line {line}: frame {frame} of camera {cam!r} '
                                 'is listed twice')
            times[cam][frame] = time
    for cam in names:
        if not np.isfinite(times[cam]).any():
            raise ValueError(f'{path}: no row for camera {cam!r}')
    return times


def pair_by_time(times, names, tolerance_s=None):
    """(instants, C) frame indices (-1 = no frame within tolerance) pairing each camera's
    nearest frame to each timed frame of the first camera.

    tolerance_s: default half the median frame interval of the first camera."""
    ref = times[names[0]]
    ref_frames = np.flatnonzero(np.isfinite(ref))
    ref_times = ref[ref_frames]
    if tolerance_s is None:
        steps = np.diff(np.sort(ref_times))
        tolerance_s = 0.5 * float(np.median(steps)) if steps.size else np.inf
    out = np.full((len(ref_frames), len(names)), -1, np.int64)
    out[:, 0] = ref_frames
    for c, name in enumerate(names[1:], start=1):
        t = times[name]
        frames = np.flatnonzero(np.isfinite(t))
        order = np.argsort(t[frames])
        frames, sorted_t = frames[order], t[frames][order]
        pos = np.clip(np.searchsorted(sorted_t, ref_times), 1, max(len(sorted_t) - 1, 1))
        lo = np.clip(pos - 1, 0, len(sorted_t) - 1)
        hi = np.clip(pos, 0, len(sorted_t) - 1)
        nearest = np.where(np.abs(sorted_t[lo] - ref_times) <= np.abs(sorted_t[hi] - ref_times),
                           lo, hi)
        ok = np.abs(sorted_t[nearest] - ref_times) <= tolerance_s
        out[ok, c] = frames[nearest[ok]]
    return out


def apply_pairing(detections, pairing):
    """CameraDetections re-indexed by instants (pairing (instants, C) from pair_by_time):
    corners NaN where a camera has no frame at an instant."""
    from dataclasses import replace
    out = []
    for c, d in enumerate(detections):
        index = pairing[:, c]
        corners = np.full((len(index),) + d.corners.shape[1:], np.nan)
        corners[index >= 0] = d.corners[index[index >= 0]]
        out.append(replace(d, corners=corners))
    return out
