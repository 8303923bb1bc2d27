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

from monet_ros.config import ConfigError

V0 = 2.0     # m/s: velocity standard deviation of a joint when it (re)starts (callers
             # pass it in rig units: geometry.units.from_m(V0, units))


def predict(p, v, P, dt, q):
    """(p, P) after dt seconds: p (J, 3) m + v (J, 3) m/s dt; P (3, J) with the process
    noise q dt^4/4, q dt^3/2, q dt^2 added. New arrays; v is unchanged by the model.
    q scalar or (J,); (J,) may be any shape ((T, C) joints of T tracks: p, v (T, C, 3),
    P (3, T, C), q broadcast against (T, C))."""
    new = np.empty(np.shape(P))                  # (cheaper than stacking three arrays)
    new[0] = P[0] + 2 * dt * P[1] + dt * dt * P[2] + q * dt ** 4 / 4
    new[1] = P[1] + dt * P[2] + q * dt ** 3 / 2
    new[2] = P[2] + q * dt * dt
    return p + v * dt, new


def innovation(p, P, X, r2, measured=None):
    """(y (J, 3) m: X - p, 0 where X is not finite; S (J,) m^2: innovation variance per
    axis P00 + r2; d2 (J,): squared Mahalanobis distance |y|^2 / S; measured (J,) bool: X
    finite). X (J, 3) measurements (m, NaN = none); r2 scalar or (J,); measured: the
    caller's np.isfinite(X).all(axis=1) when at hand (None: computed)."""
    if measured is None:
        measured = np.isfinite(X).all(axis=1)
    with np.errstate(invalid='ignore'):  # inf - inf where X is missing: replaced by 0
        y = np.where(measured[:, None], X - p, 0.0)
    S = P[0] + r2
    return y, S, (y * y).sum(axis=1) / S, measured


def update(p, v, P, y, S, accept):
    """(p, v, P) after the Kalman update with innovation y (J, 3) and variance S (J,) at the
    joints `accept` (J,) bool; the others unchanged. New arrays."""
    k0, k1 = np.where(accept, P[:2] / S, 0.0)                   # the gains, 0 elsewhere
    new = np.empty_like(P)
    np.multiply(1 - k0, P[:2], out=new[:2])
    np.subtract(P[2], k1 * P[1], out=new[2])
    return p + k0[:, None] * y, v + k1[:, None] * y, new


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


def model_numbers(config, units, noise, acceleration, gate, step, v0):
    """(r2 units^2, q (units/s^2)^2, gate2) of a filter config in a rig's length unit `units`
    ('m', 'cm', 'mm'), checked against what the step computes from them: r2 and gate2
    finite and > 0, q finite, and a joint's covariance (started as `start` does) predicted
    over `step` and its innovation variance finite.

    noise, acceleration: (field, value) pairs: the config's field (mm, m/s^2 whatever the
    rig's unit) and its value converted into `units` by the caller (units, units/s^2;
    geometry.units), so that the numbers checked are those the filter uses; gate (sigmas)
    and step (s: the longest step the filter predicts over): field names; v0: the velocity
    prior of a (re)started joint (units/s, from_m(V0, units)). Raises ConfigError naming the
    field (e.g. a noise of 1e200 mm: its square overflows in any unit; 1e155 mm overflows
    in a mm rig only; 1e-200 mm underflows to 0)."""
    owner = type(config).__name__
    (noise, noise_units), (acceleration, acceleration_units) = noise, acceleration
    values = {name: getattr(config, name) for name in (noise, acceleration, gate, step)}
    with np.errstate(all='ignore'):
        r2 = np.float64(noise_units) ** 2
        q = np.float64(acceleration_units) ** 2
        gate2 = np.float64(values[gate]) ** 2
        v02 = np.float64(v0) ** 2
    for name, value, what, unit in (
            (noise, r2, 'measurement variance', f'{units}^2'),
            (acceleration, q, 'process noise variance', f'({units}/s^2)^2'),
            (gate, gate2, 'squared gate', '')):
        positive = name != acceleration
        if not np.isfinite(value) or (positive and not value > 0):
            raise ConfigError(owner, name, f'{values[name]!r} gives a {what} of '
                              f'{float(value)!r} {unit}'.rstrip() + ' (must be finite'
                              f'{" and > 0" if positive else ""})')
    dt = np.float64(values[step])
    with np.errstate(all='ignore'):
        twice = 2 * r2
        _, P = predict(np.zeros((1, 3)), np.zeros((1, 3)), np.array([[r2], [0.0], [v02]]),
                       dt, q)
        long_step = not np.isfinite(dt ** 4 * 2 * v02)
        innovation = P[0] + r2
    if not (np.isfinite(P).all() and np.isfinite(innovation).all()):
        if not np.isfinite(twice):       # the innovation variance of a fresh joint alone
            raise ConfigError(owner, noise, f'{values[noise]!r} gives a measurement variance '
                              f'of {float(r2)!r} {units}^2 whose innovation variance (twice '
                              'it) is not finite (lower it)')
        name = step if long_step else acceleration
        raise ConfigError(owner, name, f'{acceleration} {values[acceleration]!r} m/s^2 over a '
                          f'step of {step} {values[step]!r} s gives a non-finite covariance '
                          f'in {units} (lower one of them)')
    return float(r2), float(q), float(gate2)
