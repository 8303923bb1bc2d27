"""The crop rule: where each view's crop comes from (no ROS). One implementation, used by
training, evaluation, `monet process` and the detector node.

Sources of a crop box, in pixel-EDGE coordinates (x0, y0, x1, y1):
- ``tracked``: the projection of the previous instant's fused 3D keypoints (the live
  detector's rule; `TrackedCrops` holds that state, `crop_boxes` is the box function);
- ``labels``: the labelled 2D keypoints (and their spatial augmentation: triangulated
  labels projected into the unlabelled views);
- ``pseudo_labels``: labels plus given pseudo-labels (e.g. spatiotemporal tracks);
- ``fixed``: one configured box; ``full``: the full frame;
- ``ground_truth``: the projected ground-truth 3D. A benchmark option only, never a
  default: a deployed detector has no ground truth, and ground-truth crops hand an
  image-blind detector a free floor (every keypoint near the crop centre scores well).

Tracked boxes are robust: per view, projected keypoints farther than ``trim`` scaled MADs
from the median (on either axis) are left out before the bounding box is taken, so one
wild joint cannot blow the box up to the whole frame.
"""
from dataclasses import dataclass
import warnings

import numpy as np

from monet_ros.geometry import project_views, stack_cameras
from monet_ros.geometry.units import check_units, convert
from monet_ros.learning.dataset import boxes_from_points, fill_boxes

SOURCES = ('tracked', 'labels', 'pseudo_labels', 'fixed', 'full', 'ground_truth')
_MAD_TO_SIGMA = 1.4826


def trimmed(uv, ok, trim=4.0, floor=8.0):
    """(V, N) bool: points of `ok` within `trim` robust sigmas (1.4826 MAD, at least `floor`
    pixels) of their view's median on both axes. uv (V, N, 2) pixels; ok (V, N) bool."""
    pts = np.where(ok[..., None], uv, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)       # views without any point
        med = np.nanmedian(pts, axis=1, keepdims=True)                       # (V, 1, 2)
        mad = np.nanmedian(np.abs(pts - med), axis=1, keepdims=True)
    scale = np.maximum(_MAD_TO_SIGMA * np.nan_to_num(mad), floor)
    close = (np.abs(pts - med) <= trim * scale).all(axis=-1)
    return ok & close


def subject_boxes(cameras, X, margin=0.3, min_points=3, min_size=32.0, trim=4.0):
    """Boxes (V, 4) (x0, y0, x1, y1) edge coordinates around the projections of X.

    cameras: V Camera (full images); X (N, 3) world points, NaN = missing. A view's box is
    the bounding box of the projected points in front of the camera and within the image
    (one image size of slack), outliers trimmed (see `trimmed`; trim <= 0: none), grown by
    `margin` x its size on each side and to at least `min_size` pixels; NaN rows where fewer
    than `min_points` points qualify.
    """
    X = np.asarray(X, np.float64).reshape(-1, 3)
    V = len(cameras)
    boxes = np.full((V, 4), np.nan)
    finite = np.isfinite(X).all(axis=1)
    if finite.sum() < min_points or V == 0:
        return boxes
    Xf = X[finite]
    uv = project_views(stack_cameras(cameras), Xf)          # (V, n, 2)
    R = np.stack([cam.R for cam in cameras])
    t = np.stack([cam.t for cam in cameras])
    depth = np.einsum('vj,nj->vn', R[:, 2], Xf) + t[:, 2, None]  # (V, n)
    size = np.array([[cam.width, cam.height] for cam in cameras], np.float64)  # (V, 2)
    inside = ((depth > 0) & np.isfinite(uv).all(axis=-1)
              & (uv > -size[:, None]).all(axis=-1) & (uv < 2 * size[:, None]).all(axis=-1))
    if trim > 0:
        inside = trimmed(uv, inside, trim)
    ok = inside.sum(axis=1) >= min_points
    uv = np.where(inside[..., None], uv, np.nan)
    uv[~ok] = 0.0                       # views without a box: no all-NaN reductions
    lo, hi = np.nanmin(uv, axis=1), np.nanmax(uv, axis=1)
    extent = np.maximum(hi - lo, 0.0)
    centre = (lo + hi) / 2
    half = np.maximum(extent * (0.5 + margin), min_size / 2)
    # +0.5: pixel centres are integers, the box is in edge coordinates.
    boxes[ok] = np.concatenate([centre - half + 0.5, centre + half + 0.5], axis=1)[ok]
    return boxes


