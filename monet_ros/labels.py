"""2D keypoint labels of multiview recordings: a small CSV format (no ROS).

Format (UTF-8 CSV, one labelled keypoint per row, comma separated, header required)::

    stamp_ns,camera,keypoint,u,v
    1767225600000000000,cam0,head,312.25,101.5
    1767225600000000000,cam1,head,298.0,97.75

- stamp_ns: the image's header stamp in integer nanoseconds (the views of one instant
  share it);
- camera: the camera name of the rig file (cam0, cam1, ...);
- keypoint: a keypoint name of the skeleton (config/skeletons/*.yaml);
- u, v: pixel column and row in the ORIGINAL image (pixel centres on integers, lens
  distortion NOT removed), finite decimals.

A keypoint that is not labelled in a view simply has no row. Rows may come in any order;
a (stamp_ns, camera, keypoint) triple may appear only once. `monet synth` labels every
keypoint that projects inside the image, occluded ones included (see its README).

read_labels(path, keypoints) -> Labels: stamp_ns -> camera -> (C, 2) float64 array in
keypoint order, NaN where unlabelled. write_labels(path, rows) writes atomically.
"""
import csv
from dataclasses import dataclass
import math
import os
from pathlib import Path

import numpy as np

HEADER = ('stamp_ns', 'camera', 'keypoint', 'u', 'v')


class LabelError(ValueError):
    """A labels file is malformed; the message names the file, line and field."""


@dataclass(frozen=True)
class Labels:
    """Labels of a recording.

    keypoints: names in channel order; frames: {stamp_ns: {camera: (C, 2) float64 array}},
    NaN where a keypoint is not labelled in that view.
    """

    keypoints: tuple
    frames: dict

    @property
    def stamps(self):
        """Labelled instants, sorted (list of int ns)."""
        return sorted(self.frames)

    @property
    def cameras(self):
        """Camera names with at least one label, sorted."""
        return sorted({cam for views in self.frames.values() for cam in views})

    @property
    def num_points(self):
        """Number of labelled (instant, camera, keypoint) triples."""
        return int(sum(np.isfinite(a[:, 0]).sum() for v in self.frames.values()
                       for a in v.values()))

    def __len__(self):
        return len(self.frames)

    def points(self, stamp_ns, cameras):
        """(V, C, 2) labels of one instant in the order of `cameras` (names), NaN where a
        view or keypoint is unlabelled."""
        views = self.frames.get(int(stamp_ns), {})
        out = np.full((len(cameras), len(self.keypoints), 2), np.nan)
        for i, cam in enumerate(cameras):
            if cam in views:
                out[i] = views[cam]
        return out

    def rows(self):
        """(stamp_ns, camera, keypoint, u, v) tuples, sorted by stamp, camera, channel."""
        for stamp in self.stamps:
            views = self.frames[stamp]
            for cam in sorted(views):
                for c, (u, v) in enumerate(views[cam]):
                    if np.isfinite(u) and np.isfinite(v):
                        yield stamp, cam, self.keypoints[c], float(u), float(v)


def _keypoint_names(keypoints):
    if keypoints is None:
        return None
    names = getattr(keypoints, 'keypoints', keypoints)     # a Skeleton or a list of names
    return tuple(str(k) for k in names)


