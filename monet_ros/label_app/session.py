"""The state behind `monet label`: a recording's cameras, instants and images, the
skeleton, and the labels table being edited (no ROS, no web framework).

Labels are the canonical table of monet_ros.labels (stamp_ns, camera, keypoint, u, v):
existing labels are read through read_label_rows / the importers of
monet_ros.labels_import and checked by the ONE validator resolve_labels; every change is
written at once with write_labels (a temporary file renamed over the table: atomic).
"""
from dataclasses import dataclass
import os
from pathlib import Path
import secrets
import threading

import cv2
import numpy as np

from monet_ros.config import ConfigError, setting, validate_config

# Thumbnail size (width, height) of each view in the image embedding of `suggest`.
THUMB_SIZE = (16, 12)
# Longest camera / keypoint name a request may carry (rig and skeleton names are shorter).
NAME_CHARS = 256


class VersionConflict(Exception):
    """A save carried a version of the instant older than the server's: another tab or
    client saved it since. Attributes: t, version (the server's), labels (its (V, C, 2))."""

    def __init__(self, t, sent, version, labels):
        super().__init__(f'instant {t} was saved by another tab or client since this page '
                         f'loaded it (version {sent!r}, now {version!r}); nothing was '
                         'overwritten: merge with or reload the saved labels')
        self.t, self.version, self.labels = t, version, labels


def short(value, chars=60):
    """repr of a request value for an error message, cut to `chars` characters."""
    text = repr(value)
    return text if len(text) <= chars else text[:chars] + '...'


def coordinate(value, where):
    """A JSON number (int or float, not a bool or string) as float; ValueError naming
    `where` otherwise, an integer too large for a float included (finiteness is checked by
    the caller, with the image bounds)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f'{where} must be a number, got {short(value)} '
                         f'({type(value).__name__})')
    try:
        return float(value)
    except OverflowError:
        digits = len(str(abs(value)))
        raise ValueError(f'{where} must be a finite number, got a {digits}-digit integer') \
            from None


@dataclass(frozen=True)
class LabelConfig:
    """Settings of `monet label` (validated on construction; CLI options of the same names)."""
    flag_px: float = setting(10.0, 'reprojection error (px) above which a clicked view is '
                             'flagged as disagreeing with the triangulation',
                             minimum=0.0, exclusive_minimum=True)
    threshold_px: float = setting(15.0, 'outlier threshold (px) of the robust triangulation',
                                  minimum=0.0, exclusive_minimum=True)
    suggestions: int = setting(10, 'number of suggested instants', minimum=1)
    model_instants: int = setting(200, 'most instants the detector runs on for suggestions '
                                  '(evenly spaced)', minimum=1)

    def __post_init__(self):
        validate_config(self)


# Most subjects a page may address (ids 0 .. MAX_SUBJECT): a bound on what a request makes
# the session keep, far above any scene labelled by hand.
MAX_SUBJECT = 99


def check_subject(value):
    """A request's subject id: an integer 0..MAX_SUBJECT (not a bool or a string), else
    ValueError naming the field."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or \
            not 0 <= int(value) <= MAX_SUBJECT:
        raise ValueError(f'subject: expected an integer 0..{MAX_SUBJECT}, got {short(value)}')
    return int(value)


