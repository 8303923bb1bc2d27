"""Multi-view triangulation: confidence-weighted DLT (one batched eigen-solve), robust variants
(Pose2Sim-style worst-camera exclusion, RANSAC over views) and reprojection error.

Shapes: points2d (V, N, 2) observed (distorted) pixels, NaN = missing; weights (V, N) >= 0
(0 or NaN = missing); cameras: list of V Camera; X (N, 3) world points, NaN = not
triangulated.

Cheirality, in every path: a triangulated point must lie in front of (camera-frame z > 0)
every view used for it. A view that puts the point behind its camera is an outlier (its
reprojection error counts as infinite); a point with fewer than 2 (min_views) views left is
NaN with no inlier views. (Rays that meet behind the cameras reproject with 0 px error, so
the reprojection error alone cannot catch them.)
"""
from functools import lru_cache
from itertools import combinations
from math import comb

import numpy as np

from monet_ros.geometry.camera import (
    project_uvz,
    project_views,
    stack_cameras,
    undistort_views,
)
from monet_ros.timing import NO_TIMER


def _prepare(points2d, cameras, weights, rig=None, ideal=None):
    """Validate shapes; -> (observed (V,N,2), ideal (V,N,2) with 0 at missing, w (V,N)).
    rig: stack_cameras(cameras) when at hand; ideal: undistort_views(rig, points2d) when
    the caller has it already (a copy is made)."""
    obs = np.asarray(points2d, dtype=np.float64)
    V = len(cameras)
    if obs.ndim != 3 or obs.shape[0] != V or obs.shape[2] != 2:
        raise ValueError(f'points2d must have shape (V={V}, N, 2), got {obs.shape}')
    if weights is None:
        w = np.ones(obs.shape[:2])
    else:
        w = np.array(weights, dtype=np.float64)
        if w.shape != obs.shape[:2]:
            raise ValueError(f'weights must have shape {obs.shape[:2]}, got {w.shape}')
        if (w < 0).any():
            raise ValueError('weights must be >= 0 (0 or NaN = missing)')
    if ideal is None:
        ideal = undistort_views(rig or stack_cameras(cameras), obs)
    else:
        ideal = np.array(ideal, dtype=np.float64)
        if ideal.shape != obs.shape:
            raise ValueError(f'ideal must have the shape of points2d {obs.shape}, got '
                             f'{ideal.shape}')
    # missing: NaN input, zero/NaN weight, or a point the distortion model cannot invert
    missing = ~(np.isfinite(ideal).all(axis=2) & np.isfinite(w) & (w > 0))
    w[missing] = 0.0
    ideal[missing] = 0.0
    return obs, ideal, w


def dlt_rows(ideal, P):
    """Unweighted DLT rows B (V, N, 2, 4): u P[2] - P[0] and v P[2] - P[1] per view/point.

    ideal: (V, N, 2) undistorted pixels; P: (V, 3, 4)."""
    return ideal[..., None] * P[:, None, 2:3, :] - P[:, None, 0:2, :]


