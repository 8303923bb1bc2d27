"""2D keypoint labels of multiview recordings: the canonical table and its ONE validator
(no ROS). Used by `monet train`, `monet eval`, `monet info`, `monet labels import`.

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
a (stamp_ns, camera, keypoint[, subject]) may appear only once.

Several subjects (two mice, two monkeys in view): an optional last column `subject`, an
integer >= 0 (default 0: a file without the column is all subject 0)::

    stamp_ns,camera,keypoint,u,v,subject
    1767225600000000000,cam0,head,312.25,101.5,0
    1767225600000000000,cam0,head,512.0,140.25,1

A subject id is an instance label WITHIN one labelled instant: the same id in every view
of that instant names the same animal (so the views of an instant can be triangulated
together), but ids need not follow an animal from one labelled instant to the next.
write_labels writes the column only when some label is of a subject other than 0, so a
single-subject table is written exactly as before. `monet synth` labels every
keypoint that projects inside the image, occluded ones included (see its README).

A frame-indexed variant has `frame` (the 0-based index of the recording's multiview
instant, as `monet info` lists them) instead of `stamp_ns`::

    frame,camera,keypoint,u,v
    42,cam0,head,312.25,101.5

(with the same optional `subject` column).

A 2D points table (`monet triangulate`, read with read_label_rows(path, points=True))
is frame-indexed, may add a detection score column (frame,camera,keypoint,u,v,score) and
may hold empty / NaN u, v or score for a missing detection. A last `subject` column
(frame,camera,keypoint,u,v[,score],subject; `monet triangulate --subjects`) labels the
instance a detection belongs to within its camera and frame: the row's keypoint is read
as '<subject>/<keypoint>', as the SLEAP and DeepLabCut readers name several instances.

read_labels(path, keypoints) -> Labels: stamp_ns -> camera -> (C, 2) float64 array in
keypoint order, NaN where unlabelled (stamp-keyed files only). write_labels(path, rows)
writes atomically.

Labels against a recording (any source: either CSV, or an importer in
monet_ros.labels_import) go through ONE validator, `resolve_labels(rows, stamps, cameras,
keypoints, options)`:
- camera and keypoint names are mapped (`LabelOptions.camera_map`, `keypoint_map`, e.g.
  cam_01 -> cam01) and must then name a rig camera / skeleton keypoint;
- a `frame` must be an instant index 0..T-1; a `stamp_ns` matches the NEAREST instant
  within half the recording's median frame period (so a few ns of rounding match); a
  stamp that only matches after x1e6 / x1e3 / x1e9 is reported as milliseconds /
  microseconds / seconds instead of nanoseconds;
- u must lie in [-0.5, width - 0.5] and v in [-0.5, height - 0.5] (pixel-edge box of the
  camera's image, the convention of `monet synth`);
- a subject must be an integer 0..2**31 - 1 (MAX_SUBJECT);
- a (instant, camera, keypoint, subject) may be labelled once.
Every bad row raises LabelError naming file, line and field; with
`LabelOptions(skip_bad=True)` (`--skip-bad-labels`) it is dropped and counted by kind in
the returned LabelReport instead. Nothing is dropped silently.
"""
import csv
from dataclasses import dataclass, field
import math
import os
from pathlib import Path
import re

import numpy as np

HEADER = ('stamp_ns', 'camera', 'keypoint', 'u', 'v')
FRAME_HEADER = ('frame', 'camera', 'keypoint', 'u', 'v')
SCORED_FRAME_HEADER = FRAME_HEADER + ('score',)
SUBJECT_HEADERS = (FRAME_HEADER + ('subject',), SCORED_FRAME_HEADER + ('subject',))
# labels files with the optional subject column (an integer id; module docstring)
# the largest subject id: it travels as the UINT32 `subject` field of /monet/keypoints3d and
# as int32 / int64 arrays, so it must fit a signed 32-bit integer
MAX_SUBJECT = 2 ** 31 - 1
LABEL_SUBJECT_HEADERS = (HEADER + ('subject',), FRAME_HEADER + ('subject',))


class LabelError(ValueError):
    """A labels file is malformed; the message names the file, line and field."""


class LabelResolutionError(LabelError):
    """Labels refused whole: too many lie outside the images, as labels made at another
    resolution than the recording's (resolve_labels)."""


