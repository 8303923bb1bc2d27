"""Per-frame 3D keypoints as analysis tables: anipose's CSV and OpenSim / Pose2Sim TRC
(writers and readers; no ROS).

anipose CSV (what `anipose triangulate` writes, one row per frame): for every keypoint K
the columns K_x, K_y, K_z (the rig's length unit, stated in the sidecar file
<name>.units.json: csv_units_path), K_error (mean
reprojection error of the inlier views, px), K_ncams (inlier views), K_score (mean peak
confidence), then fnum (frame number); monet adds stamp_ns (header stamp, ns) at the end.
With a filter (`--filter kalman|optim`) the points are the filtered ones, K_score their
confidence, and two more columns per keypoint come after the keypoint groups, before fnum
(anipose's readers ignore them): K_change_mm (|filtered - raw|, mm) and K_bridged (1 where
the raw point was missing and the filter bridged the gap, else 0).
Missing values are empty cells (pandas' default), as anipose's own files.

TRC (OpenSim's marker file, the layout Pose2Sim writes; tab separated):
    PathFileType  4  (X/Y/Z)  <file name>
    DataRate CameraRate NumFrames NumMarkers Units OrigDataRate OrigDataStartFrame
    OrigNumFrames / their values
    Frame#  Time  <marker 1>  ''  ''  <marker 2> ...
    ''  ''  X1 Y1 Z1 X2 ...
    then one row per frame: Frame# (1-based), Time (s), X Y Z per marker.
monet writes the rig's world frame as it is (Units: the rig's unit, m / cm / mm);
Pose2Sim's demo .trc is Y-up
(trc(X, Y, Z) = world(Y, Z, X)): pass axes='yzx' for OpenSim's convention. Frame numbers
count instants from the first processed one at the median frame period, so a gap in the
recording is a gap in Frame#; the rate is the median stamp period's, snapped to 0.001 Hz
when within 1e-4 Hz.

One time base for every export (TIME_BASE): time of an instant = (its header stamp - the
time origin) / 1e9 s. The origin is the first exported instant's stamp (a recording,
`monet process`: the first instant is 0.0) unless the writer is given origin_ns: 2D tables
(`monet triangulate`) have stamps = source frame / fps (+ a start time the source gives)
and origin 0, so an export's time is its source's (video frame 10 at 30 fps: 0.333 s). TRC
Time and the NWB timestamps (export_nwb) are the same numbers.
Frame numbers (SOURCE_FRAMES): CSV fnum = the source's frame number (anipose's meaning,
0-based) when the writer is given fnum (2D tables: the tables' own frame numbers, a table
that starts late keeps them), else counted from the stamps as above; TRC Frame# = fnum + 1
(OpenSim's 1-based numbering, as Pose2Sim writes frame 0 as Frame# 1).
(Pose2Sim writes Time = Frame# / DataRate, one period later; readers here place TRC rows
by Frame#, which both agree on.)
"""
import csv
import os
from pathlib import Path

import numpy as np

from monet_ros.labels import frame_period_ns

FIELDS = ('x', 'y', 'z', 'error', 'ncams', 'score')
TIME_BASE = ('seconds from the time origin: the first exported instant, or frame 0 of the '
             'source for 2D tables (frame / fps)')
EXTRA_FIELDS = ('change_mm', 'bridged')
AXES = {'xyz': (0, 1, 2), 'yzx': (1, 2, 0)}


class ExportError(ValueError):
    """A table that cannot be written or read; the message names the file and field."""


def frame_numbers(stamps_ns):
    """(T,) 0-based frame numbers of stamps at the median period (gaps kept); (T,) zeros
    for a single instant."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    period = frame_period_ns(stamps)
    if period <= 0:
        return np.zeros(len(stamps), np.int64)
    return np.round((stamps - stamps[0]) / period).astype(np.int64)


def export_times(stamps_ns, origin_ns=None):
    """(T,) seconds of each instant from the time origin (TIME_BASE): origin_ns (int ns),
    default the first stamp. The time column of every export."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    if not len(stamps):
        return np.zeros(0)
    return (stamps - (stamps[0] if origin_ns is None else np.int64(origin_ns))) / 1e9


def source_frames(stamps_ns, fnum=None):
    """(T,) int frame numbers of the exported instants (SOURCE_FRAMES in the module
    docstring): fnum as given (the source's own), else frame_numbers(stamps_ns).
    Raises ExportError when fnum is not T integers."""
    if fnum is None:
        return frame_numbers(stamps_ns)
    out = np.asarray(fnum)
    if out.shape != (len(stamps_ns),) or (out.size and not np.issubdtype(out.dtype,
                                                                          np.integer)):
        raise ExportError(f'fnum: expected {len(stamps_ns)} integer frame numbers, got '
                          f'shape {out.shape} {out.dtype}')
    return out.astype(np.int64)


def _cell(x, integer=False):
    if not np.isfinite(x):
        return ''
    return str(int(x)) if integer else repr(float(x))