def solve_dlt(B, w, per_metre=1.0):
    """Weighted DLT from rows B (V, N, 2, 4) and weights w (..., V, N) -> X (..., N, 3).

    The homogeneous least-squares point of each keypoint's rows A (2V, 4) (zero rows for
    zero weights): the right singular vector of A's smallest singular value, taken as the
    eigenvector of A^T A (4 x 4) of its smallest eigenvalue, all keypoints (and leading
    batch entries) in ONE batched np.linalg.eigh (a third of the time of an SVD of A;
    A^T A squares A's condition number, which in metres leaves the points within 1e-12 m
    of a per-keypoint SVD on real rigs in mm and m, test_triangulation); NaN where < 2
    weighted views.
    per_metre: the rig's length unit per metre (stack_cameras' 'per_metre'): the system is
    solved in metres and X returned in the rig's unit, so a rig in mm gives the points of
    the same rig in m x 1000 (a homogeneous DLT weighs X against its 4th coordinate by the
    unit; in metres it is cv2.triangulatePoints' and Pose2Sim's)."""
    V, N = B.shape[:2]
    if per_metre != 1.0:
        B = np.concatenate([B[..., :3], B[..., 3:] / per_metre], axis=-1)
    A = w[..., None, None] * B  # (..., V, N, 2, 4)
    A = A.swapaxes(-4, -3).reshape(*A.shape[:-4], N, 2 * V, 4)
    n_views = (w > 0).sum(axis=-2)  # (..., N)
    if 2 * V < 4:
        return np.full((*n_views.shape, 3), np.nan)
    h = np.linalg.eigh(A.swapaxes(-1, -2) @ A)[1][..., 0]  # eigenvalues ascending
    with np.errstate(divide='ignore', invalid='ignore'):
        X = h[..., :3] / h[..., 3:]
    if per_metre != 1.0:
        X = X * per_metre
    X[n_views < 2] = np.nan
    return X


def depths(rig, X):
    """Camera-frame depths (..., V, N) of X (..., N, 3) in every view of `rig` (the dict of
    stack_cameras); > 0 in front of the camera, NaN where X is NaN."""
    X = np.asarray(X, dtype=np.float64)
    return np.einsum('...nk,vk->...vn', X, rig['R'][:, 2]) + rig['t'][:, 2, None]


def _behind(rig, X, used):
    """Used views (..., V, N) that see X (..., N, 3) behind (or on) their camera plane."""
    with np.errstate(invalid='ignore'):
        return used & ~(depths(rig, X) > 0) & np.isfinite(X).all(axis=-1)[..., None, :]


def triangulate(points2d, cameras, weights=None):
    """Confidence-weighted DLT triangulation of N keypoints seen by V cameras.

    points2d: (V, N, 2) observed pixels (NaN = missing); weights: (V, N) >= 0 or None
    (rows of view v are scaled by weights[v], as Pose2Sim's weighted triangulation).
    Points are undistorted first. One batched eigen-solve over a (N, 2V, 4) stack (solve_dlt).
    Cheirality: views that put the point behind their camera are left out and the point is
    solved again from the rest; NaN if it is still behind a used view.
    Returns X (N, 3), NaN where fewer than 2 views (in front) are present."""
    _, ideal, w = _prepare(points2d, cameras, weights)
    rig = stack_cameras(cameras)
    B = dlt_rows(ideal, rig['P'])
    X = solve_dlt(B, w, rig['per_metre'])
    behind = _behind(rig, X, w > 0)
    if behind.any():
        cols = np.flatnonzero(behind.any(axis=0))
        w_cols = np.where(behind[:, cols], 0.0, w[:, cols])
        X_cols = solve_dlt(B[:, cols], w_cols, rig['per_metre'])
        X_cols[_behind(rig, X_cols, w_cols > 0).any(axis=0)] = np.nan
        X[cols] = X_cols
    return X


def _view_errors(rig, X, obs):
    """Pixel distances (..., V, N) between the projections of X (..., N, 3) and obs (V, N, 2)
    (the numbers of np.linalg.norm(project_views(rig, X) - obs, axis=-1))."""
    return _errors_and_depths(rig, X, obs)[0]


def _errors_and_depths(rig, X, obs):
    """(_view_errors', camera-frame depths (..., V, N)) of one projection of X."""
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        u, v, z = project_uvz(rig, X)
        du = u - obs[..., 0]
        dv = v - obs[..., 1]
        return np.sqrt(du * du + dv * dv), z