@dataclass(frozen=True)
class Labels:
    """Labels of a recording.

    keypoints: names in channel order; frames: {stamp_ns: {camera: (C, 2) float64 array}}
    of subject 0, NaN where a keypoint is not labelled in that view; others: the same for
    every other subject, {subject (int >= 1): {stamp_ns: {camera: (C, 2)}}} ({} for a
    single-subject table). A subject id names one animal within one instant (module
    docstring).
    """

    keypoints: tuple
    frames: dict
    others: dict = field(default_factory=dict)

    def _by_subject(self):
        """{subject: {stamp: {camera: (C, 2)}}} of every subject with a label."""
        out = {0: self.frames} if self.frames else {}
        out.update((s, f) for s, f in sorted(self.others.items()) if f)
        return out

    @property
    def subjects(self):
        """Subject ids with at least one label, sorted (list of int; [0] for a
        single-subject table, [] for an empty one)."""
        return sorted(self._by_subject())

    @property
    def stamps(self):
        """Labelled instants (of any subject), sorted (list of int ns)."""
        return sorted({s for f in self._by_subject().values() for s in f})

    @property
    def cameras(self):
        """Camera names with at least one label, sorted."""
        return sorted({cam for f in self._by_subject().values() for views in f.values()
                       for cam in views})

    @property
    def num_points(self):
        """Number of labelled (instant, camera, keypoint, subject) cells."""
        return int(sum(np.isfinite(a[:, 0]).sum() for f in self._by_subject().values()
                       for v in f.values() for a in v.values()))

    def __len__(self):
        """Labelled instants (of any subject)."""
        return len(self.stamps)

    def points(self, stamp_ns, cameras, subject=0):
        """(V, C, 2) labels of one subject (default 0) at one instant in the order of
        `cameras` (names), NaN where a view or keypoint is unlabelled."""
        frames = self.frames if subject == 0 else self.others.get(int(subject), {})
        views = frames.get(int(stamp_ns), {})
        out = np.full((len(cameras), len(self.keypoints), 2), np.nan)
        for i, cam in enumerate(cameras):
            if cam in views:
                out[i] = views[cam]
        return out

    def instant_subjects(self, stamp_ns):
        """Subjects labelled at one instant, sorted (list of int)."""
        return [s for s, f in self._by_subject().items() if int(stamp_ns) in f]

    def rows(self):
        """(stamp_ns, camera, keypoint, u, v) tuples of subject 0, sorted by stamp, camera,
        channel (subject_rows: every subject's)."""
        for stamp, cam, keypoint, u, v, _ in self.subject_rows(subjects=(0,)):
            yield stamp, cam, keypoint, u, v

    def subject_rows(self, subjects=None):
        """(stamp_ns, camera, keypoint, u, v, subject) tuples of `subjects` (default all),
        sorted by stamp, camera, subject, channel."""
        by_subject = self._by_subject()
        wanted = sorted(by_subject) if subjects is None else \
            [s for s in subjects if s in by_subject]
        for stamp in self.stamps:
            cams = sorted({c for s in wanted for c in by_subject[s].get(stamp, {})})
            for cam in cams:
                for s in wanted:
                    view = by_subject[s].get(stamp, {}).get(cam)
                    if view is None:
                        continue
                    for c, (u, v) in enumerate(view):
                        if np.isfinite(u) and np.isfinite(v):
                            yield stamp, cam, self.keypoints[c], float(u), float(v), s


def _keypoint_names(keypoints):
    if keypoints is None:
        return None
    names = getattr(keypoints, 'keypoints', keypoints)     # a Skeleton or a list of names
    return tuple(str(k) for k in names)


@dataclass(frozen=True)
class LabelRow:
    """One label as read from a source, before it is checked against a recording.

    source: file name (for messages); line: 1-based line (CSV) or row/record number;
    stamp_ns or frame (exactly one is not None); camera, keypoint: names as in the source;
    u, v: pixels (finite; NaN in a 2D points table and in the missing points of an
    importer, labels_import, kept with keep_missing only). where: how to name the place in
    messages (default 'line N'). score: the detection's confidence (likelihood) when the
    source has one, else None. subject: the labelled subject (int >= 0, checked by
    resolve_labels; module docstring); instance: the source's name of that subject (a
    SLEAP track, a DeepLabCut individual; '' when the source has one subject)."""
    source: str
    line: int
    stamp_ns: int | None
    frame: int | None
    camera: str
    keypoint: str
    u: float
    v: float
    where: str = ''
    score: float | None = None
    subject: int = 0
    instance: str = ''

    @property
    def place(self):
        return f'{self.source}:{self.where or self.line}'