def _atomic_writer(path):
    path = Path(path)
    return path, path.with_name(path.name + '.tmp')


def csv_units_path(path):
    """The sidecar of a 3D CSV that states its units: keypoints3d.csv -> keypoints3d.units.json
    (anipose's CSV layout has no place for them)."""
    path = Path(path)
    return path.with_name(path.stem + '.units.json')


def read_csv_units(path):
    """The length unit ('m', 'cm', 'mm') a 3D CSV's sidecar states, or None without one.
    ExportError naming the sidecar when it is unreadable or states another unit."""
    import json

    from monet_ros.geometry.units import check_units
    side = csv_units_path(path)
    if not side.is_file():
        return None
    try:
        return check_units(json.loads(side.read_text())['length_unit'])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ExportError(f'{side}: field length_unit: unreadable ({error})') from None


def write_anipose_csv(path, keypoints, stamps_ns, X, error, ncams, score, extra=None,
                      units='m', fnum=None, subject=None):
    """Write anipose's 3D CSV. X (T, C, 3) in `units` (the rig's length unit, written to
    the sidecar csv_units_path(path)); error, ncams, score (T, C); extra: None or
    {field: (T, C)} for fields of EXTRA_FIELDS (module docstring); fnum: None or (T,) int
    the source's frame numbers (source_frames); subject: None or (T,) int, a `subject`
    column before fnum (several subjects: one row per frame and subject, the T rows then
    repeat stamps and frame numbers). Atomic."""
    import json
    extra = {f: np.asarray(v, float) for f, v in (extra or {}).items()}
    bad = [f for f in extra if f not in EXTRA_FIELDS]
    if bad:
        raise ExportError(f'{path}: unknown extra column {bad[0]!r}; one of {EXTRA_FIELDS}')
    X = np.asarray(X, float)
    T, C = X.shape[:2]
    fnum = source_frames(stamps_ns, fnum)
    path, tmp = _atomic_writer(path)
    with open(tmp, 'w', newline='', encoding='utf-8') as f:
        w = csv.writer(f, lineterminator='\n')
        w.writerow([f'{k}_{field}' for k in keypoints for field in FIELDS]
                   + [f'{k}_{field}' for field in extra for k in keypoints]
                   + ([] if subject is None else ['subject']) + ['fnum', 'stamp_ns'])
        for t in range(T):
            row = []
            for c in range(C):
                row += [_cell(X[t, c, 0]), _cell(X[t, c, 1]), _cell(X[t, c, 2]),
                        _cell(error[t, c]), _cell(ncams[t, c], True), _cell(score[t, c])]
            for field, values in extra.items():
                row += [_cell(values[t, c], field == 'bridged') for c in range(C)]
            ident = [] if subject is None else [int(subject[t])]
            w.writerow(row + ident + [int(fnum[t]), int(stamps_ns[t])])
    side, side_tmp = _atomic_writer(csv_units_path(path))
    side_tmp.write_text(json.dumps({
        'file': path.name, 'length_unit': units,
        'columns': {'<keypoint>_x, _y, _z': units, '<keypoint>_error': 'px',
                    '<keypoint>_change_mm': 'mm', 'stamp_ns': 'ns'}}, indent=1) + '\n')
    os.replace(side_tmp, side)
    os.replace(tmp, path)
    return path


def read_anipose_csv(path):
    """dict(keypoints, fnum (T,), stamps_ns (T,) or None, X (T, C, 3), error, ncams, score
    (T, C), extra {field: (T, C)} of the EXTRA_FIELDS columns present, subject (T,) int or
    None without a subject column: several subjects' rows) of an anipose 3D
    CSV (anipose's own or ours). Raises ExportError naming the file, line and column."""
    path = Path(path)
    try:
        with open(path, newline='', encoding='utf-8-sig') as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise ExportError(f'{path}: cannot read ({error})') from None
    if not rows:
        raise ExportError(f'{path}: empty file')
    header = rows[0]
    keypoints = [h[:-2] for h in header if h.endswith('_x') and h[:-2] + '_z' in header]
    if not keypoints:
        raise ExportError(f'{path}:1: no <keypoint>_x/_y/_z columns (anipose 3D layout)')
    col = {h: i for i, h in enumerate(header)}
    T, C = len(rows) - 1, len(keypoints)
    present = [f for f in EXTRA_FIELDS if any(f'{k}_{f}' in col for k in keypoints)]
    out = {f: np.full((T, C), np.nan) for f in FIELDS + tuple(present)}
    for t, row in enumerate(rows[1:]):
        for c, k in enumerate(keypoints):
            for f in out:
                i = col.get(f'{k}_{f}')
                if i is None or i >= len(row) or not row[i].strip():
                    continue
                try:
                    out[f][t, c] = float(row[i])
                except ValueError:
                    raise ExportError(f'{path}:{t + 2}: column {k}_{f}: {row[i]!r} is not a '
                                      'number') from None

    def ints(name):
        if name not in col:
            return None
        def one(text):
            try:
                return int(text)
            except ValueError:
                return int(float(text))        # '7.0' as pandas may write it
        try:
            return np.array([one(r[col[name]]) for r in rows[1:]], np.int64)
        except (ValueError, IndexError, OverflowError):
            raise ExportError(f'{path}: column {name}: not integers') from None
    fnum = ints('fnum')
    return dict(keypoints=tuple(keypoints), fnum=np.arange(T) if fnum is None else fnum,
                stamps_ns=ints('stamp_ns'), X=np.stack([out['x'], out['y'], out['z']], -1),
                error=out['error'], ncams=out['ncams'], score=out['score'],
                extra={f: out[f] for f in present}, subject=ints('subject'))