def _errors_behind(rig, X, obs, used):
    """_view_errors of X (..., N, 3) against obs (V, N, 2), inf at the `used` (..., V, N)
    views that see X behind (or on) their camera plane (_behind's rule: cheirality, a view
    behind is an outlier), from one projection."""
    err, z = _errors_and_depths(rig, X, obs)
    with np.errstate(invalid='ignore'):
        behind = used & (z <= 0)                          # NaN depth (NaN X): not behind
    if behind.any():  # (rarely: most frames have every point in front of its views)
        behind &= np.isfinite(X).all(axis=-1)[..., None, :]
        err[behind] = np.inf
    return err


def reprojection_error(X, points2d, cameras):
    """Reprojection error (V, N) in pixels of X (N, 3) against points2d (V, N, 2), with
    distortion; NaN where the observation or the point is missing."""
    X = np.asarray(X, dtype=np.float64)
    obs = np.asarray(points2d, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3 or obs.shape != (len(cameras), X.shape[0], 2):
        raise ValueError(f'expected X (N, 3) and points2d (V={len(cameras)}, N, 2), got '
                         f'{X.shape} and {obs.shape}')
    return _view_errors(stack_cameras(cameras), X, obs)


def _mean_used_error(err, used):
    """Mean error over used views: err, used (S, V, n) -> (S, n); inf when < 2 used."""
    n_used = used.sum(axis=-2)
    total = np.where(used, err, 0.0).sum(axis=-2)
    with np.errstate(invalid='ignore', divide='ignore'):
        mean = total / n_used
    mean[(n_used < 2) | ~np.isfinite(mean)] = np.inf
    return mean


# mean reprojection errors (px) of two view subsets closer than this are a tie (_exclusion)
TIE_PX = 1e-6


@lru_cache(maxsize=64)
def _left_out(V, k):
    """(C(V, k), V) bool, read-only: every subset of k of V views, as the views left out."""
    drop = np.zeros((comb(V, k), V), dtype=bool)
    for s, idx in enumerate(combinations(range(V), k)):
        drop[s, list(idx)] = True
    drop.setflags(write=False)
    return drop


def _exclusion(obs, B, w, rig, threshold_px, min_views, max_subsets):
    V, N = w.shape
    avail = w > 0
    n_avail = avail.sum(axis=0)
    X = np.full((N, 3), np.nan)
    accepted = np.zeros(N, dtype=bool)  # keypoints whose subset met the threshold
    current = avail.copy()  # best view subset found so far, per keypoint (V, N)
    current_err = np.zeros((V, N))  # its per-view reprojection errors
    todo = np.arange(N)
    for k in range(V - min_views + 1):
        todo = todo[n_avail[todo] - k >= min_views]
        if todo.size == 0:
            break
        cols = slice(None) if todo.size == N else todo  # (a slice: no copies)
        if k == 0:  # every available view
            used = avail[None, :, cols]
        elif comb(V, k) <= max_subsets:  # every subset with k views left out (as Pose2Sim)
            used = avail[None, :, cols] & ~_left_out(V, k)[:, :, None]  # (S, V, n)
        else:  # leave out the worst view (largest error) of the previous level's best subset
            err = np.where(current[:, cols], current_err[:, cols], -np.inf)
            worst = np.argmax(err, axis=0)
            used = current[:, cols].copy()
            used[worst, np.arange(todo.size)] = False
            used = used[None]
        # (w is 0 at the views not available: w * used is w when every available one is used)
        w_used = w[None, :, cols] if k == 0 else w[None, :, cols] * used
        Xs = solve_dlt(B[:, cols], w_used, rig['per_metre'])  # (S, n, 3)
        err = _errors_behind(rig, Xs, obs[:, cols], used)  # (S, V, n), inf: behind
        mean = _mean_used_error(err, used)
        if len(used) == 1:  # one candidate subset: it is the best
            best_mean, best_X, best_used, best_err = mean[0], Xs[0], used[0], err[0]
        else:
            # subsets within TIE_PX of each other are a tie, taken in subset order: an exact
            # tie (every view pair of a degenerate geometry meets with zero residual) is
            # otherwise broken by the eigen-solver's rounding, which differs between CPUs
            best = np.argmin(np.round(mean / TIE_PX), axis=0)
            n = np.arange(todo.size)
            best_mean, best_X = mean[best, n], Xs[best, n]
            best_used, best_err = used[best, :, n].T, err[best, :, n].T  # (V, n)
        ok = best_mean <= threshold_px
        X[todo[ok]] = best_X[ok]
        accepted[todo[ok]] = True
        current[:, cols] = best_used
        current_err[:, cols] = best_err
        todo = todo[~ok]
        if todo.size == 0:
            break
    # an accepted keypoint left `todo`: its current subset and errors are those accepted
    inliers = current & accepted
    return X, np.where(inliers, current_err, np.nan), inliers


def _two_view_points(B1, B2, valid):
    """Linear two-view points (..., 3) from the DLT rows B1, B2 (..., 2, 4) of two views:
    the 4 rows solved with X inhomogeneous (3x3 normal equations); garbage where not
    valid (..., bool)."""
    A = np.concatenate([B1, B2], axis=-2)  # (..., 4, 4)
    AtA = A[..., :3].swapaxes(-1, -2) @ A[..., :3]
    Atb = -(A[..., :3].swapaxes(-1, -2) @ A[..., 3:])
    AtA[~valid] = np.eye(3)
    try:
        return np.linalg.solve(AtA, Atb)[..., 0]
    except np.linalg.LinAlgError:  # a degenerate pair (e.g. coincident rays)
        return (np.linalg.pinv(AtA) @ Atb)[..., 0]


def _ransac(obs, B, w, rig, threshold_px, min_views, max_hypotheses, rng):
    V, N = w.shape
    avail = w > 0
    X = np.full((N, 3), np.nan)
    inliers = np.zeros((V, N), dtype=bool)
    todo = np.flatnonzero(avail.sum(axis=0) >= max(2, min_views))
    if todo.size == 0:
        return X, None, inliers
    n = todo.size
    cols = np.arange(n)
    if comb(V, 2) <= max_hypotheses:  # every view pair
        pairs = np.array(list(combinations(range(V), 2)))
        a = np.repeat(pairs[:, :1], n, axis=1)
        b = np.repeat(pairs[:, 1:], n, axis=1)
    else:  # two distinct random available views per hypothesis and keypoint
        order = np.argsort(~avail[:, todo], axis=0, kind='stable')  # available views first
        n_avail = avail[:, todo].sum(axis=0)
        r1 = (rng.random((max_hypotheses, n)) * n_avail).astype(int)
        r2 = (rng.random((max_hypotheses, n)) * (n_avail - 1)).astype(int)
        r2 += r2 >= r1
        a, b = order[r1, cols], order[r2, cols]  # (H, n)
    valid = avail[a, todo] & avail[b, todo]
    Xh = _two_view_points(B[a, todo], B[b, todo], valid)
    err = _errors_behind(rig, Xh, obs[:, todo], True)  # (H, V, n), inf: behind
    inl = (err < threshold_px) & avail[None, :, todo]
    count = inl.sum(axis=1).astype(np.float64)
    mean_inl = np.where(inl, err, 0.0).sum(axis=1) / np.maximum(count, 1)
    score = np.where(valid & np.isfinite(mean_inl), count - mean_inl / (threshold_px * 2), -1)
    best_inl = inl[np.argmax(score, axis=0), :, cols].T  # (V, n)
    Xr = solve_dlt(B[:, todo], w[:, todo] * best_inl, rig['per_metre'])
    for _ in range(2):  # re-select the inliers of the refined point, refine again
        err_r = _errors_behind(rig, Xr, obs[:, todo], True)
        new_inl = (err_r < threshold_px) & avail[:, todo]
        new_inl = np.where(new_inl.sum(axis=0) >= 2, new_inl, best_inl)
        if np.array_equal(new_inl, best_inl):
            break
        best_inl = new_inl
        Xr = solve_dlt(B[:, todo], w[:, todo] * best_inl, rig['per_metre'])
    ok = (best_inl.sum(axis=0) >= max(2, min_views)) & np.isfinite(Xr).all(axis=-1)
    ok &= ~_behind(rig, Xr, best_inl).any(axis=0)
    X[todo[ok]] = Xr[ok]
    inliers[:, todo[ok]] = best_inl[:, ok]
    return X, None, inliers


def triangulate_robust(points2d, cameras, weights=None, threshold_px=15.0, min_views=2,
                       method='exclusion', max_subsets=20, max_hypotheses=20, seed=0,
                       timer=None, errors=False, ideal=None):
    """Outlier-robust triangulation, batched over keypoints.

    method='exclusion' (Pose2Sim's rule): triangulate with all available views; while the
    mean reprojection error over the used views exceeds threshold_px, leave out k = 1, 2, ...
    views and keep the subset with the lowest mean error, until it is <= threshold_px
    (else NaN) or fewer than min_views would remain. Every subset of k left-out views is
    tried while C(V, k) <= max_subsets (exactly Pose2Sim's search); beyond that the view
    with the largest reprojection error in the previous level's best subset is left out
    (one candidate per keypoint). Each level is one batched DLT solve over all candidate
    subsets x pending keypoints.
    method='ransac': two-view linear hypotheses (every pair when C(V, 2) <= max_hypotheses,
    otherwise max_hypotheses random pairs per keypoint, seeded), inliers = views with
    reprojection error < threshold_px; the hypothesis with most inliers (then lowest mean
    inlier error) wins and is refined by weighted DLT on its inliers; NaN with fewer than
    min_views inliers.
    timer: a monet_ros.timing.StageTimer to account 'undistort', 'triangulate' and
    'errors' to. ideal: (V, N, 2) the undistorted pixels of points2d (undistort_views)
    when the caller has them (subjects.association), else None (undistorted here).
    Returns (X (N, 3), inlier_mask (V, N) bool of the views used), and with errors=True
    also view_errors (V, N): the reprojection errors (pixels, reprojection_error's) of the
    inlier views, NaN elsewhere (the exclusion search has them already)."""
    if min_views < 2:
        raise ValueError(f'min_views must be >= 2, got {min_views}')
    if not threshold_px > 0:
        raise ValueError(f'threshold_px must be > 0, got {threshold_px}')
    timer = timer or NO_TIMER
    rig = stack_cameras(cameras)
    with timer('undistort'):
        obs, ideal, w = _prepare(points2d, cameras, weights, rig, ideal)
    with timer('triangulate'):
        X, view_errors, inliers = _robust(obs, ideal, w, rig, threshold_px, min_views,
                                          method, max_subsets, max_hypotheses, seed)
    if not errors:
        return X, inliers
    with timer('errors'):
        if view_errors is None:
            view_errors = np.where(inliers, _view_errors(rig, X, obs), np.nan)
    return X, inliers, view_errors


def _robust(obs, ideal, w, rig, threshold_px, min_views, method, max_subsets,
            max_hypotheses, seed):
    """(X, view errors of the inliers or None where not at hand, inliers)."""
    B = dlt_rows(ideal, rig['P'])
    if method == 'exclusion':
        return _exclusion(obs, B, w, rig, threshold_px, min_views, max_subsets)
    if method == 'ransac':
        rng = np.random.default_rng(seed)
        return _ransac(obs, B, w, rig, threshold_px, min_views, max_hypotheses, rng)
    raise ValueError(f"method must be 'exclusion' or 'ransac', got {method!r}")


@lru_cache(maxsize=32)
def _every_pair(V, K):
    """(a, i, b, j), each (C(V, 2) K^2, 1): every candidate pair of two views a < b."""
    pairs = np.array(list(combinations(range(V), 2)))                # (P, 2)
    ij = np.stack(np.meshgrid(np.arange(K), np.arange(K), indexing='ij'), -1).reshape(-1, 2)
    a, b = (np.repeat(pairs[:, q], len(ij))[:, None] for q in (0, 1))
    i, j = (np.tile(ij[:, q], len(pairs))[:, None] for q in (0, 1))
    for x in (a, i, b, j):
        x.setflags(write=False)
    return a, i, b, j


def _candidate_pairs(avail, max_hypotheses, rng):
    """Hypotheses (view a, candidate i, view b, candidate j), each (H, N) or (H, 1), a != b:
    every pair of candidates of two different views when C(V, 2) K^2 <= max_hypotheses,
    else max_hypotheses random ones per keypoint (two distinct views with a candidate,
    seeded).
    avail (V, N, K) bool."""
    V, N, K = avail.shape
    if comb(V, 2) * K * K <= max_hypotheses:
        return _every_pair(V, K)                 # (H, 1) each: the same for every keypoint
    seen = avail.any(axis=2)                                         # (V, N)
    order = np.argsort(~seen, axis=0, kind='stable')                 # views with candidates
    count = np.maximum(seen.sum(axis=0), 2)
    cols = np.arange(N)
    r1 = (rng.random((max_hypotheses, N)) * count).astype(int)
    r2 = (rng.random((max_hypotheses, N)) * (count - 1)).astype(int)
    r2 += r2 >= r1
    i = (rng.random((max_hypotheses, N)) * K).astype(int)
    j = (rng.random((max_hypotheses, N)) * K).astype(int)
    return order[r1, cols], i, order[r2, cols], j


def select_candidates(points2d, cameras, weights=None, threshold_px=15.0, max_hypotheses=64,
                      seed=0):
    """Which of K candidate detections of each view to triangulate, per keypoint: the most
    consistent combination of views and candidates (a view whose best peak is another
    joint contributes its second peak instead of being dropped).

    points2d (V, N, K, 2) observed pixels of K candidates per view and keypoint (e.g. the
    top-K heatmap maxima, best first), NaN = missing; weights (V, N, K) >= 0 (their
    confidences; 0 or NaN = missing). Hypotheses: the linear two-view points of pairs of
    candidates of two different views (every pair while C(V, 2) K^2 <= max_hypotheses,
    else max_hypotheses random pairs per keypoint, seeded), dropped when either view sees
    the point behind it (cheirality). Each hypothesis is projected into every view; a view
    supports it when its candidate nearest to the projection is within threshold_px (and
    the point is in front of it). Score: number of supporting views, ties broken by their
    mean weight (relative to the keypoint's largest), then by their mean distance (px)
    (_support_score).
    The winner is refined once (weighted DLT on its supporting candidates, supporters
    re-selected as the nearest candidates within threshold_px, kept when >= 2).
    Batched over keypoints and hypotheses (one (H, V, N, K) distance array).
    Returns (choice (V, N) int: the candidate index of each view, 0 (the best) where the
    view supports no hypothesis or no hypothesis has 2 supporters; support (V, N) bool:
    the supporting views). Feed the chosen candidates to triangulate_robust (its
    outlier rejection and cheirality then decide the inliers)."""
    obs = np.asarray(points2d, dtype=np.float64)
    V = len(cameras)
    if obs.ndim != 4 or obs.shape[0] != V or obs.shape[3] != 2:
        raise ValueError(f'points2d must have shape (V={V}, N, K, 2), got {obs.shape}')
    _, N, K, _ = obs.shape
    if weights is not None and np.shape(weights) != obs.shape[:3]:
        raise ValueError(f'weights must have shape {obs.shape[:3]}, got {np.shape(weights)}')
    if not threshold_px > 0:
        raise ValueError(f'threshold_px must be > 0, got {threshold_px}')
    rig = stack_cameras(cameras)
    flat_w = None if weights is None else np.reshape(weights, (V, N * K))
    _, ideal, w = _prepare(obs.reshape(V, N * K, 2), cameras, flat_w, rig)
    w = w.reshape(V, N, K)
    avail = w > 0
    B = dlt_rows(ideal, rig['P']).reshape(V, N, K, 2, 4)
    a, i, b, j = _candidate_pairs(avail, max_hypotheses, np.random.default_rng(seed))
    cols = np.arange(N)
    valid = avail[a, cols, i] & avail[b, cols, j]                    # (H, N)
    Xh = _two_view_points(B[a, cols, i], B[b, cols, j], valid)       # (H, N, 3)
    in_front = depths(rig, Xh) > 0                                   # (H, V, N)
    hcols = np.arange(valid.shape[0])[:, None]
    valid &= in_front[hcols, a, cols] & in_front[hcols, b, cols]
    nearest, dist = _nearest_candidates(rig, Xh, obs, avail)         # (H, V, N)
    support = (dist < threshold_px) & in_front
    score = _support_score(support, dist, w, nearest, threshold_px)
    score[~valid] = -1.0
    best = np.argmax(score, axis=0)                                  # (N,)
    found = score[best, cols] >= 2                                   # 2 supporters or more
    choice = np.where(support[best, :, cols].T, nearest[best, :, cols].T, 0)
    chosen = support[best, :, cols].T & found
    # refine: weighted DLT on the supporters, then the nearest candidates of that point
    Bc = np.take_along_axis(B, choice[:, :, None, None, None], axis=2)[:, :, 0]
    wc = np.take_along_axis(w, choice[:, :, None], axis=2)[:, :, 0]
    Xr = solve_dlt(Bc, wc * chosen, rig['per_metre'])
    near_r, dist_r = _nearest_candidates(rig, Xr, obs, avail)
    with np.errstate(invalid='ignore'):
        support_r = (dist_r < threshold_px) & (depths(rig, Xr) > 0)
    better = found & (support_r.sum(axis=0) >= 2) & np.isfinite(Xr).all(axis=1)
    choice = np.where(better, np.where(support_r, near_r, 0), np.where(chosen, choice, 0))
    support = np.where(better, support_r, chosen)
    return choice, support


def _nearest_candidates(rig, X, obs, avail):
    """Per view, the candidate nearest the projection of X (..., N, 3): (index, distance)
    (..., V, N), distance inf where a view has no candidate; obs (V, N, K, 2)."""
    with np.errstate(invalid='ignore', divide='ignore', over='ignore'):  # (depth 0: inf)
        d = np.linalg.norm(project_views(rig, X)[..., None, :] - obs, axis=-1)  # (.., V,N,K)
    d = np.where(avail & np.isfinite(d), d, np.inf)
    nearest = np.argmin(d, axis=-1)
    return nearest, np.take_along_axis(d, nearest[..., None], axis=-1)[..., 0]


def _support_score(support, dist, w, nearest, threshold_px):
    """(H, N): supporting views + 0.8 x their mean weight / the keypoint's largest weight +
    0.1 x (1 - their mean distance / threshold_px): the count decides, the two tie-breaks
    add less than 1 together; between equally supported hypotheses (e.g. the left ankle
    where two views' best peaks are on the right one, and the right ankle from the same
    maps' second peaks) the stronger peaks win."""
    count = support.sum(axis=1)
    w_near = np.take_along_axis(w[None], nearest[..., None], axis=-1)[..., 0]  # (H, V, N)
    top = np.maximum(w.max(axis=(0, 2)), 1e-300)                             # (N,)
    with np.errstate(invalid='ignore', divide='ignore'):
        n = np.maximum(count, 1)
        mean_w = np.where(support, w_near, 0.0).sum(axis=1) / n / top
        mean_d = np.where(support, dist, 0.0).sum(axis=1) / n
    return count + 0.8 * mean_w + 0.1 * (1 - mean_d / threshold_px)