def read_label_rows(path, points=False):
    """LabelRow list of a stamp-keyed or frame-indexed labels CSV (module docstring);
    points=True: a 2D points table instead (frame-indexed, optional score column, empty /
    NaN u, v, score allowed: NaN in the rows).

    Only the syntax is checked here (header, field count, integer stamp/frame, finite u/v,
    non-empty names); names, instants and bounds are checked by resolve_labels. Raises
    LabelError naming the file, line and field.
    """
    path = Path(path)
    try:
        handle = open(path, newline='', encoding='utf-8-sig')
    except OSError as error:
        raise LabelError(f'{path}: cannot open labels file ({error.strerror})') from None
    rows = []
    with handle:
        reader = csv.reader(handle)
        try:
            header = next(reader, None)
            if header is None:
                raise LabelError(f'{path}: empty file, expected the header '
                                 f'{",".join(HEADER)} or {",".join(FRAME_HEADER)}')
            header = tuple(h.strip() for h in header)
            allowed = (FRAME_HEADER, SCORED_FRAME_HEADER) if points else (HEADER, FRAME_HEADER)
            if points and header in SUBJECT_HEADERS:
                allowed = SUBJECT_HEADERS
            if not points and header in LABEL_SUBJECT_HEADERS:
                allowed = LABEL_SUBJECT_HEADERS
            if header not in allowed:      # every header that reads, subject ones too
                known = [','.join(h) for h in dict.fromkeys(
                    allowed + (SUBJECT_HEADERS if points else LABEL_SUBJECT_HEADERS))]
                raise LabelError(f'{path}:1: header is {",".join(header)!r}, expected '
                                 f'{", ".join(map(repr, known[:-1]))} or {known[-1]!r}')
            for row in reader:
                if not row or all(not cell.strip() for cell in row):
                    continue
                rows.append(_parse_row(path, reader.line_num, row, header, points))
        except csv.Error as error:
            raise LabelError(f'{path}:{reader.line_num}: not valid CSV ({error})') from None
        except UnicodeDecodeError as error:
            raise LabelError(f'{path}: not UTF-8 text ({error})') from None
    return rows


def read_labels(path, keypoints=None):
    """Labels from a stamp-keyed CSV file (format in the module docstring), without a
    recording: stamps are kept as written, cameras as named.

    keypoints: a Skeleton or a list of names fixing the channel order (a row naming any
    other keypoint is an error); None = the names found in the file, sorted.
    Raises LabelError naming the file, line and field for any malformed row, and for a
    frame-indexed file (that needs a recording: resolve_labels / load_recording).
    """
    rows = read_label_rows(path)
    names = _keypoint_names(keypoints)
    for row in rows:
        _check_subject(row)
        if row.stamp_ns is None:
            raise LabelError(f'{row.place}: field frame: a frame-indexed labels file needs '
                             'a recording to resolve frames to stamps (monet train/eval '
                             '--labels, or monet labels import frames)')
        if names is not None and row.keypoint not in names:
            raise LabelError(f'{row.place}: field keypoint: {row.keypoint!r} is not a '
                             f'keypoint of the skeleton ({", ".join(names)})')
    if names is None:
        names = tuple(sorted({row.keypoint for row in rows}))
    return _build_labels(rows, names, [r.stamp_ns for r in rows], [r.camera for r in rows],
                         [r.keypoint for r in rows])


def _check_subject(row):
    """None when row.subject is an integer 0..MAX_SUBJECT, else the reason (text)."""
    s = row.subject
    if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0:
        return f'{s!r} is not an integer >= 0 (the subject id within its instant)'
    if s > MAX_SUBJECT:
        return f'{s} is above {MAX_SUBJECT} (the largest subject id)'
    return None


