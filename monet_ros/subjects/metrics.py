"""Identity metrics of tracked subjects against ground truth (no ROS).

A ground-truth subject g and a track h "match" in a frame when both exist and the mean
distance over their common finite keypoints is <= threshold (the rig's unit).
- identity switches (as CLEAR MOT's IDSW, Bernardin & Stiefelhagen 2008): per frame, each
  ground-truth subject takes the track matched to it by the Hungarian assignment of the
  frame's distances (gated by threshold); a switch is a ground-truth subject whose matched
  track differs from the one it last had;
- IDF1 (Ristani et al., "Performance Measures and a Data Set for Multi-Target,
  Multi-Camera Tracking", ECCV 2016 workshops): one global one-to-one assignment of tracks
  to ground-truth subjects maximising IDTP, the frames where assigned pairs match;
  IDF1 = 2 IDTP / (ground-truth detections + track detections).
- assign_subjects (the reference subjects of `monet eval --reference` / `monet train
  --holdout-labelled` to the tracks of a several-subject run): one global one-to-one
  assignment (Hungarian) of ground-truth subjects to tracks minimising the sum of each
  assigned pair's mean distance over the frames both have; no threshold (every subject
  that shares a frame with a track gets one while tracks remain).
"""
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment


@dataclass
class IdentityScores:
    """switches: identity switches (all ground-truth subjects); idf1 in [0, 1]; idtp, gt
    (ground-truth subject-frames), pred (track-frames); matched (frames x subjects matched
    per frame); error (G,) mean 3D keypoint error per ground-truth subject over its
    matched frames (rig units), NaN when never matched."""
    switches: int
    idf1: float
    idtp: int
    gt: int
    pred: int
    matched: int
    error: np.ndarray
    found: np.ndarray
    track: np.ndarray
    distance: np.ndarray


def _distance(A, B):
    """Mean distances (T, G, H) over common finite keypoints; A (T, G, C, 3), B (T, H, C, 3)."""
    d = np.linalg.norm(A[:, :, None] - B[:, None], axis=-1)            # (T, G, H, C)
    ok = np.isfinite(d)
    n = ok.sum(-1)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(n > 0, np.where(ok, d, 0.0).sum(-1) / n, np.inf)


def identity_scores(gt_X, pred_X, pred_ids, threshold):
    """IdentityScores of tracks against ground truth.

    gt_X (T, G, C, 3) ground-truth keypoints (subject g in slot g; all NaN = absent);
    pred_X (T, H, C, 3) tracked subjects per frame (padded with NaN), pred_ids (T, H) int
    their identities (-1 = none / padding); threshold: match distance (the rig's unit)."""
    gt_X, pred_X = np.asarray(gt_X, float), np.asarray(pred_X, float)
    pred_ids = np.asarray(pred_ids)
    T, G = gt_X.shape[:2]
    dist = _distance(gt_X, pred_X)
    dist = np.where((pred_ids >= 0)[:, None, :], dist, np.inf)
    gt_here = np.isfinite(gt_X).all(-1).any(-1)                         # (T, G)
    pred_here = (pred_ids >= 0) & np.isfinite(pred_X).all(-1).any(-1)   # (T, H)
    uids = np.unique(pred_ids[pred_ids >= 0])
    last = np.full(G, -1)
    switches = matched = 0
    err_sum, err_n = np.zeros(G), np.zeros(G)
    co = np.zeros((G, len(uids)), np.int64)
    track = np.full((T, G), -1)
    distance = np.full((T, G), np.nan)
    col = np.searchsorted(uids, np.maximum(pred_ids, 0))
    for t in range(T):     # the per-frame assignment (few subjects: a tiny matrix)
        ok = dist[t] <= threshold
        g_idx, h_idx = np.nonzero(ok)
        np.add.at(co, (g_idx, col[t, h_idx]), 1)
        rows, cols = linear_sum_assignment(np.where(ok, dist[t], 1e12))
        keep = ok[rows, cols]
        rows, cols = rows[keep], cols[keep]
        ids = pred_ids[t, cols]
        switches += int(((last[rows] >= 0) & (last[rows] != ids)).sum())
        last[rows] = ids
        track[t, rows] = ids
        distance[t, rows] = dist[t, rows, cols]
        matched += len(rows)
        err_sum[rows] += dist[t, rows, cols]
        err_n[rows] += 1
    if co.size:
        r, c = linear_sum_assignment(-co)
        idtp = int(co[r, c].sum())
    else:
        idtp = 0
    n_gt, n_pred = int(gt_here.sum()), int(pred_here.sum())
    idf1 = 2 * idtp / (n_gt + n_pred) if n_gt + n_pred else 1.0
    with np.errstate(invalid='ignore', divide='ignore'):
        error = err_sum / err_n
    return IdentityScores(switches=switches, idf1=idf1, idtp=idtp, gt=n_gt, pred=n_pred,
                          matched=matched, error=error, found=err_n.astype(np.int64),
                          track=track, distance=distance)


def assign_subjects(gt_X, pred_X, pred_ids):
    """(track (G,) int, distance (G,)): the track identity assigned to each ground-truth /
    reference subject and the pair's mean distance (module docstring's rule).

    gt_X (T, G, C, D) subject g in slot g (all NaN = absent; D = 3 for 3D points, any D
    works); pred_X (T, H, C, D) tracked subjects per frame (padded with NaN), pred_ids
    (T, H) int their identities (-1 = none / padding), as identity_scores takes them. A
    pair's distance in a frame is the mean over their common finite keypoints (the one of
    identity_scores), its cost the mean of those over the frames where both have one.
    The assignment (scipy linear_sum_assignment) first pairs as many subjects as share a
    frame with some track, then minimises the sum of the pairs' costs. track -1 and
    distance NaN: a subject sharing no frame with any track left to it."""
    gt_X, pred_X = np.asarray(gt_X, float), np.asarray(pred_X, float)
    pred_ids = np.asarray(pred_ids)
    G = gt_X.shape[1]
    track, distance = np.full(G, -1), np.full(G, np.nan)
    uids = np.unique(pred_ids[pred_ids >= 0])
    if not len(uids) or not G:
        return track, distance
    dist = _distance(gt_X, pred_X)                                      # (T, G, H)
    t, g, h = np.nonzero((pred_ids >= 0)[:, None, :] & np.isfinite(dist))
    col = np.searchsorted(uids, pred_ids[t, h])
    total, count = np.zeros((G, len(uids))), np.zeros((G, len(uids)), np.int64)
    np.add.at(total, (g, col), dist[t, g, h])
    np.add.at(count, (g, col), 1)
    with np.errstate(invalid='ignore', divide='ignore'):
        cost = np.where(count > 0, total / np.maximum(count, 1), np.inf)
    # pairs without a common frame cost more than any sum of real pairs: as many pairs as
    # possible first, then the least total distance
    big = 1.0 + G * float(np.max(cost[np.isfinite(cost)], initial=0.0)) * 2
    rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, big))
    keep = count[rows, cols] > 0
    track[rows[keep]] = uids[cols[keep]]
    distance[rows[keep]] = cost[rows[keep], cols[keep]]
    return track, distance