def crop_boxes(cameras, X=None, fallback_box=None, margin=0.3, min_points=3, trim=4.0):
    """The live rule, (V, 4): around the projection of X (the latest 3D keypoints) where at
    least `min_points` project into the view, else `fallback_box` ((4,) one box for every
    view, or (V, 4) per view, NaN rows = none), else the full frame."""
    V = len(cameras)
    boxes = (subject_boxes(cameras, X, margin, min_points, trim=trim) if X is not None
             else np.full((V, 4), np.nan))
    fallback = np.full((V, 4), np.nan)
    if fallback_box is not None and len(fallback_box):
        fallback[:] = np.broadcast_to(np.asarray(fallback_box, np.float64), (V, 4))
    full = np.array([(0, 0, c.width, c.height) for c in cameras], np.float64).reshape(V, 4)
    fallback = np.where(np.isnan(fallback).any(axis=1, keepdims=True), full, fallback)
    return np.where(np.isnan(boxes).any(axis=1, keepdims=True), fallback, boxes)


@dataclass(frozen=True)
class TrackedRule:
    """Settings of the tracked rule (mirrored by the detector node's track_* parameters)."""
    margin: float = 0.3
    min_points: int = 3
    trim: float = 4.0
    timeout_ns: int = 1_000_000_000

    def __post_init__(self):
        if not (self.margin >= 0 and self.min_points >= 1 and self.timeout_ns >= 0):
            raise ValueError(f'TrackedRule: margin >= 0, min_points >= 1, timeout_ns >= 0; '
                             f'got {self}')


class TrackedCrops:
    """State of the tracked rule over a stream: the last fused 3D keypoints and their stamp.

    `update(X, stamp_ns)` after each fused instant; `boxes(cameras, stamp_ns, fallback)` for
    the next one. Keypoints are used while the image stamp is at most rule.timeout_ns newer
    than theirs (source stamps, not arrival times: a replay, live or offline, crops the same
    way at any speed); older, newer-than-the-image or too few finite points -> fallback.
    units: the length unit of the keypoints and of the cameras they are projected with (the
    rig's: 'm', 'cm', 'mm').
    """

    def __init__(self, rule=None, units='m'):
        self.rule = rule or TrackedRule()
        self.units = check_units(units)
        self.X = None
        self.stamp_ns = None

    def update(self, X, stamp_ns=0):
        """Keypoints (N, 3) in `units` fused for the instant `stamp_ns`; kept as a subscriber
        reads them from /monet/keypoints3d (metres at float32 precision, back in `units`),
        so live and offline crop from the same numbers (points read from the topic are
        kept as they are)."""
        metres = convert(np.asarray(X, np.float64).reshape(-1, 3), self.units, 'm')
        self.X = convert(metres.astype(np.float32).astype(np.float64), 'm', self.units)
        self.stamp_ns = int(stamp_ns)

    def current(self, stamp_ns=None):
        """The keypoints to crop an image of `stamp_ns` around, or None."""
        if self.X is None:
            return None
        if stamp_ns is not None and not 0 <= int(stamp_ns) - self.stamp_ns <= \
                self.rule.timeout_ns:
            return None
        return self.X

    def boxes(self, cameras, stamp_ns=None, fallback_box=None):
        return crop_boxes(cameras, self.current(stamp_ns), fallback_box, self.rule.margin,
                          self.rule.min_points, self.rule.trim)