def _build_labels(rows, names, stamps, cameras, keypoints):
    """Labels from rows and their resolved stamp, camera, keypoint (subject from the
    row); a bad subject or a duplicate raises."""
    index = {k: i for i, k in enumerate(names)}
    by_subject = {}
    seen = {}
    for row, stamp, camera, keypoint in zip(rows, stamps, cameras, keypoints):
        problem = _check_subject(row)
        if problem:
            raise LabelError(f'{row.place}: field subject: {problem}')
        subject = int(row.subject)
        key = (stamp, camera, keypoint, subject)
        if key in seen:
            raise LabelError(f'{row.place}: duplicate label for stamp_ns={stamp} '
                             f'camera={camera} keypoint={keypoint}'
                             + (f' subject={subject}' if subject else '')
                             + f' ({_first(seen[key], row)})')
        seen[key] = row
        views = by_subject.setdefault(subject, {}).setdefault(stamp, {})
        if camera not in views:
            views[camera] = np.full((len(names), 2), np.nan)
        views[camera][index[keypoint]] = (row.u, row.v)
    frames = by_subject.pop(0, {})
    return Labels(keypoints=tuple(names), frames=frames, others=by_subject)


def _first(first, row):
    """'first on line N' (same file) or 'first at FILE:WHERE'."""
    if first.source == row.source:
        return f'first on {first.where or f"line {first.line}"}'
    return f'first at {first.place}'


def _parse_row(path, line, row, header, points=False):
    """LabelRow of one CSV row, or LabelError. points: a 2D points table's row (NaN /
    empty u, v allowed; an optional score)."""
    if len(row) != len(header):
        raise LabelError(f'{path}:{line}: expected {len(header)} fields '
                         f'({",".join(header)}), got {len(row)}')
    key_text, camera, keypoint, u_text, v_text = (cell.strip() for cell in row[:5])
    key = header[0]
    try:
        value = int(key_text)
    except ValueError:
        what = 'an integer number of nanoseconds' if key == 'stamp_ns' else 'an integer'
        raise LabelError(f'{path}:{line}: field {key}: {key_text!r} is not {what}') from None
    if value < 0:
        raise LabelError(f'{path}:{line}: field {key}: must be >= 0, got {value}')
    if not camera:
        raise LabelError(f'{path}:{line}: field camera: empty')
    if not keypoint:
        raise LabelError(f'{path}:{line}: field keypoint: empty')
    coords = []
    for name, text in (('u', u_text), ('v', v_text)):
        coords.append(_number(path, line, name, text, points))
    score = _number(path, line, 'score', row[5].strip(), True) \
        if len(header) > 5 and header[5] == 'score' else None
    subject_id = 0
    if header[-1] == 'subject' and not points:            # a labels file: an integer id
        text = row[-1].strip()
        try:
            subject_id = int(text)
        except ValueError:
            subject_id = text       # _check_subject refuses it (or --skip-bad-labels drops it)
    elif header[-1] == 'subject':
        subject = row[-1].strip()
        if not subject or '/' in subject:
            raise LabelError(f'{path}:{line}: field subject: {subject!r} must be a '
                             "non-empty name without '/'")
        keypoint = f'{subject}/{keypoint}'
    stamp, frame = (value, None) if key == 'stamp_ns' else (None, value)
    return LabelRow(str(path), line, stamp, frame, camera, keypoint, coords[0], coords[1],
                    score=score, subject=subject_id)


def _number(path, line, name, text, missing_ok):
    """float of a cell; NaN for an empty / NaN cell when missing_ok; else LabelError."""
    if missing_ok and text.lower() in ('', 'nan'):
        return math.nan
    try:
        number = float(text)
    except ValueError:
        number = math.nan
    if not math.isfinite(number):
        raise LabelError(f'{path}:{line}: field {name}: {text!r} is not a finite number')
    return number


