"""Which instances in different cameras are the same subject, in one frame (no ROS).

Algorithm: greedy agglomerative clustering of the instances of all cameras on a
pairwise epipolar affinity, with the cycle-consistency constraint of Dong et al.
("Fast and Robust Multi-Person 3D Pose Estimation from Multiple Views", CVPR 2019,
sec. 3.2: a subject has at most one instance per camera) kept by construction
instead of by their convex relaxation:

1. cost(a, b) between two instances of two different cameras = the median, over the
   keypoints both see, of the symmetric epipolar distance (px, undistorted pixels:
   the mean of the distances of each point to the other's epipolar line, as Dong et al.'s
   geometric affinity before its exponential). Pairs with fewer than `min_common` common
   keypoints have no cost (inf). The median makes one wrong keypoint harmless.
2. Candidate pairs with cost <= threshold_px, those with >= strong_common common
   keypoints (or all of them) first, each group cheapest first, merge their two clusters
   when (a) the clusters share no camera and (b) the mean cost over every pair of their
   instances that has a cost (average linkage) is <= threshold_px. So a third camera's
   instance joins a subject only if it agrees with all of its views, not just one; and a
   partly hidden instance (few keypoints, whose median can agree with the wrong subject
   by chance) joins only after the well-seen instances have formed their subjects.
3. Repair of a chance pair: a two-instance cluster whose two instances each fit a
   different larger cluster (no shared camera, mean cost <= threshold_px) is split into
   them (two subjects that lie on one epipolar plane of two facing cameras agree in that
   pair only, and that pair may form before either instance joins its own subject).
4. A cluster with >= min_views instances is a subject; the others are left over
   (counted, never silently dropped). Each subject is triangulated with the project's
   robust triangulation (geometry.triangulate_robust: confidence-weighted DLT with
   worst-view exclusion or RANSAC, cheirality), all subjects in one batched call.

Epipolar distances are in pixels: the same for a rig in m or mm. The pair costs (a loop
over instance pairs and their keypoints) and the greedy merging (a loop over candidate
pairs) are compiled kernels (monet_ros.jit): a frame holds a few dozen instances, where
numpy's cost per call, not the arithmetic, was the time. The rare two-instance clusters of
step 3 are handled in numpy.
"""
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from monet_ros.config import setting, validate_config
from monet_ros.geometry.camera import stack_cameras, undistort_views
from monet_ros.geometry.epipolar import fundamental_from_params
from monet_ros.geometry.triangulation import triangulate_robust
from monet_ros.jit import kernel

METHODS = ('exclusion', 'ransac')


@dataclass(frozen=True)
class AssociationConfig:
    """Settings of the association across cameras (validated; errors name the field)."""
    threshold_px: float = setting(
        15.0, 'association: largest median symmetric epipolar distance (px) between two '
        'instances of one subject', minimum=0.0, exclusive_minimum=True)
    min_common: int = setting(
        3, 'association: fewest keypoints two instances must both see to be compared',
        minimum=1)
    strong_common: int = setting(
        6, 'association: instance pairs with this many common keypoints (or all) are '
        'merged before the others', minimum=1)
    confidence_threshold: float = setting(
        0.1, 'detection score below which a keypoint is left out', minimum=0.0)
    min_views: int = setting(2, 'fewest cameras (instances) of a subject', minimum=2)
    triangulation_px: float = setting(
        15.0, 'reprojection error (px) of an inlier view in the triangulation',
        minimum=0.0, exclusive_minimum=True)
    method: str = setting('exclusion', 'robust triangulation method', choices=METHODS)

    def __post_init__(self):
        validate_config(self)


_DEFAULT = AssociationConfig()


@dataclass
class Association:
    """One frame's subjects.

    X (S, C, 3) triangulated keypoints (the rig's unit), NaN where not triangulated;
    instance (S, V) int: the instance index of each subject in each camera, -1 = not seen;
    inliers (S, V, C) bool: the views used per keypoint; view_errors (S, V, C) px: their
    reprojection errors (NaN elsewhere); score (S, C): mean score of the inlier views
    (NaN where not triangulated); cost (S,) mean epipolar cost (px)
    of the subject's instance pairs; unmatched: instances (with >= 1 keypoint) in no
    subject; instances: instances with >= 1 keypoint; points2d (S, V, C, 2) the
    detections (observed px) of each subject's instances, NaN where the subject has none
    (not seen, keypoint missing or below the confidence threshold), and scores2d (S, V, C)
    their scores (0 there): the 2D an offline filter of the subject weighs
    (subjects.offline.smooth_subjects)."""
    X: np.ndarray
    instance: np.ndarray
    inliers: np.ndarray
    view_errors: np.ndarray
    score: np.ndarray
    cost: np.ndarray
    unmatched: int
    instances: int
    points2d: np.ndarray = None
    scores2d: np.ndarray = None


