"""Several subjects over a recording's 2D instances (no ROS): per-camera instance
tables split by instance, associated across cameras and tracked over time
(subjects.association, subjects.tracking), for `monet triangulate --subjects N`.

Instances: the readers name a keypoint of one instance '<instance>/<keypoint>' (SLEAP
tracks, DeepLabCut individuals, the points table's `subject` column). An instance name
labels one detection within a camera and frame only: nothing here assumes it means the
same subject in another camera or frame.
"""
from dataclasses import dataclass

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
    seconds (association + tracking, wall clock)."""
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


class RowCollector:
    """SubjectRows accumulated frame by frame (one implementation of the rows of
    `monet triangulate --subjects` and `monet process --subjects`).

    add(t, association, ids, keep): the subjects `keep` (index array or slice into
    association's subjects) of frame t with their tracker identities ids (-1: no track,
    counted in `untracked`, left out)."""

    def __init__(self):
        self.rows = dict(frame=[], subject=[], X=[], error=[], ncams=[], score=[])
        self.untracked = 0

    def add(self, t, a, ids, keep=slice(None)):
        ok = np.asarray(ids) >= 0
        self.untracked += int((~ok).sum())
        n = int(ok.sum())
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
    rows = RowCollector()
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