def write_labels(path, rows):
    """Write labels atomically (tmp file + os.replace).

    rows: a Labels (every subject), or an iterable of (stamp_ns, camera, keypoint, u, v) or
    (stamp_ns, camera, keypoint, u, v, subject); rows with a non-finite u or v are skipped
    (unlabelled). The subject column is written only when some row's subject is not 0: a
    single-subject table is written exactly as without subjects. Floats are written with
    repr, so reading back gives the same float64 values. Returns the number of rows
    written. Raises ValueError for a subject that is not an integer >= 0.
    """
    path = Path(path)
    items = rows.subject_rows() if isinstance(rows, Labels) else rows
    items = [(*item, 0) if len(item) == 5 else tuple(item) for item in items]
    for item in items:
        s = item[5]
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0:
            raise ValueError(f'write_labels: subject {s!r} of {item[:3]} is not an integer '
                             '>= 0')
    with_subject = any(item[5] != 0 for item in items)
    tmp = path.with_name(path.name + '.tmp')
    count = 0
    with open(tmp, 'w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle, lineterminator='\n')
        writer.writerow(HEADER + (('subject',) if with_subject else ()))
        for stamp, camera, keypoint, u, v, subject in items:
            u, v = float(u), float(v)
            if not (math.isfinite(u) and math.isfinite(v)):
                continue
            writer.writerow((int(stamp), str(camera), str(keypoint), repr(u), repr(v))
                            + ((int(subject),) if with_subject else ()))
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


# ------------------------------------------------------------------- the label validator

STAMP_UNITS = (('milliseconds', 1_000_000), ('microseconds', 1_000), ('seconds', 1_000_000_000))
SKIP_KINDS = ('camera', 'keypoint', 'instant', 'bounds', 'duplicate', 'subject')


def parse_name_map(items, what='camera'):
    """('a=b', 'c=d,e=f', ...) or a dict -> tuple of (source, target) pairs.

    Raises LabelError naming the bad item (an entry without '=' or an empty side)."""
    if isinstance(items, dict):
        return tuple((str(k), str(v)) for k, v in items.items())
    pairs = []
    for item in items or ():
        if isinstance(item, (tuple, list)) and len(item) == 2:
            pairs.append((str(item[0]), str(item[1])))
            continue
        for part in str(item).split(','):
            if not part.strip():
                continue
            source, sep, target = part.partition('=')
            if not sep or not source.strip() or not target.strip():
                raise LabelError(f'--{what}-map: {part!r} is not NAME=NEW_NAME')
            pairs.append((source.strip(), target.strip()))
    return tuple(pairs)


@dataclass(frozen=True)
class LabelOptions:
    """How labels are matched to a recording (validated on construction).

    camera_map, keypoint_map: (source name, recording name) pairs ('cam_01=cam01' strings
    are accepted too; keypoint_map also takes a shipped map's name, see
    monet_ros.keypoint_maps); skip_bad: drop and count bad rows instead of raising;
    stamp_tolerance: fraction of the median frame period within which a stamp matches its
    nearest instant (0 < x <= 0.5; default 0.5 = half a frame period)."""
    camera_map: tuple = ()
    keypoint_map: tuple = ()
    skip_bad: bool = False
    stamp_tolerance: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, 'camera_map', parse_name_map(self.camera_map, 'camera'))
        from monet_ros.keypoint_maps import KeypointMapError, expand_keypoint_maps
        try:                          # shipped maps by name: --keypoint-map body25b
            keypoint_map = expand_keypoint_maps(self.keypoint_map)
        except KeypointMapError as error:
            raise LabelError(str(error)) from None
        object.__setattr__(self, 'keypoint_map', parse_name_map(keypoint_map, 'keypoint'))
        if not isinstance(self.skip_bad, bool):
            raise LabelError(f'skip_bad must be true or false, got {self.skip_bad!r}')
        tol = self.stamp_tolerance
        if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol <= 0.5:
            raise LabelError(f'stamp_tolerance must be in (0, 0.5] frame periods, got {tol!r}')


@dataclass
class LabelReport:
    """What resolve_labels did: rows read, kept, and dropped per kind (skip_bad only),
    with the first message of each kind."""
    rows: int = 0
    kept: int = 0
    skipped: dict = field(default_factory=dict)
    first: dict = field(default_factory=dict)

    @property
    def total_skipped(self):
        return sum(self.skipped.values())

    def summary(self):
        text = f'{self.kept} of {self.rows} label rows used'
        if self.skipped:
            parts = ', '.join(f'{n} ({kind})' for kind, n in sorted(self.skipped.items()))
            text += f'; skipped {parts} (first: {next(iter(self.first.values()))})'
        return text


def _nearest(stamps, value):
    """(index, |difference|) of the recording stamp nearest `value` (Python ints)."""
    i = int(np.searchsorted(stamps, min(max(value, int(stamps[0])), int(stamps[-1]))))
    best = None
    for j in (i - 1, i):
        if 0 <= j < len(stamps):
            d = abs(int(stamps[j]) - value)
            if best is None or d < best[1]:
                best = (j, d)
    return best


