"""Causal per-joint filter of live 3D keypoints (the fusion node's `filter`).

A constant-velocity Kalman filter per joint (state: position and velocity per axis; the
discrete white-noise-acceleration model of Bar-Shalom, Li & Kirubarajan, "Estimation
with Applications to Tracking and Navigation", 2001, sec. 6.3.3), with Mahalanobis
gating of each measurement. Chosen over the One-Euro filter (Casiez et al., CHI 2012)
because it (1) gates: a joint triangulated far off in one frame (a wrong view kept as an
inlier, the other leg) is rejected by its innovation's Mahalanobis distance instead of
dragging the output, which One-Euro cannot tell from fast motion; (2) takes the real time
step of each frame's stamp (dropped or late frames, variable rates) in its model; (3) is
set in physical units (measurement noise in mm, acceleration in m/s^2) and bridges a
short gap by prediction. The estimate is at the frame's own stamp: no frames of delay; the
price is lag while a joint accelerates (the constant-velocity model is caught up by the
update; bench/live_filter.py measures it on synthetic trajectories).

The axes are independent with the same noise, so each joint keeps one 2x2 covariance
shared by x, y, z; all joints are updated at once (numpy over (J,) arrays, no loop).
State resets: all joints when the stamp goes backwards or jumps more than filter_reset_s
(a replay loop, a paused recording); one joint when it has had no accepted measurement
for filter_max_gap_s (it is then NaN until measured again, and restarts from that
measurement) or when LOST_AFTER measurements in a row were gated (it lost track: a single
outlier is rejected; a real jump is followed from the second measurement, below).
A NaN (not triangulated) joint is a missing measurement: predicted, never written into
the state.
Velocity guards (an outlier right after a restart, or after a missed frame when the
gate is wide, would otherwise pass and throw the velocity off): a (re)started joint is
tentative until a second measurement agrees with its first, i.e. lies within
filter_max_speed x the time between them + filter_gate x sqrt(2) x filter_noise_mm of it;
right after a miss (no accepted measurement in the previous frame) a measurement whose
update would make the joint faster than filter_max_speed is gated; a gated measurement
is kept as a candidate, and when the next one agrees with it (a real jump, or a fresh
joint whose first measurement was the outlier) the joint restarts from the pair
(velocity by differencing, with its two-point covariance r2, r2/dt, 2 r2/dt^2).
The predict / gate / update step is temporal.cv_kalman, shared with the offline smoother.
"""
from dataclasses import dataclass

import numpy as np

from monet_ros.config import ConfigError, setting, validate_config
from monet_ros.geometry.units import from_m, from_mm
from monet_ros.temporal import cv_kalman

# Consecutive gated measurements (that do not agree with each other: two that agree
# restart the joint at once) after which a joint has lost track: it restarts from the
# measurement.
LOST_AFTER = 3


@dataclass(frozen=True)
class LiveFilterConfig:
    """Settings of the live filter (mirrored as fusion node parameters)."""
    filter: bool = setting(False, 'causal per-joint constant-velocity Kalman filter: '
                           'filtered keypoints on keypoints3d, the raw ones on '
                           'keypoints3d_raw (subjects >= 2: one filter per identity)')
    # defaults from the sweep of bench/live_filter.py (a walking synthetic subject at 30 Hz,
    # 20 mm noise, 3% outliers of 0.3 m): 10 m/s^2 smooths the walk best (p90 40 mm, raw
    # 53) but loses a 2 Hz 0.2 m wave (peak 32 m/s^2: 60 mm RMS, raw 20); 25 m/s^2 follows
    # it (lag ~3 ms) and still cuts the walk's p90 to 45 mm, p99 309 -> 72 mm
    filter_noise_mm: float = setting(
        20.0, 'filter: measurement noise of a triangulated joint (mm, 1 sigma per axis)',
        minimum=0.0, exclusive_minimum=True)
    filter_acceleration: float = setting(
        25.0, 'filter: process noise, white acceleration of a joint (m/s^2, 1 sigma per '
        'axis); larger follows fast moves with less lag, smaller smooths more',
        minimum=0.0, exclusive_minimum=True)
    filter_gate: float = setting(
        4.0, 'filter: Mahalanobis distance (sigmas) beyond which a measurement is an '
        'outlier and the prediction is kept', minimum=0.0, exclusive_minimum=True)
    filter_max_gap_s: float = setting(
        0.25, 'filter: a joint without an accepted measurement this long restarts (NaN '
        'until measured again); shorter gaps are bridged by prediction',
        minimum=0.0, exclusive_minimum=True)
    filter_reset_s: float = setting(
        1.0, 'filter: a stamp going backwards or jumping more than this resets every joint '
        '(a replay loop)', minimum=0.0, exclusive_minimum=True)
    # default from bench/live_filter.py's walk (joints up to 3.4 m/s): 4 m/s cuts the max
    # error 676 -> 429 mm (raw 359), p99 72 -> 71; 3 m/s p99 77, 5+ m/s max 540-820 mm.
    # At 30 Hz two measurements agree within 4 m/s x 33 ms + 4 x sqrt(2) x 20 mm = 246 mm
    filter_max_speed: float = setting(
        4.0, 'filter: fastest a joint moves (m/s): after a missed frame a measurement that '
        'would make it faster is gated; after a restart the second measurement must lie '
        'within this speed (plus the noise margin) of the first; two gated ones that agree '
        'restart the joint',
        minimum=0.0, exclusive_minimum=True)

    def __post_init__(self):
        validate_config(self)