def read_labels(path, keypoints=None):
    """Labels from a CSV file (format in the module docstring).

    keypoints: a Skeleton or a list of names fixing the channel order (a row naming any
    other keypoint is an error); None = the names found in the file, sorted.
    Raises LabelError naming the file, line and field for any malformed row.
    """
    path = Path(path)
    names = _keypoint_names(keypoints)
    try:
        handle = open(path, newline='', encoding='utf-8-sig')
    except OSError as error:
        raise LabelError(f'{path}: cannot open labels file ({error.strerror})') from None
    parsed = []
    with handle:
        reader = csv.reader(handle)
        try:
            header = next(reader, None)
            if header is None:
                raise LabelError(f'{path}: empty file, expected the header '
                                 f'{",".join(HEADER)}')
            if tuple(h.strip() for h in header) != HEADER:
                raise LabelError(f'{path}:1: header is {",".join(header)!r}, expected '
                                 f'{",".join(HEADER)!r}')
            for row in reader:
                line = reader.line_num
                if not row or all(not cell.strip() for cell in row):
                    continue
                parsed.append(_parse_row(path, line, row, names))
        except csv.Error as error:
            raise LabelError(f'{path}:{reader.line_num}: not valid CSV ({error})') from None
        except UnicodeDecodeError as error:
            raise LabelError(f'{path}: not UTF-8 text ({error})') from None
    if names is None:
        names = tuple(sorted({row[2] for row in parsed}))
    index = {k: i for i, k in enumerate(names)}
    frames = {}
    seen = {}
    for line, stamp, camera, keypoint, u, v in ((r[5], *r[:5]) for r in parsed):
        key = (stamp, camera, keypoint)
        if key in seen:
            raise LabelError(f'{path}:{line}: duplicate label for stamp_ns={stamp} '
                             f'camera={camera} keypoint={keypoint} (first on line '
                             f'{seen[key]})')
        seen[key] = line
        views = frames.setdefault(stamp, {})
        if camera not in views:
            views[camera] = np.full((len(names), 2), np.nan)
        views[camera][index[keypoint]] = (u, v)
    return Labels(keypoints=names, frames=frames)


def _parse_row(path, line, row, names):
    """(stamp_ns, camera, keypoint, u, v, line) of one CSV row, or LabelError."""
    if len(row) != len(HEADER):
        raise LabelError(f'{path}:{line}: expected {len(HEADER)} fields '
                         f'({",".join(HEADER)}), got {len(row)}')
    stamp_text, camera, keypoint, u_text, v_text = (cell.strip() for cell in row)
    try:
        stamp = int(stamp_text)
    except ValueError:
        raise LabelError(f'{path}:{line}: field stamp_ns: {stamp_text!r} is not an integer '
                         'number of nanoseconds') from None
    if stamp < 0:
        raise LabelError(f'{path}:{line}: field stamp_ns: must be >= 0, got {stamp}')
    if not camera:
        raise LabelError(f'{path}:{line}: field camera: empty')
    if not keypoint:
        raise LabelError(f'{path}:{line}: field keypoint: empty')
    if names is not None and keypoint not in names:
        raise LabelError(f'{path}:{line}: field keypoint: {keypoint!r} is not a keypoint of '
                         f'the skeleton ({", ".join(names)})')
    coords = []
    for field, text in (('u', u_text), ('v', v_text)):
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise LabelError(f'{path}:{line}: field {field}: {text!r} is not a finite number')
        coords.append(value)
    return stamp, camera, keypoint, coords[0], coords[1], line


def write_labels(path, rows):
    """Write labels atomically (tmp file + os.replace).

    rows: a Labels, or an iterable of (stamp_ns, camera, keypoint, u, v); rows with a
    non-finite u or v are skipped (unlabelled). Floats are written with repr, so reading
    back gives the same float64 values. Returns the number of rows written.
    """
    path = Path(path)
    items = rows.rows() if isinstance(rows, Labels) else rows
    tmp = path.with_name(path.name + '.tmp')
    count = 0
    with open(tmp, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle, lineterminator='\n')
        writer.writerow(HEADER)
        for stamp, camera, keypoint, u, v in items:
            u, v = float(u), float(v)
            if not (math.isfinite(u) and math.isfinite(v)):
                continue
            writer.writerow((int(stamp), str(camera), str(keypoint), repr(u), repr(v)))
            count += 1
    os.replace(tmp, path)
    return count


def label_rows(stamps, cameras, keypoints, points2d):
    """Rows for write_labels from arrays: stamps (L,) ns, cameras (V,) names, keypoints (C,)
    names, points2d (L, V, C, 2) pixels with NaN = unlabelled."""
    points2d = np.asarray(points2d, dtype=np.float64)
    expected = (len(stamps), len(cameras), len(keypoints), 2)
    if points2d.shape != expected:
        raise ValueError(f'points2d has shape {points2d.shape}, expected {expected}')
    for i, stamp in enumerate(stamps):
        for j, cam in enumerate(cameras):
            for c, name in enumerate(keypoints):
                u, v = points2d[i, j, c]
                if np.isfinite(u) and np.isfinite(v):
                    yield int(stamp), cam, name, float(u), float(v)