class LabelSession:
    """A recording opened for labelling.

    rec: recording (rosbag2 folder, .mcap or `monet synth` folder); labels_path: the labels
    CSV edited and autosaved (read first when it exists, stamp- or frame-keyed; always
    written stamp-keyed); rig: rig file (default: the recording's); skeleton: preset name
    or YAML; imports: (format, path) pairs of existing labels (monet_ros.labels_import
    formats) merged in (the table's own points win); options: LabelOptions (camera /
    keypoint name maps, skip_bad); config: LabelConfig; rig_units: the length unit of a
    rig file that states none (geometry.read_rig).

    Attributes: cameras (V Camera), stamps (T,) int64 ns, skeleton, keypoints (C names),
    labels {stamp_ns: (V, C, 2) float64 px, NaN = unlabelled} of subject 0, others
    {subject >= 1: {stamp_ns: (V, C, 2)}} of the other subjects (the labels table's subject
    column: an animal within one instant, the same id in every view), subject_names
    {subject: name} from the imports (SLEAP tracks, DeepLabCut individuals), report (one
    line: rows used / skipped per source), notes (what was adapted). Images are kept in
    memory as the recording's messages (JPEG / PNG bytes of compressed views are served
    as they are). Raises LabelError / RecordingError / ValueError naming the file or field.
    """

    def __init__(self, rec, labels_path, rig=None, skeleton='human14', imports=(),
                 options=None, config=None, rig_units=None):
        from monet_ros.labels import LabelOptions
        from monet_ros.learning.recording_index import recording_index
        from monet_ros.skeleton import load_skeleton

        self.config = config or LabelConfig()
        self.options = options or LabelOptions()
        self.labels_path = Path(labels_path)
        if self.labels_path.is_dir():
            raise ConfigError('monet label', 'labels', f'{self.labels_path}: is a folder, '
                              'expected a labels CSV file')
        self._check_savable()
        self.skeleton = load_skeleton(skeleton)
        self.keypoints = tuple(self.skeleton.keypoints)
        index = recording_index(rec, rig=rig, camera_map=self.options.camera_map,
                                rig_units=rig_units)
        self.rec = str(rec)
        self.bag = index.bag          # its import record scales labels made on the videos
        self.notes = list(index.notes or ())
        self.cameras = list(index.cameras)
        self.names = [c.name for c in self.cameras]
        self._messages = self._collect(index)
        self.stamps = np.array(sorted(self._messages), np.int64)
        self.complete = np.array([len(self._messages[int(s)]) == len(self.cameras)
                                  for s in self.stamps], bool)
        self._lock = threading.Lock()
        self.labels = {}
        self.others = {}
        self.subject_names = {}
        # per (instant, subject): saves since start; a version is '<run>.<saves>' so that a page
        # loaded before a restart never matches (the run part is new at each start)
        self._saves = {}
        self._run = secrets.token_hex(4)
        self.report = None
        self._load(imports)
        self._thumbs = None
        # set when the server stops: long jobs (thumbnails, detector) end at the next instant
        self.stopping = threading.Event()
        self.work = threading.Lock()   # held by those jobs; the server's stop waits for it

    # ------------------------------------------------------------------ recording
    def _collect(self, index):
        from monet_ros.io import iter_multiview_frames

        out = {}
        for frame in iter_multiview_frames(index.reader, index.topics, decode=False):
            out[int(frame.stamp_ns)] = {cam: m.msg for cam, m in frame.images.items()}
        if index.reader.report is not None and not index.reader.report.ok:
            self.notes.append(f'reading {index.bag}: {index.reader.report.summary()}')
        return out

    def instant(self, t):
        """Stamp (int ns) of instant index t; IndexError naming the range."""
        if not 0 <= int(t) < len(self.stamps):
            raise IndexError(f'instant {t} out of range 0..{len(self.stamps) - 1}')
        return int(self.stamps[int(t)])

    def camera_index(self, name):
        if name not in self.names:
            raise KeyError(f'camera {short(name)} is not one of {", ".join(self.names)}')
        return self.names.index(name)

    def image_bytes(self, t, camera):
        """(bytes, mimetype) of a view of instant t: a compressed view's own JPEG / PNG
        bytes, a raw view encoded as PNG (to_rgb8: any bit depth). KeyError when the view
        is missing."""
        from monet_ros.io.images import any_image_to_numpy, to_rgb8

        msg = self._messages[self.instant(t)].get(camera)
        if msg is None:
            raise KeyError(f'camera {camera!r} has no image at instant {t}')
        fmt = str(getattr(msg, 'format', '') or '').lower()
        if hasattr(msg, 'format') and not hasattr(msg, 'encoding'):
            if 'jpeg' in fmt or 'jpg' in fmt:
                return bytes(msg.data), 'image/jpeg'
            if 'png' in fmt and 'compressedDepth' not in fmt:
                return bytes(msg.data), 'image/png'
        rgb = to_rgb8(any_image_to_numpy(msg))
        ok, data = cv2.imencode('.png', cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        if not ok:                                       # pragma: no cover - cv2 failure
            raise ValueError(f'cannot encode the image of {camera} at instant {t}')
        return data.tobytes(), 'image/png'

    def images(self, t):
        """{camera: (H, W, 3) uint8 RGB} of instant t (decoded)."""
        from monet_ros.io.images import any_image_to_numpy, to_rgb8
        msgs = self._messages[self.instant(t)]
        return {cam: to_rgb8(any_image_to_numpy(msg)) for cam, msg in msgs.items()}

    def thumbnails(self):
        """(T, V * 16 * 12) float32 grey thumbnails of every view of every instant
        (0..1; a missing view is 0.5 grey) - the image embedding of `suggest`. Cached."""
        with self.work:
            if self._thumbs is None:
                self._thumbs = self._thumbnails()
            return self._thumbs

    def _thumbnails(self):
        W, H = THUMB_SIZE
        out = np.full((len(self.stamps), len(self.cameras), H * W), 0.5, np.float32)
        for t in range(len(self.stamps)):
            if self.stopping.is_set():
                raise InterruptedError('monet label is stopping')
            for cam, rgb in self.images(t).items():
                grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
                small = cv2.resize(grey, (W, H), interpolation=cv2.INTER_AREA)
                out[t, self.names.index(cam)] = small.reshape(-1) / 255.0
        return out.reshape(len(self.stamps), -1)

    def summary(self):
        """JSON-ready description of the recording and skeleton."""
        return {
            'recording': self.rec,
            'labels_path': str(self.labels_path),
            'notes': self.notes,
            'cameras': [{'name': c.name, 'width': c.width, 'height': c.height,
                         'K': c.K.tolist(), 'dist': c.dist.tolist(), 'R': c.R.tolist(),
                         't': c.t.tolist()} for c in self.cameras],
            'instants': [{'index': i, 'stamp_ns': str(int(s)), 'complete': bool(c),
                          'views': sorted(self._messages[int(s)])}
                         for i, (s, c) in enumerate(zip(self.stamps, self.complete))],
            'keypoints': list(self.keypoints),
            'bones': [list(b) for b in self.skeleton.bone_indices],
            'flag_px': self.config.flag_px,
            'label_report': self.report,
        }

    # ------------------------------------------------------------------ labels
    def _load(self, imports):
        """Labels of the imports, then of the table itself (each through resolve_labels);
        a point the table has wins over an imported one."""
        from monet_ros.labels import read_label_rows
        from monet_ros.labels_import import import_labels, to_recording_pixels

        sources = []
        for fmt, path in imports:
            result = import_labels(fmt, path, cameras=self.names,
                                   camera_map=dict(self.options.camera_map))
            rows, note = to_recording_pixels(result.rows, fmt, self.bag,
                                             camera_map=dict(self.options.camera_map))
            if note:
                self.notes.append(f'{fmt}={path}: {note}')
            if result.note:
                self.notes.append(f'{fmt}={path}: {result.note}')
            for name, subject in result.subjects.items():
                self.subject_names.setdefault(int(subject), str(name))
            sources.append((f'{fmt}={path}', rows))
        if self.labels_path.is_file():
            sources.append((str(self.labels_path), read_label_rows(self.labels_path)))
        notes = []
        for name, rows in sources:
            labels, report = self._resolve(rows)
            beyond = [s for s in labels.subjects if s > MAX_SUBJECT]
            if beyond:       # the page could list it but never show or save it
                raise ConfigError('monet label', 'labels', f'{name}: subject {beyond[0]}: '
                                  f'the page addresses subjects 0..{MAX_SUBJECT}; number '
                                  'the subjects of an instant from 0')
            notes.append(f'{name}: {report.summary()}')
            for stamp in labels.stamps:
                for subject in labels.instant_subjects(stamp):
                    points = labels.points(stamp, self.names, subject)
                    table = self._table(subject)
                    old = table.get(int(stamp))
                    if old is not None:
                        points = np.where(np.isfinite(points), points, old)
                    table[int(stamp)] = points
        self.report = '; '.join(notes) or 'no labels yet'

    def _resolve(self, rows):
        from monet_ros.labels import resolve_labels
        return resolve_labels(rows, self.stamps, self.cameras, self.keypoints, self.options)

    def _table(self, subject):
        """{stamp: (V, C, 2)} of one subject (created when new)."""
        return self.labels if subject == 0 else self.others.setdefault(int(subject), {})

    def instant_labels(self, t, subject=0):
        """(V, C, 2) labels of one subject (default 0) at instant t (a copy; NaN =
        unlabelled)."""
        return self.instant_state(t, subject)[0]

    def instant_state(self, t, subject=0):
        """((V, C, 2) labels, version) of one subject (default 0) at instant t, read
        together. The version (an opaque string) changes at every save of the subject at
        that instant; set_instant needs it."""
        stamp = self.instant(t)
        subject = check_subject(subject)
        with self._lock:
            return self._points(stamp, subject), self._version(stamp, subject)

    def instant_subjects(self, t):
        """Subjects labelled at instant t, sorted (list of int)."""
        stamp = self.instant(t)
        with self._lock:
            return sorted(s for s, table in [(0, self.labels), *self.others.items()]
                          if stamp in table and np.isfinite(table[stamp]).any())

    def subjects(self):
        """{subject: name or ''} of every subject labelled anywhere or named by an import,
        sorted; subject 0 always."""
        with self._lock:
            ids = {0, *self.subject_names, *(s for s, table in self.others.items() if table)}
        return {s: self.subject_names.get(s, '') for s in sorted(ids)}

    def _points(self, stamp, subject=0):
        points = self._table(subject).get(stamp) if subject == 0 or subject in self.others \
            else None
        if points is None:
            return np.full((len(self.cameras), len(self.keypoints), 2), np.nan)
        return points.copy()

    def _version(self, stamp, subject=0):
        return f'{self._run}.{self._saves.get((stamp, subject), 0)}'

    def points_from_json(self, views):
        """{camera: {keypoint: [u, v] | null}} -> (V, C, 2) float64 (NaN = none).
        u and v must be JSON numbers (not strings or booleans), finite, inside the image;
        at most V cameras and C keypoints each. ValueError naming the camera / keypoint /
        field that does not fit (KeyError for an unknown camera or keypoint)."""
        out = np.full((len(self.cameras), len(self.keypoints), 2), np.nan)
        if not isinstance(views, dict):
            raise ValueError('labels must be an object {camera: {keypoint: [u, v]}}')
        if len(views) > len(self.cameras):
            raise ValueError(f'labels: {len(views)} cameras, the rig has {len(self.cameras)}')
        for cam, points in views.items():
            j = self.camera_index(cam)
            if not isinstance(points, dict):
                raise ValueError(f'labels of camera {cam!r} must be an object')
            if len(points) > len(self.keypoints):
                raise ValueError(f'labels of camera {cam!r}: {len(points)} keypoints, the '
                                 f'skeleton has {len(self.keypoints)}')
            for name, uv in points.items():
                if name not in self.keypoints:
                    raise KeyError(f'keypoint {short(name)} is not in the skeleton')
                if uv is None:
                    continue
                if not isinstance(uv, list) or len(uv) != 2:
                    raise ValueError(f'labels {cam}/{name}: expected [u, v], got {short(uv)}')
                u = coordinate(uv[0], f'labels {cam}/{name}: u')
                v = coordinate(uv[1], f'labels {cam}/{name}: v')
                camera = self.cameras[j]
                if not (np.isfinite(u) and np.isfinite(v) and -0.5 <= u <= camera.width - 0.5
                        and -0.5 <= v <= camera.height - 0.5):
                    raise ValueError(f'labels {cam}/{name}: ({u}, {v}) lies outside the '
                                     f'{camera.width}x{camera.height} image')
                out[j, self.keypoints.index(name)] = (u, v)
        return out

    def points_to_json(self, points):
        """(V, C, 2) -> {camera: {keypoint: [u, v]}} (labelled points only)."""
        out = {}
        for j, cam in enumerate(self.names):
            got = {self.keypoints[c]: [float(u), float(v)]
                   for c, (u, v) in enumerate(points[j]) if np.isfinite(u) and np.isfinite(v)}
            if got:
                out[cam] = got
        return out

    def set_instant(self, t, points, version, subject=0):
        """Replace the labels of one subject (default 0) at instant t by (V, C, 2) `points`
        and save the table at once (atomically; every subject's labels), if `version` is
        that subject's version at the instant (instant_state): a save built on an older
        reading raises VersionConflict and changes nothing (compare and set under one
        lock). Returns (rows written, the new version)."""
        stamp = self.instant(t)
        subject = check_subject(subject)
        with self._lock:
            current = self._version(stamp, subject)
            if version != current:
                raise VersionConflict(t, version, current, self._points(stamp, subject))
            table = self._table(subject)
            if np.isfinite(points).any():
                table[stamp] = np.array(points, np.float64)
            else:
                table.pop(stamp, None)
            self._saves[(stamp, subject)] = self._saves.get((stamp, subject), 0) + 1
            return self._save(), self._version(stamp, subject)

    def _save(self):
        from monet_ros.labels import write_labels

        rows = []
        stamps = sorted({s for table in [self.labels, *self.others.values()] for s in table})
        for stamp in stamps:
            for j, cam in enumerate(self.names):
                for subject in [0, *sorted(self.others)]:
                    points = self._table(subject).get(stamp)
                    if points is None:
                        continue
                    for c, (u, v) in enumerate(points[j]):
                        if np.isfinite(u) and np.isfinite(v):
                            rows.append((stamp, cam, self.keypoints[c], u, v, subject))
        self.labels_path.parent.mkdir(parents=True, exist_ok=True)
        return write_labels(self.labels_path, rows)

    def _check_savable(self):
        """Every change is saved at once to labels_path (atomically: a new file in its
        folder, renamed over it), so that folder must take a new file: checked before the
        server starts (ConfigError naming --labels), not at the first click of a session."""
        import tempfile

        from monet_ros.error_text import os_error_text

        folder = self.labels_path.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
            handle, probe = tempfile.mkstemp(prefix=f'.{self.labels_path.name}.',
                                             suffix='.probe', dir=folder)
            os.close(handle)
            os.unlink(probe)
        except OSError as error:
            raise ConfigError('monet label', 'labels', f'{self.labels_path}: cannot be saved '
                              f'({os_error_text(error)})') from None

    def labelled_instants(self):
        """Indices of instants with at least one label (of any subject)."""
        where = {int(s): i for i, s in enumerate(self.stamps)}
        with self._lock:
            return sorted({where[s] for table in [self.labels, *self.others.values()]
                           for s, p in table.items() if np.isfinite(p).any()})
