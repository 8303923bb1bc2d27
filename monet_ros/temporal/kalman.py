"""Per-joint constant-velocity Kalman filter with Mahalanobis gating and a
Rauch-Tung-Striebel (RTS) smoother over a whole recording (no ROS).

Model (Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to Tracking and
Navigation", 2001, sec. 6.3.2, discretised white-noise acceleration): per joint and axis
state (p, v), p' = p + v dt, v' = v + a dt with white acceleration a of standard deviation
`acceleration_m_s2`; a measurement is the triangulated point with isotropic noise
`measurement_noise_mm`. The three axes share one 2x2 covariance per joint (isotropic
noise), so a joint's state is (2, 3) and its covariance (2, 2); the filter is batched
over joints (one Python step per frame, numpy over joints).

Gating: a measurement whose squared Mahalanobis distance |z - p|^2 / S (S the innovation
variance per axis) exceeds gate_sigma^2 is rejected (an outlier: a peak on the wrong limb
triangulated far off). A joint with no accepted measurement for longer than max_gap_s is
re-initialised at its next measurement (so a wrong lock cannot last). The smoother runs
backwards over each stretch between re-initialisations.
"""
from dataclasses import dataclass

import numpy as np

from monet_ros.geometry.units import to_mm
from monet_ros.temporal import cv_kalman
from monet_ros.temporal.gaps import bridgeable, frames_for


@dataclass
class KalmanResult:
    """X (T, C, 3) smoothed positions (the rig's unit), NaN where not bridged; accepted (T, C): a
    measurement was used; rejected (T, C): a measurement was gated out; bridged (T, C):
    no measurement used, filled from its neighbours (gap <= max_gap_s); sd_mm (T, C)
    posterior standard deviation per axis (mm)."""
    X: np.ndarray
    accepted: np.ndarray
    rejected: np.ndarray
    bridged: np.ndarray
    sd_mm: np.ndarray


def kalman_smooth(X, stamps_ns, config, noise_scale=None, units='m'):
    """RTS-smoothed KalmanResult of raw points X (T, C, 3) in `units` (the rig's length
    unit, 'm', 'cm' or 'mm'; NaN = missing) at stamps_ns (T,) increasing. config:
    temporal.FilterConfig (measurement_noise_mm, acceleration_m_s2: mm and m/s^2 whatever
    the units, gate_sigma, max_gap_s); noise_scale (T, C) >= 1 or None: factor on
    the measurement noise of each point (smooth_points gives 1 + (mean reprojection error /
    reprojection_px)^2, so a point triangulated with a stray view counts less). Raises
    ValueError on bad shapes or stamps or an unknown unit, ConfigError naming the setting
    whose number cannot be used in `units` (FilterConfig.in_units)."""
    X = np.asarray(X, np.float64)
    stamps = np.asarray(stamps_ns, np.int64)
    if X.ndim != 3 or X.shape[-1] != 3 or len(stamps) != len(X):
        raise ValueError(f'X must be (T, C, 3) with T = {len(stamps)} stamps, got {X.shape}')
    if len(stamps) > 1 and np.any(np.diff(stamps) <= 0):
        raise ValueError('stamps must increase')
    T, C = X.shape[:2]
    physical = config.in_units(units)      # converted and checked (ConfigError)
    r2, q, gate2 = physical.r2, physical.q, physical.gate2
    scale2 = np.ones((T, C)) if noise_scale is None else \
        np.nan_to_num(np.asarray(noise_scale, np.float64), nan=1.0, posinf=1.0) ** 2
    max_gap = frames_for(config.max_gap_s, stamps)
    dts = np.diff(stamps) / 1e9
    # the forward pass is the live filter's step (temporal.cv_kalman), per-point noise
    p, v, P = np.zeros((C, 3)), np.zeros((C, 3)), np.zeros((3, C))
    init = np.zeros(C, bool)
    unseen = np.zeros(C, np.int64)         # frames since the last accepted measurement
    xf, Pf = np.zeros((T, C, 2, 3)), np.zeros((T, 3, C))
    xp, Pp = np.zeros((T, C, 2, 3)), np.zeros((T, 3, C))
    accepted = np.zeros((T, C), bool)
    rejected = np.zeros((T, C), bool)
    restart = np.zeros((T, C), bool)
    for k in range(T):
        if k:
            p, P = cv_kalman.predict(p, v, P, dts[k - 1], q)
        xp[k, :, 0], xp[k, :, 1], Pp[k] = p, v, P
        rk = r2 * scale2[k]
        y, S, d2, valid = cv_kalman.innovation(p, P, X[k], rk)
        ok = valid & init & (d2 <= gate2)
        new = valid & (~init | (unseen > max_gap)) & ~ok
        p, v, P = cv_kalman.update(p, v, P, y, S, ok)
        cv_kalman.start(p, v, P, X[k], new, rk, physical.v0)
        init |= new
        used = ok | new
        accepted[k], rejected[k], restart[k] = used, valid & ~used, new
        unseen = np.where(used, 0, unseen + 1)
        xf[k, :, 0], xf[k, :, 1], Pf[k] = p, v, P
    Pf, Pp = cv_kalman.as_matrices(Pf), cv_kalman.as_matrices(Pp)     # (T, C, 2, 2)
    seen = np.cumsum(accepted, axis=0) > 0                      # initialised
    xs, Ps = xf.copy(), Pf.copy()
    for k in range(T - 2, -1, -1):
        dt = dts[k]
        F = np.array([[1.0, dt], [0.0, 1.0]])
        chain = seen[k] & ~restart[k + 1]                     # same stretch as k + 1
        # a joint not yet started has only process noise (rank 1): no gain there
        Pp_k = np.where(chain[:, None, None], Pp[k + 1], np.eye(2))
        G = Pf[k] @ F.T @ np.linalg.inv(Pp_k)                  # (C, 2, 2)
        xs_k = xf[k] + G @ (xs[k + 1] - xp[k + 1])
        Ps_k = Pf[k] + G @ (Ps[k + 1] - Pp[k + 1]) @ G.transpose(0, 2, 1)
        xs[k] = np.where(chain[:, None, None], xs_k, xf[k])
        Ps[k] = np.where(chain[:, None, None], Ps_k, Pf[k])
    bridged = bridgeable(accepted, max_gap)
    keep = accepted | bridged
    out = np.where(keep[..., None], xs[:, :, 0], np.nan)
    sd = np.where(keep, to_mm(np.sqrt(np.maximum(Ps[:, :, 0, 0], 0.0)), units), np.nan)
    return KalmanResult(X=out, accepted=accepted, rejected=rejected, bridged=bridged,
                        sd_mm=sd)