def filter_numbers(config, units, noise, acceleration, max_speed, v0):
    """(r2 units^2, q (units/s^2)^2, gate2) of a LiveFilterConfig in a rig's length unit
    `units`, from its settings converted into that unit by LiveFilter (noise units,
    acceleration units/s^2, max_speed units/s, v0 units/s), checked against what the
    filter computes from them: the variances and the gate squared are finite and > 0 (r2,
    gate2), and a joint's covariance predicted over the longest step the filter takes
    (filter_reset_s), its innovation variance, the reach of filter_max_speed over the
    oldest candidate's age (LOST_AFTER + 1 steps or filter_max_gap_s) and the covariance
    of a restart from two measurements 1 ns apart are finite. Raises ConfigError naming
    the field otherwise (e.g. filter_noise_mm 1e200: its square overflows; 1e-200: it
    underflows to 0; 1e155 overflows in a mm rig only)."""
    owner = type(config).__name__
    r2, q, gate2 = cv_kalman.model_numbers(config, units, ('filter_noise_mm', noise),
                                           ('filter_acceleration', acceleration),
                                           'filter_gate', 'filter_reset_s', v0)
    step = np.float64(config.filter_reset_s)
    with np.errstate(all='ignore'):
        # a candidate is at most LOST_AFTER frames old, or filter_max_gap_s
        horizon = (LOST_AFTER + 1) * max(step, np.float64(config.filter_max_gap_s))
        reach = np.float64(max_speed) * horizon + config.filter_gate * np.sqrt(2 * r2)
        pair = 2 * r2 / 1e-9 ** 2
    if not np.isfinite(reach):
        name = 'filter_max_speed' if np.isfinite(horizon) else \
            'filter_max_gap_s' if config.filter_max_gap_s > step else 'filter_reset_s'
        raise ConfigError(owner, name, f'filter_max_speed {config.filter_max_speed!r} m/s '
                          f'over {LOST_AFTER + 1} x max(filter_reset_s {float(step)!r} s, '
                          f'filter_max_gap_s {config.filter_max_gap_s!r} s) gives a '
                          f'non-finite reach in {units} (lower one of them)')
    if not np.isfinite(pair):
        raise ConfigError(owner, 'filter_noise_mm', f'{config.filter_noise_mm!r} mm gives a '
                          f'non-finite restart covariance in {units}')
    return float(r2), float(q), float(gate2)


