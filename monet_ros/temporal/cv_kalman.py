"""The constant-velocity Kalman step shared by the live filter (temporal.live) and the
offline smoother's forward pass (temporal.kalman): predict, gate, update and start, over
all joints at once (numpy over (J,) arrays, no loop; no ROS).

Model (Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to Tracking and
Navigation", 2001, sec. 6.3.2, the discretised white-noise-acceleration model): per joint
and axis a state (position p, velocity v); p' = p + v dt, v' = v + a dt with white
acceleration a of variance q ((m/s^2)^2); a measurement is the triangulated point with
isotropic noise variance r2 (m^2). The three axes share one 2x2 covariance per joint, kept
as its three entries P = (P00, P01, P11), shape (3, J) (m^2, m^2/s, m^2/s^2).
Lengths are in the rig's unit (m above; callers convert their settings, geometry.units).
"""
import numpy as np

V0 = 2.0     # m/s: velocity standard deviation of a joint when it (re)starts (callers
             # pass it in rig units: geometry.units.from_m(V0, units))


def predict(p, v, P, dt, q):
    """(p, P) after dt seconds: p (J, 3) m + v (J, 3) m/s dt; P (3, J) with the process
    noise q dt^4/4, q dt^3/2, q dt^2 added. New arrays; v is unchanged by the model."""
    P00 = P[0] + 2 * dt * P[1] + dt * dt * P[2] + q * dt ** 4 / 4
    P01 = P[1] + dt * P[2] + q * dt ** 3 / 2
    P11 = P[2] + q * dt * dt
    return p + v * dt, np.stack([P00, P01, P11])


def innovation(p, P, X, r2):
    """(y (J, 3) m: X - p, 0 where X is not finite; S (J,) m^2: innovation variance per
    axis P00 + r2; d2 (J,): squared Mahalanobis distance |y|^2 / S; measured (J,) bool: X
    finite). X (J, 3) measurements (m, NaN = none); r2 scalar or (J,)."""
    measured = np.isfinite(X).all(axis=1)
    y = np.where(measured[:, None], X, 0.0) - np.where(measured[:, None], p, 0.0)
    S = P[0] + r2
    return y, S, (y * y).sum(axis=1) / S, measured


def update(p, v, P, y, S, accept):
    """(p, v, P) after the Kalman update with innovation y (J, 3) and variance S (J,) at the
    joints `accept` (J,) bool; the others unchanged. New arrays."""
    k0 = np.where(accept, P[0] / S, 0.0)
    k1 = np.where(accept, P[1] / S, 0.0)
    P = np.stack([(1 - k0) * P[0], (1 - k0) * P[1], P[2] - k1 * P[1]])
    return p + k0[:, None] * y, v + k1[:, None] * y, P


def start(p, v, P, X, which, r2, v0=V0):
    """Start the joints `which` (J,) bool at their measurement X (J, 3): p = X, v = 0,
    P = (r2, 0, v0^2) (measurement noise; a wide but bounded velocity prior, rig units/s,
    V0 m/s by default). In place; r2 scalar or (J,)."""
    p[which], v[which] = X[which], 0.0
    P[0, which] = np.broadcast_to(r2, which.shape)[which]
    P[1, which], P[2, which] = 0.0, v0 ** 2


def as_matrices(P):
    """(..., 3, J) entries -> (..., J, 2, 2) symmetric covariance matrices."""
    P = np.asarray(P)
    row0 = np.stack([P[..., 0, :], P[..., 1, :]], axis=-1)
    row1 = np.stack([P[..., 1, :], P[..., 2, :]], axis=-1)
    return np.stack([row0, row1], axis=-2)
