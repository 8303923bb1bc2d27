"""Spatiotemporal optimisation of 3D keypoints over a whole recording (no ROS).

Minimises, with scipy.optimize.least_squares (trust-region reflective, sparse Jacobian,
LSMR), the sum of three kinds of residuals over the positions X (T, C, 3) of every joint
at every frame it is kept:

- reprojection: (project_v(X[t, c]) - uv[t, v, c]) * sqrt(score) / reprojection_px for
  each 2D detection with score >= confidence_threshold (distortion included), under a
  robust loss (config.loss: cauchy, soft_l1, huber; 'linear' = plain least squares), so a
  view whose peak is on the wrong limb is discounted, not averaged in;
- smoothness: the finite-difference acceleration of each joint (second difference over
  the actual frame times) divided by acceleration_m_s2 (a Gaussian prior on
  acceleration, as a constant-velocity model's white-noise acceleration);
- bone lengths: (|X[t, a] - X[t, b]| - L_ab) / bone_mm for each bone of the skeleton,
  L_ab the median length over confident frames (temporal.bones).

Smoothness and bone terms are quadratic; only the reprojection term is robust. The
Jacobian is assembled analytically as a sparse matrix (projection derivatives by central
differences of 10 um per point, batched per view), so one iteration costs a few batched
projections and one LSMR solve. The same objective as anipose's triangulate_optim
(Karashchuk et al., Cell Reports 2021, "Anipose", STAR methods), with an analytic sparse
Jacobian instead of finite differences over a jac_sparsity pattern.
"""
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

from monet_ros.geometry.camera import project_views, stack_cameras
from monet_ros.geometry.units import rig_units


@dataclass
class OptimResult:
    """X (T, C, 3) optimised (the rig's unit), NaN where not kept; support (T, C) in [0, 1]: mean
    over the views used of score x the robust loss weight of their residual (0: no view,
    a bridged frame); cost (final objective), iterations, status (least_squares')."""
    X: np.ndarray
    support: np.ndarray
    cost: float
    iterations: int
    status: int


def _robust(name, z):
    """rho, rho', rho'' (3, m) of scipy's robust losses at z = residual^2 (f_scale 1)."""
    if name == 'cauchy':
        return np.stack([np.log1p(z), 1 / (1 + z), -1 / (1 + z) ** 2])
    if name == 'soft_l1':
        s = np.sqrt(1 + z)
        return np.stack([2 * z / (s + 1), 1 / s, -0.5 / s ** 3])   # 2 (s - 1), no cancelling
    if name == 'huber':
        big = z > 1
        sz = np.sqrt(np.where(big, z, 1.0))
        return np.stack([np.where(big, 2 * sz - 1, z), np.where(big, 1 / sz, 1.0),
                         np.where(big, -0.5 / sz ** 3, 0.0)])
    if name == 'linear':
        return np.stack([z, np.ones_like(z), np.zeros_like(z)])
    raise ValueError(f'loss must be cauchy, soft_l1, huber or linear, got {name!r}')


