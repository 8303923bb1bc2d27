"""The constant-velocity Kalman step shared by the live filter (temporal.live) and the
offline smoother's forward pass (temporal.kalman): predict, gate, update and start, over
all joints at once (numpy over (J,) arrays, no loop; no ROS).

Model (Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to Tracking and
Navigation", 2001, sec. 6.3.2, the discretised white-noise-acceleration model): per joint
and axis a state (position p, velocity v); p' = p + v dt, v' = v + a dt with white
acceleration a of variance q ((m/s^2)^2); a measurement is the triangulated point with
isotropic noise variance r2 (m^2). The three axes share one 2x2 covariance per joint, kept
as its three entries P = (P00, P01, P11), shape (3, J) (m^2, m^2/s, m^2/s^2).
"""
import numpy as np

from monet_ros.config import ConfigError

V0 = 2.0     # m/s: velocity standard deviation of a joint when it (re)starts


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
    P = (r2, 0, v0^2) (measurement noise; a wide but bounded velocity prior, m/s). In
    place; r2 scalar or (J,)."""
    p[which], v[which] = X[which], 0.0
    P[0, which] = np.broadcast_to(r2, which.shape)[which]
    P[1, which], P[2, which] = 0.0, v0 ** 2


def as_matrices(P):
    """(..., 3, J) entries -> (..., J, 2, 2) symmetric covariance matrices."""
    P = np.asarray(P)
    row0 = np.stack([P[..., 0, :], P[..., 1, :]], axis=-1)
    row1 = np.stack([P[..., 1, :], P[..., 2, :]], axis=-1)
    return np.stack([row0, row1], axis=-2)


def model_numbers(config, noise, acceleration, gate, step):
    """(r2 m^2, q (m/s^2)^2, gate2) of a filter config whose fields are named by `noise`
    (mm), `acceleration` (m/s^2), `gate` (sigmas) and `step` (s: the longest step the
    filter predicts over), checked against what the step computes from them: r2 and gate2
    finite and > 0, q finite, and a joint's covariance (started as `start` does) predicted
    over `step` and its innovation variance finite. Raises ConfigError naming the field
    (e.g. a noise of 1e200 mm: its square overflows; 1e-200 mm: it underflows to 0)."""
    owner = type(config).__name__
    values = {name: getattr(config, name) for name in (noise, acceleration, gate, step)}
    with np.errstate(all='ignore'):
        r2 = np.float64(values[noise] * 1e-3) ** 2
        q = np.float64(values[acceleration]) ** 2
        gate2 = np.float64(values[gate]) ** 2
    for name, value, what, unit in ((noise, r2, 'measurement variance', 'm^2'),
                                    (acceleration, q, 'process noise variance', '(m/s^2)^2'),
                                    (gate, gate2, 'squared gate', '')):
        positive = name != acceleration
        if not np.isfinite(value) or (positive and not value > 0):
            raise ConfigError(owner, name, f'{values[name]!r} gives a {what} of '
                              f'{float(value)!r} {unit}'.rstrip() + ' (must be finite'
                              f'{" and > 0" if positive else ""})')
    dt = np.float64(values[step])
    with np.errstate(all='ignore'):
        _, P = predict(np.zeros((1, 3)), np.zeros((1, 3)), np.array([[r2], [0.0], [V0 ** 2]]),
                       dt, q)
        long_step = not np.isfinite(dt ** 4 * 2 * V0 ** 2)
    if not (np.isfinite(P).all() and np.isfinite(P[0] + r2).all()):
        name = step if long_step else acceleration
        raise ConfigError(owner, name, f'{acceleration} {values[acceleration]!r} m/s^2 over a '
                          f'step of {step} {values[step]!r} s gives a non-finite covariance '
                          '(lower one of them)')
    return float(r2), float(q), float(gate2)