def _stamp_problem(stamp, stamps, tolerance_ns):
    """None when `stamp` matches an instant, else the reason (text)."""
    first, last = int(stamps[0]), int(stamps[-1])
    for unit, factor in STAMP_UNITS:
        j, d = _nearest(stamps, stamp * factor)
        if d <= tolerance_ns:
            return (f'{stamp} matches no instant, but x{factor} matches instant {j} '
                    f'({int(stamps[j])}): the stamp looks like {unit}, expected nanoseconds')
    j, d = _nearest(stamps, stamp)
    if stamp < first - tolerance_ns or stamp > last + tolerance_ns:
        return (f'{stamp} is outside the recording ({first} .. {last} ns, '
                f'{len(stamps)} instants)')
    return (f'{stamp} matches no instant: the nearest ({j}, {int(stamps[j])}) is {d} ns '
            f'away, more than the tolerance {tolerance_ns} ns')


def frame_period_ns(stamps):
    """Median difference of consecutive stamps (ns), 0 for fewer than 2 instants."""
    stamps = np.asarray(stamps, dtype=np.int64)
    return int(np.median(np.diff(stamps))) if len(stamps) > 1 else 0


# More than this share of the rows outside the images: labels at another resolution (the
# full-size videos of a resized recording), refused whole even with skip_bad.
OTHER_RESOLUTION_SHARE = 0.25


def resolve_labels(rows, stamps, cameras, keypoints, options=None, valid=None):
    """Check label rows against a recording -> (Labels keyed by the recording's stamps,
    LabelReport). The ONE label validator (rules in the module docstring).

    rows: LabelRow iterable (read_label_rows or an importer); stamps: (T,) int ns of the
    recording's instants, increasing (a row's frame indexes them); cameras: Camera list
    (name, width, height) or (name, width, height) tuples; keypoints: a Skeleton or names;
    options: LabelOptions; valid: optional (T,) bool, False where an instant cannot be
    used (e.g. a view is missing) - labels there are 'instant' errors too.
    Raises LabelError (file:line: field ...: reason) for the first bad row unless
    options.skip_bad; then bad rows are counted in the report. Rows outside the images are
    judged together: more than OTHER_RESOLUTION_SHARE of the rows means labels at another
    resolution than the recording's images, a LabelError even with skip_bad (naming
    `monet labels import --label-scale`).
    """
    options = options or LabelOptions()
    names = _keypoint_names(keypoints)
    stamps = np.asarray(stamps, dtype=np.int64)
    sizes = {}
    for cam in cameras:
        name, width, height = (cam if isinstance(cam, tuple)
                               else (cam.name, cam.width, cam.height))
        sizes[name] = (int(width), int(height))
    camera_map, keypoint_map = dict(options.camera_map), dict(options.keypoint_map)
    period = frame_period_ns(stamps)
    tolerance_ns = int(period * options.stamp_tolerance)
    report = LabelReport()
    kept, kept_stamps, kept_cams, kept_kps, seen = [], [], [], [], {}

    def bad(kind, row, field_name, reason):
        message = f'{row.place}: field {field_name}: {reason}'
        # rows outside the images are judged together at the end: many of them mean labels
        # at another resolution, which no row-by-row skipping may half-keep
        if not options.skip_bad and kind != 'bounds':
            raise LabelError(message + ' (--skip-bad-labels drops and counts such rows)')
        report.skipped[kind] = report.skipped.get(kind, 0) + 1
        report.first.setdefault(kind, message)

    for row in rows:
        report.rows += 1
        problem = _check_subject(row)
        if problem:
            bad('subject', row, 'subject', problem)
            continue
        camera = camera_map.get(row.camera, row.camera)
        if camera not in sizes:
            hint = _name_hint(row.camera, sizes, 'camera')
            bad('camera', row, 'camera', f'{row.camera!r}'
                + (f' (mapped to {camera!r})' if camera != row.camera else '')
                + f' is not a camera of the recording ({", ".join(sorted(sizes))}){hint}')
            continue
        keypoint = keypoint_map.get(row.keypoint, row.keypoint)
        if keypoint not in names:
            hint = _name_hint(row.keypoint, names, 'keypoint')
            bad('keypoint', row, 'keypoint', f'{row.keypoint!r} is not a keypoint of the '
                f'skeleton ({", ".join(names)}){hint}')
            continue
        if len(stamps) == 0:
            bad('instant', row, 'frame' if row.stamp_ns is None else 'stamp_ns',
                'the recording has no instant')
            continue
        if row.frame is not None:
            if not 0 <= row.frame < len(stamps):
                bad('instant', row, 'frame', f'{row.frame} is not an instant of the recording '
                    f'(0 .. {len(stamps) - 1})')
                continue
            t = row.frame
        else:
            t, d = _nearest(stamps, row.stamp_ns)
            if d > tolerance_ns:
                bad('instant', row, 'stamp_ns',
                    _stamp_problem(row.stamp_ns, stamps, tolerance_ns))
                continue
        if valid is not None and not valid[t]:
            bad('instant', row, 'frame' if row.stamp_ns is None else 'stamp_ns',
                f'instant {t} ({int(stamps[t])}) is incomplete (a view is missing)')
            continue
        width, height = sizes[camera]
        out = [(f, x, n) for f, x, n in (('u', row.u, width), ('v', row.v, height))
               if not -0.5 <= x <= n - 0.5]
        if out:
            f, x, n = out[0]
            bad('bounds', row, f, f'{x!r} lies outside the image of {camera} '
                f'({width}x{height}: -0.5 .. {n - 0.5})')
            continue
        key = (t, camera, keypoint, int(row.subject))
        if key in seen:
            bad('duplicate', row, 'keypoint', f'{keypoint} of {camera} at instant {t}'
                + (f' (subject {row.subject})' if row.subject else '')
                + f' is labelled twice ({_first(seen[key], row)})')
            continue
        seen[key] = row
        kept.append(row)
        kept_stamps.append(int(stamps[t]))
        kept_cams.append(camera)
        kept_kps.append(keypoint)
    outside = report.skipped.get('bounds', 0)
    if outside and outside > OTHER_RESOLUTION_SHARE * report.rows:
        raise LabelResolutionError(
            f'{outside} of {report.rows} label rows lie outside the images (first: '
            f'{report.first["bounds"]}): the labels look like another resolution than the '
            "recording's images; refused whole (--skip-bad-labels drops only stray rows). "
            'Labels of the full-size videos of a recording imported with --resize S: '
            '`monet labels import ... --label-scale S`')
    if outside and not options.skip_bad:
        raise LabelError(report.first['bounds'] + ' (--skip-bad-labels drops and counts such '
                         'rows)')
    report.kept = len(kept)
    return _build_labels(kept, names, kept_stamps, kept_cams, kept_kps), report


