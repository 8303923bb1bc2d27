"""Several subjects over a recording's 2D instances (no ROS): per-camera instance
tables split by instance, associated across cameras and tracked over time
(subjects.association, subjects.tracking), for `monet triangulate --subjects N`; and the
offline filter per subject (smooth_subjects, `monet triangulate` / `monet process
--subjects N --filter kalman|optim`).

Instances: the readers name a keypoint of one instance '<instance>/<keypoint>' (SLEAP
tracks, DeepLabCut individuals, the points table's `subject` column). An instance name
labels one detection within a camera and frame only: nothing here assumes it means the
same subject in another camera or frame.
"""
from dataclasses import dataclass, field, replace
import time

import numpy as np

from monet_ros.subjects.association import associate
from monet_ros.subjects.tracking import SubjectTracker


def split_instances(names, keypoints=None):
    """(instances, nodes, index (I, K) int into names or -1) of flat keypoint names
    '<instance>/<keypoint>' (a name without '/' is instance '' of itself). keypoints: the
    output's keypoint names and order (a node not among them raises ValueError naming it),
    None = the nodes in first-seen order."""
    parts = [n.split('/', 1) if '/' in n else ['', n] for n in names]
    instances = list(dict.fromkeys(p[0] for p in parts))
    nodes = list(keypoints) if keypoints is not None else list(dict.fromkeys(p[1] for p in parts))
    node_index = {k: i for i, k in enumerate(nodes)}
    inst_index = {k: i for i, k in enumerate(instances)}
    index = np.full((len(instances), len(nodes)), -1)
    for flat, (inst, node) in enumerate(parts):
        if node not in node_index:
            raise ValueError(f'keypoint {node!r} (of {names[flat]!r}) is not a keypoint of '
                             f'the skeleton ({", ".join(nodes)})')
        index[inst_index[inst], node_index[node]] = flat
    return tuple(instances), tuple(nodes), index


def instance_arrays(points, score, index):
    """(points (T, V, I, K, 2), score (T, V, I, K)) of flat arrays points (T, V, F, 2),
    score (T, V, F) by split_instances' index (I, K); NaN where an instance has no such
    keypoint."""
    T, V = points.shape[:2]
    pad_p = np.concatenate([points, np.full((T, V, 1, 2), np.nan)], axis=2)
    pad_s = np.concatenate([score, np.full((T, V, 1), np.nan)], axis=2)
    return pad_p[:, :, index], pad_s[:, :, index]


@dataclass
class SubjectRows:
    """One row per frame and tracked subject: frame (R,) index into the input's frames,
    subject (R,) identity, X (R, C, 3) rig units, error (R, C) mean reprojection error of
    the inlier views (px), ncams (R, C), score (R, C); and the counts: births, deaths,
    instances (with >= 1 keypoint), unmatched (instances in no subject), extra (subjects
    beyond num_subjects in a frame, left out), untracked (subjects with too few keypoints
    for a track, or taken by no identity while num_subjects identities were alive),
    seconds (association + tracking, wall clock); points2d (R, V, C, 2) and scores2d
    (R, V, C): each row's 2D detections in the run's V cameras (Association's, NaN / 0
    where the subject has none; the 2D an offline filter weighs: smooth_subjects)."""
    frame: np.ndarray
    subject: np.ndarray
    X: np.ndarray
    error: np.ndarray
    ncams: np.ndarray
    score: np.ndarray
    births: int
    deaths: int
    instances: int
    unmatched: int
    extra: int
    untracked: int
    seconds: float
    points2d: np.ndarray = None
    scores2d: np.ndarray = None

    def identities_text(self):
        """'2 identities (0, 1), 24 subject-frames, 2 births, 0 deaths': the summary's
        identity counts (one wording for `monet process` and `monet triangulate`)."""
        ids = np.unique(self.subject)
        listed = f' ({", ".join(map(str, ids))})' if len(ids) else ''
        return (f'{counted(len(ids), "identity", "identities")}{listed}, '
                f'{counted(len(self.subject), "subject-frame")}, '
                f'{counted(self.births, "birth")}, {counted(self.deaths, "death")}')

    def untriangulated_text(self, keypoints):
        """'keypoints not triangulated per keypoint over 24 subject-frames: head 3, neck 1'
        ('none' when every row has every keypoint; keypoints: the C names of X's order):
        the summary's count of the joints the rows lack (one wording for `monet process`
        and `monet triangulate`)."""
        lost = (~np.isfinite(self.X).all(-1)).sum(axis=0)
        listed = ', '.join(f'{k} {int(n)}' for k, n in zip(keypoints, lost) if n)
        return (f'keypoints not triangulated per keypoint over '
                f'{counted(len(self.subject), "subject-frame")}: {listed or "none"}')