# the detector node's discovery_period_s by default (s): a subject that appears or is lost
# waits at most this long for discovery, which otherwise runs in every frame that has fewer
# than N subjects (its maps: the whole frame or its tiles, 4x a view's subject crops at N 2)
DISCOVERY_PERIOD_S = 0.25


def discovery_due(stamp_ns, previous_ns, period_s):
    """Whether the detector node publishes discovery maps in a frame of stamp_ns (ns) while
    fewer than N subjects are tracked (its `discovery_period_s`): with period_s 0 every
    frame; else the first frame of each window floor(stamp / period) of the stamp clock,
    i.e. a frame whose window differs from that of the frame before it (previous_ns; None:
    the first frame, due). A rule of the stamps alone, so the detectors of a rig, which see
    the same stamps, send their discovery maps in the same frames and fusion discovers on
    every view at once; between those frames their discovery slots stay empty (a subject
    that is lost or new waits at most period_s, and a missing subject no longer costs the
    discovery crops of every frame: docs/subjects.md "Live"; TrackedSubjects.boxes applies
    it). Raises ValueError for a negative period_s."""
    if not period_s >= 0:
        raise ValueError(f'discovery period must be >= 0 s, got {period_s}')
    if period_s == 0 or previous_ns is None:
        return True
    period = max(1, round(period_s * 1e9))
    return int(stamp_ns) // period != int(previous_ns) // period


class TrackedSubjects:
    """The tracked rule with several subjects (the detector node's `subjects` >= 2): the
    subjects of the last /monet/keypoints3d (its `subject` field) and their stamp.

    `update(X, subject, keypoint, stamp_ns, num_keypoints)`; `current(stamp_ns)` -> [(identity,
    (C, 3) keypoints)] by identity, [] when stale (rule.timeout_ns, as TrackedCrops);
    `boxes(cameras, stamp_ns, subjects, fallback_box)` -> the crop slots' boxes. units: the
    length unit of the keypoints and cameras (the rig's); discovery_period_s: the discovery
    slot only in the frames discovery_due gives (0: every frame)."""

    def __init__(self, rule=None, units='m', discovery_period_s=0.0):
        self.rule = rule or TrackedRule()
        self.units = check_units(units)
        discovery_due(0, None, discovery_period_s)          # ValueError when negative
        self.discovery_period_s = float(discovery_period_s)
        self.subjects = []
        self.stamp_ns = None
        self.previous_ns = None         # the stamp of the last boxes() (discovery_due)

    def update(self, X, subject, keypoint, stamp_ns, num_keypoints):
        """X (M, 3) points in `units` (as read from the topic), subject (M,) identities,
        keypoint (M,) keypoint indices (outside 0..num_keypoints-1: left out)."""
        X = np.asarray(X, np.float64).reshape(-1, 3)
        subject, keypoint = np.asarray(subject), np.asarray(keypoint)
        ok = (keypoint >= 0) & (keypoint < num_keypoints)
        out = []
        for ident in np.unique(subject[ok]):
            mine = ok & (subject == ident)
            joints = np.full((num_keypoints, 3), np.nan)
            joints[keypoint[mine]] = X[mine]
            out.append((int(ident), joints))
        self.subjects, self.stamp_ns = out, int(stamp_ns)

    def current(self, stamp_ns=None):
        """[(identity, (C, 3))] to crop an image of `stamp_ns` around ([] when none or
        stale)."""
        if self.stamp_ns is None or stamp_ns is not None and not \
                0 <= int(stamp_ns) - self.stamp_ns <= self.rule.timeout_ns:
            return []
        return self.subjects

    def boxes(self, cameras, stamp_ns, subjects, fallback_box=None, track=True):
        """(V, subjects + 1, 4) boxes of the crop slots (NaN rows: no crop in that slot and
        view): slot k < subjects around the k-th current subject (by identity; subject_boxes
        with the rule's margin, min_points and trim: NaN in a view where too few of its
        joints project); slot `subjects` the full frame (or `fallback_box`) while fewer than
        `subjects` are current and discovery is due (discovery_due of stamp_ns after the
        previous call's), else NaN. track False: no subject crops. Call it once per frame,
        stamps increasing."""
        due = discovery_due(stamp_ns, self.previous_ns, self.discovery_period_s)
        self.previous_ns = int(stamp_ns)
        V = len(cameras)
        out = np.full((V, subjects + 1, 4), np.nan)
        current = self.current(stamp_ns)[:subjects] if track else []
        for k, (_, X) in enumerate(current):
            out[:, k] = subject_boxes(cameras, X, self.rule.margin, self.rule.min_points,
                                      trim=self.rule.trim)
        if len(current) < subjects and due:
            out[:, subjects] = crop_boxes(cameras, None, fallback_box)
        return out