def _canonical(name):
    """Lower-case alphanumerics without leading zeros in numbers ('Cam_01' -> 'cam1')."""
    return re.sub(r'0+(\d)', r'\1', re.sub(r'[^0-9a-z]', '', name.lower()))


def _name_hint(name, known, what):
    """'; did you mean X? (--what-map NAME=X)' when one known name looks the same."""
    near = [k for k in known if _canonical(k) == _canonical(name)]
    if len(near) == 1:
        return f'; did you mean {near[0]!r}? (--{what}-map {name}={near[0]})'
    return f'; map names with --{what}-map {name}=NAME'


def match_camera_names(cameras, names, what='file'):
    """{camera: name} matching each camera to the one name (e.g. a video file name) that
    contains it, as anipose does; the longest camera name wins when several fit (cam1 vs
    cam10). Raises LabelError listing what failed (a camera matching no name or several,
    a name claimed by two cameras)."""
    out, problems = {}, []
    for cam in cameras:
        hits = [n for n in names if cam in n
                and not any(len(o) > len(cam) and o in n and cam in o for o in cameras)]
        if len(hits) == 1:
            out[cam] = hits[0]
        elif not hits:
            hint = [n for n in names if _canonical(cam) in _canonical(n)]
            stem = Path(hint[0]).stem if hint else ''
            problems.append(f'camera {cam!r} matches no {what}'
                            + (f' (looks like {hint[0]!r}: --camera-map {cam}={stem})'
                               if hint else ''))
        else:
            problems.append(f'camera {cam!r} matches several {what}s ({", ".join(hits)})')
    claimed = {}
    for cam, n in out.items():
        claimed.setdefault(n, []).append(cam)
    problems += [f'{what} {n!r} matches cameras {", ".join(c)}' for n, c in claimed.items()
                 if len(c) > 1]
    if problems:
        raise LabelError('; '.join(problems) + f' ({what}s: {", ".join(names)})')
    return out