def counted(n, noun, plural=None):
    """'1 birth', '0 births', '2 births' (plural: the irregular form)."""
    return f'{n} {noun if n == 1 else plural or noun + "s"}'


class RowCollector:
    """SubjectRows accumulated frame by frame (one implementation of the rows of
    `monet triangulate --subjects` and `monet process --subjects`).

    add(t, association, ids, keep, views): the subjects `keep` (index array or slice into
    association's subjects) of frame t with their tracker identities ids (-1: no track,
    counted in `untracked`, left out); views (V_t,): the run's camera index of each of
    the association's cameras (None: the same cameras, num_views of them). num_views: the
    run's cameras (None: the first association's)."""

    def __init__(self, num_views=None):
        self.rows = dict(frame=[], subject=[], X=[], error=[], ncams=[], score=[],
                         points2d=[], scores2d=[])
        self.untracked = 0
        self.num_views = num_views

    def add(self, t, a, ids, keep=slice(None), views=None):
        ok = np.asarray(ids) >= 0
        self.untracked += int((~ok).sum())
        n = int(ok.sum())
        V, C = a.inliers.shape[1], a.X.shape[1]
        if self.num_views is None:
            self.num_views = V
        views = np.arange(V) if views is None else np.asarray(views, np.int64)
        points2d = np.full((n, self.num_views, C, 2), np.nan)
        scores2d = np.zeros((n, self.num_views, C))
        if a.points2d is not None:
            points2d[:, views] = a.points2d[keep][ok]
            scores2d[:, views] = a.scores2d[keep][ok]
        self.rows['points2d'].append(points2d)
        self.rows['scores2d'].append(scores2d)
        ncams = a.inliers.sum(1)
        with np.errstate(invalid='ignore', divide='ignore'):
            error = np.where(a.inliers, a.view_errors, 0.0).sum(1) / ncams
        self.rows['frame'].append(np.full(n, t))
        self.rows['subject'].append(np.asarray(ids)[ok])
        self.rows['X'].append(a.X[keep][ok])
        self.rows['error'].append(error[keep][ok])
        self.rows['ncams'].append(ncams[keep][ok])
        self.rows['score'].append(a.score[keep][ok])

    def result(self, tracker, **counts):
        """SubjectRows of the frames added; births / deaths from the SubjectTracker, the
        other counts (instances, unmatched, extra, seconds) given."""
        cat = {k: np.concatenate(v) if v else np.zeros(0) for k, v in self.rows.items()}
        return SubjectRows(**cat, births=tracker.births, deaths=tracker.deaths,
                           untracked=self.untracked, **counts)


def track_subjects(points, score, cameras, stamps_ns, num_subjects, association=None,
                   tracker=None):
    """SubjectRows of per-camera instances over time.

    points (T, V, N, C, 2) px (NaN = missing), score (T, V, N, C) (NaN = missing);
    cameras: V Camera; stamps_ns (T,) increasing; num_subjects: the most subjects kept in
    a frame (those seen by the most cameras, association's order; the others are counted
    in `extra`) and the most identities alive (the tracker's max_tracks); association:
    AssociationConfig; tracker: TrackerConfig (units: the cameras')."""
    import time

    from monet_ros.geometry.units import rig_units
    T, V, N, C, _ = points.shape
    trk = SubjectTracker(C, tracker, units=rig_units(cameras), max_tracks=num_subjects)
    rows = RowCollector(V)
    instances = unmatched = extra = 0
    start = time.perf_counter()
    for t in range(T):
        a = associate(points[t], cameras, score[t], association)
        instances += a.instances
        unmatched += a.unmatched
        keep = slice(0, num_subjects)
        extra += max(0, len(a.X) - num_subjects)
        ids = trk.step(a.X[keep], stamps_ns[t])
        rows.add(t, a, ids, keep)
    return rows.result(trk, instances=instances, unmatched=unmatched, extra=extra,
                       seconds=time.perf_counter() - start)