def build_problem(X0, keep, points2d, score, cameras, stamps_ns, edges, lengths, config):
    """The least-squares problem of optimise (same arguments): a namespace with
    residuals(x) (m,), jacobian(x) (m, 3N) scipy.sparse CSR, loss(z) (3, m) (robust on the
    n_reproj reprojection residuals, which come first), x0 (3N,) from X0[keep], keep,
    N, n_reproj, obs (t, v, c index arrays of the reprojection terms), shape (T, C);
    None when nothing is kept."""
    X0 = np.asarray(X0, np.float64)
    keep = np.asarray(keep, bool) & np.isfinite(X0).all(-1)
    T, C = keep.shape
    V = len(cameras)
    points2d = np.asarray(points2d, np.float64)
    score = np.asarray(score, np.float64)
    physical = config.in_units(rig_units(cameras))     # mm, m/s^2 -> the rig's unit
    step = physical.step
    index = np.full((T, C), -1, np.int64)
    index[keep] = np.arange(keep.sum())
    N = int(keep.sum())
    if N == 0:
        return None
    # reprojection terms: one per (t, v, c) detection of a kept joint
    seen = (np.isfinite(points2d).all(-1) & (score >= config.confidence_threshold)
            & keep[:, None, :])
    ot, ov, oc = np.nonzero(seen)
    on = index[ot, oc]
    uv = points2d[ot, ov, oc]
    ow = np.sqrt(score[ot, ov, oc]) / config.reprojection_px
    by_view = [np.flatnonzero(ov == v) for v in range(V)]
    rigs = [stack_cameras([cam]) for cam in cameras]
    n_reproj = 2 * len(on)
    # smoothness terms: triples of consecutive kept frames of a joint
    t_sec = (np.asarray(stamps_ns, np.int64) - int(stamps_ns[0])) / 1e9
    triple = keep[:-2] & keep[1:-1] & keep[2:] if T >= 3 else np.zeros((0, C), bool)
    st, sc = np.nonzero(triple)
    dt1 = t_sec[st + 1] - t_sec[st]
    dt2 = t_sec[st + 2] - t_sec[st + 1]
    coef = np.stack([2 / (dt1 * (dt1 + dt2)), -2 / (dt1 * dt2), 2 / (dt2 * (dt1 + dt2))],
                    -1) / physical.acceleration                             # (S, 3)
    s_idx = np.stack([index[st, sc], index[st + 1, sc], index[st + 2, sc]], -1)
    # bone terms
    edges = np.asarray(edges, np.int64).reshape(-1, 2)
    lengths = np.asarray(lengths, np.float64).reshape(-1)
    good = np.isfinite(lengths)
    edges, lengths = edges[good], lengths[good]
    both = keep[:, edges[:, 0]] & keep[:, edges[:, 1]] if len(edges) else np.zeros((T, 0),
                                                                                   bool)
    bt, bb = np.nonzero(both)
    ba, bo = index[bt, edges[bb, 0]], index[bt, edges[bb, 1]]
    bl = lengths[bb]
    bone_sd = physical.bone
    n_smooth, n_bone = 3 * len(st), len(bt)
    m = n_reproj + n_smooth + n_bone

    # constant sparsity: rows and columns of every nonzero
    r_rows = np.repeat(np.arange(n_reproj), 3)
    r_cols = (3 * np.repeat(on, 2)[:, None] + np.arange(3)).reshape(-1)
    s_rows = np.repeat(n_reproj + np.arange(n_smooth), 3)
    s_cols = (3 * np.repeat(s_idx, 3, axis=0) + np.tile(np.arange(3), len(st))[:, None])
    b_rows = np.repeat(n_reproj + n_smooth + np.arange(n_bone), 6)
    b_cols = np.concatenate([3 * ba[:, None] + np.arange(3), 3 * bo[:, None] + np.arange(3)],
                            -1).reshape(-1)
    rows = np.concatenate([r_rows, s_rows, b_rows])
    cols = np.concatenate([r_cols, s_cols.reshape(-1), b_cols])
    s_data = np.repeat(coef, 3, axis=0).reshape(-1)

    def project(P):
        out = np.empty((len(on), 2))
        for v, sel in enumerate(by_view):
            if len(sel):
                out[sel] = project_views(rigs[v], P[sel])[0]
        return out

    def residuals(x):
        Xv = x.reshape(N, 3)
        r_rep = ((project(Xv[on]) - uv) * ow[:, None]).reshape(-1)
        acc = (coef[:, :, None] * Xv[s_idx]).sum(1)                       # (S, 3)
        r_bone = (np.linalg.norm(Xv[ba] - Xv[bo], axis=-1) - bl) / bone_sd
        return np.concatenate([r_rep, acc.reshape(-1), r_bone])

    def jacobian(x):
        Xv = x.reshape(N, 3)
        P = Xv[on]
        J = np.empty((len(on), 2, 3))
        for k in range(3):
            h = np.zeros(3)
            h[k] = step
            J[:, :, k] = (project(P + h) - project(P - h)) / (2 * step)
        r_data = (J * ow[:, None, None]).reshape(-1)
        d = Xv[ba] - Xv[bo]
        u = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12) / bone_sd
        b_data = np.concatenate([u, -u], -1).reshape(-1)
        data = np.concatenate([r_data, s_data, b_data])
        return csr_matrix((data, (rows, cols)), shape=(m, 3 * N))

    def loss(z):
        out = _robust('linear', z)
        out[:, :n_reproj] = _robust(config.loss, z[:n_reproj])
        return out
    return SimpleNamespace(residuals=residuals, jacobian=jacobian, loss=loss,
                           x0=X0[keep].reshape(-1), keep=keep, N=N, n_reproj=n_reproj,
                           obs=(ot, ov, oc), shape=(T, C))


def optimise(X0, keep, points2d, score, cameras, stamps_ns, edges, lengths, config,
             progress=False):
    """OptimResult.

    X0 (T, C, 3) start (the cameras' length unit, Camera.units; finite where keep); keep
    (T, C) bool: the joints/frames to solve for (observed or bridged); points2d
    (T, V, C, 2) detections in source px (NaN = missing); score (T, V, C); cameras: V
    Camera; stamps_ns (T,) increasing; edges (B, 2) keypoint index pairs; lengths (B,)
    in rig units (NaN: bone left out); config: temporal.FilterConfig (reprojection_px,
    loss, acceleration_m_s2 and bone_mm: m/s^2 and mm whatever the rig's unit,
    confidence_threshold, max_iterations); progress: a tqdm bar of the iterations on
    stderr."""
    import sys

    from tqdm import tqdm
    problem = build_problem(X0, keep, points2d, score, cameras, stamps_ns, edges, lengths,
                            config)
    T, C = np.shape(keep)
    if problem is None:
        return OptimResult(np.full((T, C, 3), np.nan), np.zeros((T, C)), 0.0, 0, 0)
    residuals, keep, N, n_reproj = (problem.residuals, problem.keep, problem.N,
                                    problem.n_reproj)
    ot, ov, oc = problem.obs
    score = np.asarray(score, np.float64)
    bar = tqdm(total=config.max_iterations, desc='filter optim', unit='iteration',
               disable=not progress, file=sys.stderr)

    def jacobian(x):
        bar.update()
        return problem.jacobian(x)
    with bar:
        solution = least_squares(residuals, problem.x0, jac=jacobian, loss=problem.loss,
                                 method='trf', tr_solver='lsmr', x_scale='jac',
                                 max_nfev=config.max_iterations, ftol=1e-6, xtol=1e-8)
    X = np.full((T, C, 3), np.nan)
    X[keep] = solution.x.reshape(N, 3)
    # support: score x robust weight of each view, averaged over a joint's views
    r = residuals(solution.x)[:n_reproj].reshape(-1, 2)
    weight = _robust(config.loss, (r ** 2))[1].mean(-1) * score[ot, ov, oc]
    total = np.zeros((T, C))
    count = np.zeros((T, C))
    np.add.at(total, (ot, oc), weight)
    np.add.at(count, (ot, oc), 1)
    support = np.where(count > 0, total / np.maximum(count, 1), 0.0)
    return OptimResult(X=X, support=support, cost=float(solution.cost),
                       iterations=int(solution.nfev), status=int(solution.status))