class LiveFilter:
    """Per-joint constant-velocity Kalman filter with gating (see the module docstring).

    update(stamp_ns, X) with X (J, 3) in `units` (the rig's length unit 'm', 'cm' or 'mm';
    NaN = not triangulated) -> (filtered (J, 3), measured (J,) bool: an accepted
    measurement this frame; False where the output is a prediction or NaN). The settings
    keep their units (filter_noise_mm mm, filter_acceleration m/s^2, filter_max_speed m/s)
    whatever the rig's: converted here, once, and checked in the rig unit
    (filter_numbers). Counters: resets (time jumps), restarts (joints restarted after a
    gap, LOST_AFTER gated measurements or from a pair), gated (measurements rejected as
    outliers), frames. Raises ConfigError naming the field when the config's numbers
    cannot be used in `units`, ValueError for an unknown unit.
    """

    def __init__(self, config=LiveFilterConfig(), units='m'):
        self.config = config
        self.units = units
        self.max_speed = from_m(config.filter_max_speed, units)
        self.v0 = from_m(cv_kalman.V0, units)
        self.r2, self.q, self.gate2 = filter_numbers(
            config, units, from_mm(config.filter_noise_mm, units),
            from_m(config.filter_acceleration, units), self.max_speed, self.v0)
        self.joints = None
        self.last_ns = None
        self.resets = self.restarts = self.gated = self.frames = 0

    def reset(self, joints):
        """Forget every joint (the next measurement of each starts it again)."""
        self.joints = joints
        self.p = np.zeros((joints, 3))            # position (rig units)
        self.v = np.zeros((joints, 3))            # velocity (rig units/s)
        self.P = np.zeros((3, joints))            # covariance P00, P01, P11 per joint
        self.live = np.zeros(joints, bool)        # started
        self.fresh = np.zeros(joints, bool)       # started from one measurement only
        self.candidate = np.full((joints, 3), np.nan)   # the last one, when gated
        self.candidate_ns = np.zeros(joints, np.int64)
        self.seen_ns = np.zeros(joints, np.int64)  # stamp of the last accepted measurement
        self.gated_run = np.zeros(joints, np.int64)  # consecutive gated measurements
        self.missed = np.zeros(joints, bool)      # no accepted measurement last frame

    def within_reach(self, X, origin, origin_ns, stamp_ns):
        """(J,) bool: X within filter_max_speed x the elapsed time + gate x sqrt(2 r2) of
        origin (J, 3) measured at origin_ns (J,) (False where either is NaN)."""
        reach = self.max_speed * ((stamp_ns - origin_ns) * 1e-9) \
            + self.config.filter_gate * np.sqrt(2 * self.r2)
        with np.errstate(invalid='ignore'):
            return np.linalg.norm(X - origin, axis=1) <= reach

    def update(self, stamp_ns, X):
        X = np.asarray(X, np.float64)
        if X.ndim != 2 or X.shape[1] != 3:
            raise ValueError(f'LiveFilter.update: X must be (J, 3), got {X.shape}')
        stamp_ns = int(stamp_ns)
        self.frames += 1
        dt = 0.0 if self.last_ns is None else (stamp_ns - self.last_ns) * 1e-9
        if self.joints != len(X) or self.last_ns is None or dt < 0 \
                or dt > self.config.filter_reset_s:
            if self.last_ns is not None:
                self.resets += 1
            self.reset(len(X))
            dt = 0.0
        self.last_ns = stamp_ns
        live = self.live
        self.p, P = cv_kalman.predict(self.p, self.v, self.P, dt, self.q)
        y, S, d2, z = cv_kalman.innovation(self.p, P, X, self.r2)
        # a fresh joint's position is its first measurement (nothing accepted since)
        agrees = ~self.fresh | self.within_reach(X, self.p, self.seen_ns, stamp_ns)
        # after a miss the gate is wide enough for an outlier that would throw the velocity
        # off: there the update may not make the joint faster than filter_max_speed
        speed = np.linalg.norm(self.v + (P[1] / S)[:, None] * y, axis=1)
        accept = live & z & (d2 <= self.gate2) & agrees \
            & ((speed <= self.max_speed) | ~self.missed)
        # gated twice in a row by two measurements that agree with each other: the joint
        # is elsewhere (or a fresh joint's first measurement was the outlier): restart
        # from the pair
        pair = live & z & ~accept & self.within_reach(X, self.candidate, self.candidate_ns,
                                                      stamp_ns)
        gated = live & z & ~accept & ~pair
        self.gated += int(gated.sum())
        self.gated_run = np.where(gated, self.gated_run + 1, 0)
        self.p, self.v, self.P = cv_kalman.update(self.p, self.v, P, y, S, accept)
        P = self.P
        self.seen_ns[accept] = stamp_ns
        self.fresh &= ~accept
        if pair.any():
            gap = (stamp_ns - self.candidate_ns[pair]) * 1e-9
            self.p[pair] = X[pair]
            self.v[pair] = (X[pair] - self.candidate[pair]) / gap[:, None]
            P[0, pair], P[1, pair], P[2, pair] = self.r2, self.r2 / gap, 2 * self.r2 / gap ** 2
            self.seen_ns[pair] = stamp_ns
            self.fresh[pair] = False
            self.restarts += int(pair.sum())
        # the candidate is the last measurement if it was gated
        self.candidate[gated], self.candidate_ns[gated] = X[gated], stamp_ns
        self.candidate[live & z & ~gated] = np.nan
        # restart the joints silent for max_gap_s; start the new ones from the measurement
        silent = (stamp_ns - self.seen_ns) * 1e-9 > self.config.filter_max_gap_s
        stale = live & ~accept & ~pair & (silent | (self.gated_run >= LOST_AFTER))
        self.restarts += int(stale.sum())
        live &= ~stale
        start = z & ~live
        cv_kalman.start(self.p, self.v, P, X, start, self.r2, self.v0)
        self.seen_ns[start] = stamp_ns
        self.gated_run[start] = 0
        self.fresh |= start
        self.candidate[start] = np.nan
        live |= start
        out = np.where(live[:, None], self.p, np.nan)
        self.missed = ~(accept | start | pair)
        return out, accept | start | pair