def write_trc(path, keypoints, stamps_ns, X, axes='xyz', units='m', fnum=None,
              origin_ns=None, rate_hz=None):
    """Write a TRC marker file (module docstring). X (T, C, 3) world in `units` (the
    rig's, the header's Units); axes 'xyz' (as is) or 'yzx' (Y-up as Pose2Sim / OpenSim:
    trc = world(Y, Z, X)); fnum (T,) source frame numbers (Frame# = fnum + 1) and origin_ns
    (Time origin): None = counted from the first stamp (TIME_BASE, SOURCE_FRAMES); rate_hz:
    DataRate when known (default: the median stamp period's). Atomic."""
    if axes not in AXES:
        raise ExportError(f'axes must be one of {sorted(AXES)}, got {axes!r}')
    X = np.asarray(X, float)[..., list(AXES[axes])]
    T, C = X.shape[:2]
    period = frame_period_ns(stamps_ns)
    rate = float(rate_hz) if rate_hz else 1e9 / period if period > 0 else 0.0
    if abs(rate - round(rate, 3)) < 1e-4:      # integer-ns periods: 16666667 ns -> 60 Hz
        rate = round(rate, 3)
    fnum = source_frames(stamps_ns, fnum) + 1
    path, tmp = _atomic_writer(path)
    rate_text = f'{rate:g}'
    lines = [f'PathFileType\t4\t(X/Y/Z)\t{path.name}',
             'DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t'
             'OrigDataStartFrame\tOrigNumFrames',
             f'{rate_text}\t{rate_text}\t{T}\t{C}\t{units}\t{rate_text}\t'
             f'{int(fnum[0]) if T else 1}\t{T}',
             'Frame#\tTime\t' + ''.join(f'{k}\t\t\t' for k in keypoints)[:-1],
             '\t\t' + '\t'.join(f'{a}{c + 1}' for c in range(C) for a in 'XYZ')]
    times = export_times(stamps_ns, origin_ns)
    for t in range(T):
        time = float(times[t])
        lines.append(f'{int(fnum[t])}\t{time!r}\t'
                     + '\t'.join(_cell(v) for v in X[t].reshape(-1)))
    with open(tmp, 'w', encoding='utf-8', newline='') as f:
        f.write('\n'.join(lines) + '\n')
    os.replace(tmp, path)
    return path


def read_trc(path, axes='xyz'):
    """dict(keypoints, frames (T,) 1-based, times (T,) s, X (T, C, 3), rate, units) of a TRC
    file (Pose2Sim's, OpenSim's or ours). axes='yzx' undoes a Y-up file (world = trc(Z, X,
    Y)). Missing / NaN values are NaN. Raises ExportError naming the file, line, field."""
    path = Path(path)
    if axes not in AXES:
        raise ExportError(f'axes must be one of {sorted(AXES)}, got {axes!r}')
    try:
        lines = Path(path).read_text(encoding='utf-8-sig').splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise ExportError(f'{path}: cannot read ({error})') from None
    if len(lines) < 5 or not lines[0].startswith('PathFileType'):
        raise ExportError(f'{path}:1: not a TRC file (expected PathFileType ...)')
    keys, values = lines[1].split('\t'), lines[2].split('\t')
    meta = dict(zip((k.strip() for k in keys), (v.strip() for v in values)))
    try:
        rate = float(meta.get('DataRate', 'nan'))
    except ValueError:
        raise ExportError(f'{path}:3: field DataRate: {meta.get("DataRate")!r}') from None
    names = [n.strip() for n in lines[3].split('\t')[2:] if n.strip()]
    frames, times, data = [], [], []
    for number, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.split('\t')
        try:
            frames.append(int(float(cells[0])))
            times.append(float(cells[1]))
            row = [float(c) if c.strip() else np.nan for c in cells[2:2 + 3 * len(names)]]
        except (ValueError, IndexError):
            raise ExportError(f'{path}:{number}: not a row of numbers') from None
        row += [np.nan] * (3 * len(names) - len(row))
        data.append(row)
    X = np.array(data, float).reshape(len(data), len(names), 3)
    inverse = np.argsort(AXES[axes])
    return dict(keypoints=tuple(names), frames=np.array(frames, np.int64),
                times=np.array(times), X=X[..., inverse], rate=rate,
                units=meta.get('Units', ''))