_F_CACHE = {}


def pair_fundamentals(cameras):
    """F (V, V, 3, 3) with x_b^T F[a, b] x_a = 0 for ideal pixels (zeros on the diagonal);
    cached per rig (stack_cameras' cache key)."""
    rig = stack_cameras(cameras)
    key = id(rig['K'])
    hit = _F_CACHE.get(key)
    if hit is not None and hit[0] is rig['K']:
        return hit[1]
    V = len(rig['K'])
    F = np.zeros((V, V, 3, 3))
    # int64 also for V < 2 (no pair: an empty float array cannot index)
    a, b = np.array(list(combinations(range(V), 2)), np.int64).reshape(-1, 2).T
    F[a, b] = fundamental_from_params(rig['K'][a], rig['R'][a], rig['t'][a],
                                      rig['K'][b], rig['R'][b], rig['t'][b])
    F[b, a] = F[a, b].swapaxes(-1, -2)
    F.setflags(write=False)
    if len(_F_CACHE) >= 16:
        _F_CACHE.pop(next(iter(_F_CACHE)))
    _F_CACHE[key] = (rig['K'], F)
    return F


def pair_costs(ideal, present, view, F, min_common):
    """(cost (M, M), common (M, M) int) between M instances: the median symmetric epipolar
    distance (px) over the keypoints both see (inf for the same camera, itself, or
    < min_common common keypoints) and how many they both see.

    ideal (M, C, 2) undistorted pixels; present (M, C) bool; view (M,) camera indices;
    F (V, V, 3, 3) of pair_fundamentals. The distances are computed for the pairs that can
    have a cost only (two cameras, >= min_common common keypoints), each once (the cost is
    symmetric: x_b^T F_ab x_a = x_a^T F_ba x_b). Compiled (_pair_costs). Raises
    ValueError for shapes that do not match, a camera index outside F (the compiled loop
    does not check its indices) or min_common < 1."""
    ideal = np.asarray(ideal, np.float64)
    present = np.asarray(present, np.bool_)
    view = np.asarray(view, np.int64)
    F = np.asarray(F, np.float64)
    M, C = present.shape
    if ideal.shape != (M, C, 2) or view.shape != (M,) or F.shape[1:] != (len(F), 3, 3):
        raise ValueError(f'pair_costs: ideal {ideal.shape}, present {present.shape}, view '
                         f'{view.shape} and F {F.shape} must be (M, C, 2), (M, C), (M,) and '
                         '(V, V, 3, 3)')
    _check_views(view, len(F))
    if not int(min_common) >= 1:
        raise ValueError(f'pair_costs: min_common must be >= 1, got {min_common}')
    return _pair_costs(ideal, present, view, F, int(min_common))


def _check_views(view, num_views):
    """ValueError unless every camera index of view (M,) is in [0, num_views)."""
    if len(view) and not (0 <= view.min() and view.max() < num_views):
        raise ValueError(f'camera indices must be in [0, {num_views}), got {view.min()} to '
                         f'{view.max()}')


@kernel(example=lambda: (np.zeros((2, 1, 2)), np.ones((2, 1), bool), np.arange(2),
                         np.zeros((2, 2, 3, 3)), 1))