def recording_boxes(recording, source, aspect, margin, pseudo=None, box=None):
    """(T, V, 4) crop boxes of every (instant, view) of a recording, for training and as the
    start of evaluation's tracked crops.

    source: 'labels' (labels + their spatial augmentation), 'pseudo_labels' (that plus
    `pseudo` (T, V, C, 2), e.g. spatiotemporal tracks), 'ground_truth' (benchmark option:
    needs recording.gt3d), 'fixed' (`box` for every view), 'full'. Instants without a box
    take the nearest instant's box of that view (full frame when the view has none).
    Raises ValueError for an unknown source or missing input. ('tracked' is a sequential
    rule: see TrackedCrops.)"""
    from monet_ros.learning.pseudo_labels import project_to_views, spatial_pseudo_labels

    T, V = recording.num_instants, recording.num_views
    if source == 'ground_truth':
        if recording.gt3d is None:
            raise ValueError(f'{recording.name}: crop source ground_truth needs ground truth')
        C = recording.num_keypoints
        points = project_to_views(recording.gt3d.reshape(-1, 3), recording.cameras)
        points = points.reshape(V, T, C, 2).transpose(1, 0, 2, 3)          # visible only
    elif source in ('labels', 'pseudo_labels'):
        spatial = spatial_pseudo_labels(recording.labels, recording.cameras).points
        points = np.where(np.isfinite(recording.labels), recording.labels, spatial)
        if source == 'pseudo_labels':
            if pseudo is None:
                raise ValueError('crop source pseudo_labels needs the pseudo-labels')
            points = np.where(np.isfinite(points), points, pseudo)
    elif source == 'fixed':
        if box is None or len(box) != 4:
            raise ValueError(f'crop source fixed needs a box x0 y0 x1 y1, got {box!r}')
        return np.broadcast_to(np.asarray(box, np.float64), (T, V, 4)).copy()
    elif source == 'full':
        points = np.full((T, V, 1, 2), np.nan)
    else:
        raise ValueError(f'unknown crop source {source!r} (one of {", ".join(SOURCES)})')
    return fill_boxes(boxes_from_points(points, aspect=aspect, margin=margin),
                      recording.cameras)


def subject_label_boxes(labels, instants, boxes, cameras, aspect, margin):
    """(J, V, 4) training crop boxes of other subjects' labels (Recording.other_labels): the
    rule of recording_boxes' 'labels' source (the subject's labels + their spatial
    augmentation) on each labelled (instant, subject). A view with neither takes the box of
    its instant in `boxes` (T, V, 4) (it has no label of that subject, so it is never a
    training crop of it).

    labels (J, V, C, 2) px NaN = none; instants (J,) their instants; cameras: V Camera."""
    from monet_ros.learning.pseudo_labels import spatial_pseudo_labels

    labels = np.asarray(labels, np.float64)
    instants = np.asarray(instants, np.int64)
    if not len(labels):
        return np.zeros((0,) + np.shape(boxes)[1:])
    spatial = spatial_pseudo_labels(labels, cameras).points
    points = np.where(np.isfinite(labels), labels, spatial)
    out = boxes_from_points(points, aspect=aspect, margin=margin)
    missing = ~np.isfinite(out[..., 0])
    return np.where(missing[..., None], np.asarray(boxes, np.float64)[instants], out)