class SubjectFilters:
    """One LiveFilter per subject identity: the live filter with several subjects (the
    fusion node's `filter` with subjects >= 2).

    update(stamp_ns, ids, X, alive=None) -> (filtered (K, C, 3), measured (K, C) bool):
    ids (K,) distinct int identities (the identity tracker's, subjects.tracking), X
    (K, C, 3) their keypoints in `units` (NaN = not triangulated). Each identity's joints
    go through its own LiveFilter (same config and unit), created the first time the
    identity is given (its birth: the state starts from that frame) and dropped once the
    identity is not in `alive` (the identities the tracker still holds after this frame,
    missed ones included; None = keep every filter): its death. An identity missed for
    some frames keeps its filter, which predicts across the gap (its own filter_max_gap_s
    and filter_reset_s apply). No state is shared or moved between identities, and the
    order of ids in a frame does not matter. clear() drops every filter (the identities
    restart, e.g. the tracker was replaced after time went back: identity 0 is then
    another subject). Counters, over the filters alive and dropped: resets, restarts,
    gated, frames (LiveFilter's, summed), births, deaths. Raises ConfigError as
    LiveFilter (checked here, at construction), ValueError for bad shapes or repeated
    ids."""

    def __init__(self, config=LiveFilterConfig(), units='m'):
        LiveFilter(config, units)             # the config's numbers, checked in this unit
        self.config = config
        self.units = units
        self.filters = {}                     # identity -> LiveFilter
        self.dropped = dict(resets=0, restarts=0, gated=0, frames=0)
        self.births = self.deaths = 0

    def total(self, name):
        """Counter `name` (resets, restarts, gated, frames) over the filters alive and
        dropped."""
        return self.dropped[name] + sum(getattr(f, name) for f in self.filters.values())

    resets = property(lambda self: self.total('resets'))
    restarts = property(lambda self: self.total('restarts'))
    gated = property(lambda self: self.total('gated'))
    frames = property(lambda self: self.total('frames'))

    def identities(self):
        """The identities that hold a filter, increasing."""
        return sorted(self.filters)

    def update(self, stamp_ns, ids, X, alive=None):
        ids = np.asarray(ids, np.int64).reshape(-1)
        X = np.asarray(X, np.float64)
        if X.ndim != 3 or X.shape[0] != len(ids) or X.shape[2] != 3:
            raise ValueError(f'SubjectFilters.update: X must be (K={len(ids)}, C, 3), got '
                             f'{X.shape}')
        if len(np.unique(ids)) != len(ids):
            raise ValueError(f'SubjectFilters.update: repeated identities {ids.tolist()}')
        out = np.full(X.shape, np.nan)
        measured = np.zeros(X.shape[:2], bool)
        for k, ident in enumerate(ids.tolist()):
            live = self.filters.get(ident)
            if live is None:
                live = self.filters[ident] = LiveFilter(self.config, self.units)
                self.births += 1
            out[k], measured[k] = live.update(stamp_ns, X[k])
        if alive is not None:
            keep = set(np.asarray(alive, np.int64).reshape(-1).tolist())
            for ident in [i for i in self.filters if i not in keep]:
                self.drop(ident)
        return out, measured

    def drop(self, ident):
        """Forget identity `ident`'s filter (its counters are kept in the totals)."""
        live = self.filters.pop(ident)
        for key in self.dropped:
            self.dropped[key] += getattr(live, key)
        self.deaths += 1

    def clear(self):
        """Drop every filter (the identities start again)."""
        for ident in list(self.filters):
            self.drop(ident)