def _pair_costs(ideal, present, view, F, min_common):
    """pair_costs compiled (monet_ros.jit): loops over instance pairs and keypoints. The
    distance of keypoint c: 0.5 |x_b^T F x_a| (1 / |l_a| + 1 / |l_b|), l_a = F x_a the line
    of a in b's image and l_b = F^T x_b that of b in a's, |l| the norm of its first two
    terms; not finite (a degenerate line) counts as inf; the median of an even count is the
    mean of the middle two."""
    M, C = present.shape
    cost = np.full((M, M), np.inf)
    common = np.zeros((M, M), np.int64)
    d = np.empty(C)
    for a in range(M):
        for b in range(a, M):
            n = 0
            for c in range(C):
                if present[a, c] and present[b, c]:
                    n += 1
            common[a, b] = common[b, a] = n
            if b == a or n == 0 or n < min_common or view[a] == view[b]:
                continue
            f = F[view[a], view[b]]                   # x_b^T f x_a = 0
            j = 0
            for c in range(C):
                if not (present[a, c] and present[b, c]):
                    continue
                xa, ya, xb, yb = ideal[a, c, 0], ideal[a, c, 1], ideal[b, c, 0], ideal[b, c, 1]
                la0 = f[0, 0] * xa + f[0, 1] * ya + f[0, 2]
                la1 = f[1, 0] * xa + f[1, 1] * ya + f[1, 2]
                la2 = f[2, 0] * xa + f[2, 1] * ya + f[2, 2]
                lb0 = f[0, 0] * xb + f[1, 0] * yb + f[2, 0]
                lb1 = f[0, 1] * xb + f[1, 1] * yb + f[2, 1]
                num = abs(la0 * xb + la1 * yb + la2)
                dist = 0.5 * num * (1 / np.sqrt(la0 * la0 + la1 * la1)
                                    + 1 / np.sqrt(lb0 * lb0 + lb1 * lb1))
                if not np.isfinite(dist):
                    dist = np.inf
                i = j                                     # insertion sort: n <= C, small
                while i > 0 and d[i - 1] > dist:
                    d[i] = d[i - 1]
                    i -= 1
                d[i] = dist
                j += 1
            cost[a, b] = cost[b, a] = 0.5 * (d[(n - 1) // 2] + d[n // 2])
    return cost, common


def cluster_instances(cost, view, num_views, threshold_px, strong=None):
    """Cluster labels (M,) of instances by the greedy rule of the module docstring (steps
    2 and 3): candidate pairs (cost (M, M) <= threshold_px; the `strong` (M, M) bool ones
    first, then the others) cheapest first, merged when their clusters share no camera and
    their average linkage (mean finite cost between their members) is <= threshold_px;
    then _dissolve_pairs. view (M,) camera indices < num_views. Step 2 is compiled
    (_merge_clusters). Raises ValueError for shapes that do not match or camera indices
    outside [0, num_views)."""
    view = np.asarray(view, np.int64)
    M = len(view)
    cost = np.asarray(cost, np.float64)
    strong = np.zeros((M, M), bool) if strong is None else np.asarray(strong, np.bool_)
    if cost.shape != (M, M) or strong.shape != (M, M):
        raise ValueError(f'cluster_instances: cost {cost.shape} and strong {strong.shape} '
                         f'must be (M, M) for the M = {M} instances of view')
    _check_views(view, num_views)
    return _clusters(cost, view, int(num_views), float(threshold_px), strong)


def _clusters(cost, view, num_views, threshold_px, strong):
    """cluster_instances of checked arrays (associate's own: no second check per frame)."""
    label = _merge_clusters(cost, view, num_views, threshold_px, strong)
    return _dissolve_pairs(label, cost, view, num_views, threshold_px)


@kernel(example=lambda: (np.zeros((2, 2)), np.arange(2), 2, 1.0, np.zeros((2, 2), bool)))
def _merge_clusters(cost, view, num_views, threshold_px, strong):
    """Step 2 of cluster_instances compiled (monet_ros.jit) -> labels (M,) int64 (a cluster
    is labelled by one of its instances). Candidate order: strong before weak, then by cost
    (a stable sort: equal costs in row-major order of (a, b), a < b)."""
    M = len(view)
    n = 0
    for a in range(M):
        for b in range(a + 1, M):
            if cost[a, b] <= threshold_px:
                n += 1
    pa = np.empty(n, np.int64)
    pb = np.empty(n, np.int64)
    pc = np.empty(n)
    n = 0
    for a in range(M):
        for b in range(a + 1, M):
            if cost[a, b] <= threshold_px:
                pa[n], pb[n], pc[n] = a, b, cost[a, b]
                n += 1
    by_cost = np.argsort(pc, kind='mergesort')
    order = np.empty(n, np.int64)
    k = 0
    for want_strong in (True, False):
        for i in by_cost:
            if strong[pa[i], pb[i]] == want_strong:
                order[k] = i
                k += 1
    label = np.arange(M)
    cams = np.zeros((M, num_views), np.bool_)            # cameras of each cluster, by label
    for m in range(M):
        cams[m, view[m]] = True
    first = np.empty(M, np.int64)
    second = np.empty(M, np.int64)
    for i in order:
        la, lb = label[pa[i]], label[pb[i]]
        if la == lb:
            continue
        shared = False
        for v in range(num_views):
            if cams[la, v] and cams[lb, v]:
                shared = True
                break
        if shared:
            continue
        n1 = n2 = 0
        for m in range(M):
            if label[m] == la:
                first[n1] = m
                n1 += 1
            elif label[m] == lb:
                second[n2] = m
                n2 += 1
        total, count = 0.0, 0
        for x in range(n1):
            for y in range(n2):
                c = cost[first[x], second[y]]
                if c < np.inf:
                    total += c
                    count += 1
        if total > threshold_px * count:
            continue
        for y in range(n2):
            label[second[y]] = la
        for v in range(num_views):
            cams[la, v] = cams[la, v] or cams[lb, v]
    return label


def _dissolve_pairs(label, cost, view, num_views, threshold_px):
    """Step 3 of the module docstring: a two-instance cluster whose two instances each
    fit a different larger cluster (no shared camera, mean cost <= threshold_px) is split
    into them. Labels are changed in place and returned."""
    size = np.bincount(label, minlength=len(label))    # labels are instance indices
    if not (size == 2).any():
        return label
    finite = np.isfinite(cost)
    cams = np.zeros((len(label), num_views), bool)     # cameras of each cluster, by label
    cams[label, view] = True
    big = np.flatnonzero(size > 2)
    for pair in np.flatnonzero(size == 2):
        members = np.flatnonzero(label == pair)
        target = []
        for m in members:
            fit = [(cost[m, label == b][finite[m, label == b]].mean(), b) for b in big
                   if not cams[b, view[m]] and finite[m, label == b].any()]
            fit = [f for f in fit if f[0] <= threshold_px]
            target.append(min(fit)[1] if fit else None)
        if None in target or target[0] == target[1]:
            continue
        for m, b in zip(members, target):
            label[m] = b
            cams[b, view[m]] = True
    return label


def _empty(V, C, M):
    """An Association without subjects, M instances all unmatched."""
    return Association(np.zeros((0, C, 3)), np.zeros((0, V), int), np.zeros((0, V, C), bool),
                       np.zeros((0, V, C)), np.zeros((0, C)), np.zeros(0), M, M,
                       np.zeros((0, V, C, 2)), np.zeros((0, V, C)))


def associate(points2d, cameras, scores=None, config=None):
    """Association of one frame's per-camera instances into subjects, triangulated.

    points2d (V, N, C, 2) observed (distorted) pixels: N instance slots per camera (pad
    with NaN: a camera with fewer instances leaves slots all NaN), C keypoints, NaN =
    missing keypoint; the instance order of a camera means nothing. scores (V, N, C) or
    None (all 1): keypoints below config.confidence_threshold are left out and the rest
    weigh the triangulation. cameras: V geometry.Camera (one unit). config:
    AssociationConfig (None: defaults). Algorithm: the module docstring.
    Returns Association, subjects ordered by how many cameras see them (most first), then
    by their first instance. Raises ValueError for bad shapes."""
    config = config or _DEFAULT
    pts = np.asarray(points2d, np.float64)
    V = len(cameras)
    if pts.ndim != 4 or pts.shape[0] != V or pts.shape[-1] != 2:
        raise ValueError(f'points2d must have shape (V={V}, N, C, 2), got {pts.shape}')
    _, N, C, _ = pts.shape
    w = np.ones((V, N, C)) if scores is None else np.asarray(scores, np.float64)
    if w.shape != (V, N, C):
        raise ValueError(f'scores must have shape {(V, N, C)}, got {w.shape}')
    rig = stack_cameras(cameras)
    present = np.isfinite(pts).all(-1)
    if scores is not None:  # NaN scores compare False: missing
        present &= (w >= config.confidence_threshold) & (w > 0)
    elif not 1.0 >= config.confidence_threshold:
        present[...] = False
    ideal = undistort_views(rig, np.where(present[..., None], pts, np.nan)
                            .reshape(V, N * C, 2)).reshape(V, N, C, 2)
    present &= np.isfinite(ideal).all(-1)
    exists = present.any(-1)                                          # (V, N)
    view, slot = np.nonzero(exists)
    M = len(view)
    if M < 2:
        return _empty(V, C, M)
    # pair_costs and cluster_instances of arrays made here (no checks needed: view from
    # np.nonzero, the config's min_common >= 1)
    cost, common = _pair_costs(ideal[view, slot], present[view, slot], view,
                               pair_fundamentals(cameras), config.min_common)
    label = _clusters(cost, view, V, config.threshold_px,
                      common >= min(config.strong_common, C))
    size = np.bincount(label, minlength=M)
    ids = np.flatnonzero(size >= config.min_views)
    if not len(ids):
        return _empty(V, C, M)
    first = np.full(M, M)
    np.minimum.at(first, label, np.arange(M))                        # first instance
    ids = ids[np.lexsort((first[ids], -size[ids]))]
    S = len(ids)
    member = label[None, :] == ids[:, None]                          # (S, M)
    instance = np.full((S, V), -1)
    s_idx, m_idx = np.nonzero(member)
    instance[s_idx, view[m_idx]] = slot[m_idx]
    rows, take = np.arange(V)[:, None], np.maximum(instance, 0).T     # (V, S)
    keep = (present[rows, take] & (instance >= 0).T[..., None])[..., None]  # (V, S, C, 1)
    sub_w = np.where(keep[..., 0], w[rows, take], 0.0)                # (V, S, C)
    sub_pts = np.where(keep, pts[rows, take], np.nan)                 # (V, S, C, 2)
    sub_ideal = np.where(keep, ideal[rows, take], np.nan)
    X, inl, err, score = triangulate_scored(sub_pts.reshape(V, S * C, 2), sub_w.reshape(V, S * C),
                                      cameras, config, sub_ideal.reshape(V, S * C, 2))
    inl = inl.reshape(V, S, C).transpose(1, 0, 2)
    score = score.reshape(S, C)
    finite = np.isfinite(cost)
    pair = member[:, :, None] & member[:, None, :] & finite[None]     # (S, M, M)
    with np.errstate(invalid='ignore'):
        mean_cost = np.where(pair, cost[None], 0.0).sum((1, 2)) / pair.sum((1, 2))
    return Association(X=X.reshape(S, C, 3), instance=instance,
                       inliers=inl, view_errors=err.reshape(V, S, C).transpose(1, 0, 2),
                       score=score, cost=mean_cost,
                       unmatched=int(M - member.sum()), instances=M,
                       points2d=sub_pts.transpose(1, 0, 2, 3),
                       scores2d=sub_w.transpose(1, 0, 2))


def triangulate_scored(pts, w, cameras, config, ideal=None):
    """The robust triangulation of associate, leave_out_views and detection's settling (one
    rule, geometry.triangulate_robust with the AssociationConfig's triangulation_px,
    min_views and method): pts (V, n, 2) px, w (V, n) detection scores (0 = none), ideal
    (V, n, 2) their undistorted points or None ->
    (X (n, 3), inliers (V, n), view errors (V, n), score (n,): the mean score of the
    inlier views, NaN without one)."""
    X, inl, err = triangulate_robust(pts, cameras, w, threshold_px=config.triangulation_px,
                                     min_views=config.min_views, method=config.method,
                                     errors=True, ideal=ideal)
    n_inl = inl.sum(0)
    with np.errstate(invalid='ignore', divide='ignore'):
        score = np.where(inl, w, 0.0).sum(0) / n_inl
    score[n_inl == 0] = np.nan
    return X, inl, err, score


def leave_out_views(a, cameras, drop, config=None):
    """Triangulate again, in place, the keypoints of an Association's subjects with the
    views `drop` left out (subjects.detection step 4: views whose instance came from
    another subject's crop).

    a: Association (with points2d / scores2d); cameras: its V geometry.Camera; drop
    (S, V, C) bool: the views to leave out of each subject's keypoint. For every (s, c)
    with a view dropped, that keypoint is triangulated as associate does (the project's
    robust triangulation, config's triangulation_px, min_views and method, one batched
    call) from the subject's other detections (scores2d > 0): X, inliers, view_errors and
    score are replaced (NaN where fewer than min_views detections are left); the dropped
    views' points2d become NaN and scores2d 0 (not this subject's 2D). config:
    AssociationConfig (None: defaults). -> int: the (subject, view, keypoint) entries
    dropped that held a detection. Raises ValueError for a drop of another shape."""
    config = config or _DEFAULT
    S, V, C = a.inliers.shape
    drop = np.asarray(drop, bool)
    if drop.shape != (S, V, C):
        raise ValueError(f'drop must have shape {(S, V, C)}, got {drop.shape}')
    drop = drop & (a.scores2d > 0)
    s, c = np.nonzero(drop.any(1))                                    # (n,) keypoints
    if not len(s):
        return 0
    a.points2d[drop] = np.nan
    a.scores2d[drop] = 0.0
    X, inl, err, score = triangulate_scored(a.points2d[s, :, c].transpose(1, 0, 2),   # (V, n, 2)
                                      a.scores2d[s, :, c].T, cameras, config)
    a.X[s, c] = X
    a.inliers[s, :, c] = inl.T
    a.view_errors[s, :, c] = err.T
    a.score[s, c] = score
    return int(drop.sum())