@dataclass
class SmoothedSubjects:
    """The offline filter of several subjects' rows (smooth_subjects).

    rows: SubjectRows of the filtered points (frame, subject, X rig units, error, ncams,
    score as temporal.Smoothed gives them; the 2D and the counts of the input rows),
    one row per frame and identity where the input had a row, plus the frames inside an
    identity's span that the filter bridged (a missed frame within max_gap_s); change_mm
    (R, C) |filtered - raw| (mm, NaN where either is missing); bridged (R, C) bool;
    per_subject {identity: temporal.Smoothed over its span of frames}; method; seconds;
    units."""
    rows: SubjectRows
    change_mm: np.ndarray
    bridged: np.ndarray
    method: str
    per_subject: dict = field(default_factory=dict)
    seconds: float = 0.0
    units: str = 'm'

    def summary(self):
        """One line: the filter, the identities, and the totals over them (points kept /
        bridged / gated out / left empty, median and p90 change)."""
        raw = sum(int(np.isfinite(s.raw).all(-1).sum()) for s in self.per_subject.values())
        out = int(np.isfinite(self.rows.X).all(-1).sum())
        rejected = sum(int(s.rejected.sum()) for s in self.per_subject.values())
        empty = sum(int((np.isfinite(s.raw).all(-1) & ~np.isfinite(s.X).all(-1)).sum())
                    for s in self.per_subject.values())
        change = self.change_mm[np.isfinite(self.change_mm)]
        med, p90 = (np.median(change), np.percentile(change, 90)) if change.size else (0, 0)
        return (f'filter {self.method} per subject ({len(self.per_subject)} identities, '
                f'each over the frames from its first to its last): {out} points out of '
                f'{raw} triangulated; {int(self.bridged.sum())} bridged over gaps, '
                f'{rejected} gated out as outliers, {empty} left empty (gaps longer than '
                f'the limit or isolated); change filtered - raw median {med:.1f} mm, p90 '
                f'{p90:.1f} mm; {self.seconds:.2f} s')


def smooth_subjects(rows, stamps_ns, cameras, edges=(), config=None, progress=False):
    """SmoothedSubjects: the offline filter (temporal.smooth_points: kalman or optim) run
    per identity of rows (SubjectRows with its 2D, frames indexing stamps_ns (T,)
    increasing), over the frames from the identity's first row to its last (its life in
    the output; frames without its row inside are missing measurements, bridged within
    config.max_gap_s), with its own 2D detections (rows.points2d / scores2d in `cameras`,
    the V cameras of the run) and the fusion's reprojection error. One identity's filter
    never sees another's points. edges: the skeleton's bones (optim's bone term, bone
    lengths per identity); config: temporal.FilterConfig (kalman or optim); progress:
    optim's bar. Units: the cameras' (the filters' mm and m/s^2 settings converted).
    Raises ValueError as smooth_points."""
    from monet_ros.geometry.units import rig_units
    from monet_ros.temporal import smooth_points

    start = time.perf_counter()
    stamps_ns = np.asarray(stamps_ns, np.int64)
    C, V = rows.X.shape[1] if rows.X.ndim == 3 else 0, len(cameras)
    if rows.points2d is None:
        raise ValueError('smooth_subjects: the rows hold no 2D detections')
    out = {k: [] for k in ('frame', 'subject', 'X', 'error', 'ncams', 'score', 'points2d',
                           'scores2d', 'change_mm', 'bridged')}
    per_subject = {}
    for ident in np.unique(rows.subject).tolist():
        mine = np.flatnonzero(rows.subject == ident)
        frames = rows.frame[mine].astype(np.int64)
        first = int(frames.min())
        span = np.arange(first, int(frames.max()) + 1)
        at = frames - first
        n = len(span)
        X = np.full((n, C, 3), np.nan)
        score = np.zeros((n, C))
        error = np.full((n, C), np.nan)
        points2d = np.full((n, V, C, 2), np.nan)
        scores2d = np.zeros((n, V, C))
        X[at], score[at], error[at] = rows.X[mine], rows.score[mine], rows.error[mine]
        points2d[at], scores2d[at] = rows.points2d[mine], rows.scores2d[mine]
        smoothed = smooth_points(X, score, points2d, scores2d, cameras, stamps_ns[span],
                                 edges, config, error=error, progress=progress)
        per_subject[int(ident)] = smoothed
        had = np.zeros(n, bool)
        had[at] = True
        keep = np.flatnonzero(had | np.isfinite(smoothed.X).all(-1).any(-1))
        out['frame'].append(span[keep])
        out['subject'].append(np.full(len(keep), ident))
        for key in ('X', 'error', 'ncams', 'score', 'change_mm', 'bridged'):
            out[key].append(getattr(smoothed, key)[keep])
        out['points2d'].append(points2d[keep])
        out['scores2d'].append(scores2d[keep])
    if per_subject:
        cat = {k: np.concatenate(v) for k, v in out.items()}
    else:
        cat = dict(frame=np.zeros(0, np.int64), subject=np.zeros(0, np.int64),
                   X=np.zeros((0, C, 3)), error=np.zeros((0, C)), ncams=np.zeros((0, C)),
                   score=np.zeros((0, C)), points2d=np.zeros((0, V, C, 2)),
                   scores2d=np.zeros((0, V, C)), change_mm=np.zeros((0, C)),
                   bridged=np.zeros((0, C), bool))
    change, bridged = cat.pop('change_mm'), cat.pop('bridged')
    method = config.method if config is not None else 'kalman'
    return SmoothedSubjects(rows=replace(rows, **cat), change_mm=change, bridged=bridged,
                            method=method, per_subject=per_subject,
                            seconds=time.perf_counter() - start,
                            units=rig_units(cameras))
