"""Identities of subjects over time (no ROS): each track is the project's per-joint
constant-velocity Kalman filter (temporal.cv_kalman, the live filter's step) over its
keypoints; each frame's subjects are assigned to the tracks' predictions.

Rule, per frame (stamps increasing):
1. predict every track's joints to the frame's time (cv_kalman.predict);
2. distance(track, subject) = mean over the keypoints finite in both (track joints
   started, subject triangulated) of |predicted - triangulated| (rig units); inf with no
   such keypoint or above gate_mm (converted into the rig's unit, so m and mm rigs gate
   alike);
3. the assignment minimising the total distance (Hungarian, scipy.optimize.
   linear_sum_assignment, Kuhn 1955 / Munkres 1957) among the gated pairs; one track per
   subject and one subject per track, so no identity is held by two subjects at once;
4. matched tracks are updated (cv_kalman.update; a joint seen for the first time is
   started, cv_kalman.start);
5. birth: a subject left unmatched with >= min_keypoints triangulated keypoints starts a
   new track with a new identity (identities count up from 0 and are never reused);
6. death: a track not matched for longer than max_missed_s is removed; a joint of a
   live track not measured for longer than max_missed_s is unstarted (predicted NaN, left
   out of step 2's distance, started again from its next measurement): its prediction
   would drift on its last velocity, and once measured again its distance could push
   its own subject past the gate.
"""
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from monet_ros.config import setting, validate_config
from monet_ros.geometry.units import check_units, from_m, from_mm
from monet_ros.temporal import cv_kalman


@dataclass(frozen=True)
class TrackerConfig:
    """Settings of the identity tracker (physical units whatever the rig's; validated,
    errors name the field)."""
    gate_mm: float = setting(
        400.0, "tracking: largest mean keypoint distance (mm) between a track's "
        'prediction and a subject for them to be the same', minimum=0.0,
        exclusive_minimum=True)
    max_missed_s: float = setting(
        0.5, 'tracking: a track unmatched for longer than this (s) dies', minimum=0.0)
    min_keypoints: int = setting(
        3, 'tracking: fewest triangulated keypoints of a subject to start a track',
        minimum=1)
    measurement_noise_mm: float = setting(
        15.0, 'tracking: standard deviation of a triangulated keypoint (mm)', minimum=0.0,
        exclusive_minimum=True)
    acceleration_m_s2: float = setting(
        20.0, 'tracking: standard deviation of joint acceleration (m/s^2)', minimum=0.0,
        exclusive_minimum=True)

    def __post_init__(self):
        validate_config(self)


class SubjectTracker:
    """Tracks of subjects with identities (the module docstring's rule).

    step(X (S, C, 3), stamp_ns) -> ids (S,) int: the identity of each subject, -1 for a
    subject neither matched nor born (fewer than min_keypoints keypoints). Counters:
    births, deaths. units: the rig's length unit of X ('m', 'cm', 'mm')."""

    def __init__(self, num_keypoints, config=None, units='m'):
        self.config = config or TrackerConfig()
        self.units = check_units(units)
        self.C = int(num_keypoints)
        c = self.config
        self._gate = from_mm(c.gate_mm, units)
        self._r2 = from_mm(c.measurement_noise_mm, units) ** 2
        self._q = from_m(c.acceleration_m_s2, units) ** 2
        self._v0 = from_m(cv_kalman.V0, units)
        self.ids = np.zeros(0, np.int64)
        self.p = np.zeros((0, self.C, 3))
        self.v = np.zeros((0, self.C, 3))
        self.P = np.zeros((3, 0, self.C))
        self.started = np.zeros((0, self.C), bool)
        self.last_seen = np.zeros(0, np.int64)
        self.joint_seen = np.zeros((0, self.C), np.int64)    # each joint's last measurement
        self.stamp = None
        self.next_id = 0
        self.births = 0
        self.deaths = 0

    def predicted(self, stamp_ns):
        """Predicted joints (tracks, C, 3) at stamp_ns, NaN at joints not started."""
        p, _ = self._predict(stamp_ns)
        return np.where(self.started[..., None], p, np.nan)

    def _predict(self, stamp_ns):
        T = len(self.ids)
        if self.stamp is None or T == 0:
            return self.p.copy(), self.P.copy()
        dt = (int(stamp_ns) - self.stamp) / 1e9
        p, P = cv_kalman.predict(self.p.reshape(-1, 3), self.v.reshape(-1, 3),
                                 self.P.reshape(3, -1), dt, self._q)
        return p.reshape(T, self.C, 3), P.reshape(3, T, self.C)

    def step(self, X, stamp_ns):
        X = np.asarray(X, np.float64).reshape(-1, self.C, 3)
        stamp_ns = int(stamp_ns)
        if self.stamp is not None and stamp_ns <= self.stamp:
            raise ValueError(f'stamps must increase: {stamp_ns} after {self.stamp}')
        S, T = len(X), len(self.ids)
        p, P = self._predict(stamp_ns)
        finite = np.isfinite(X).all(-1)                                  # (S, C)
        out = np.full(S, -1, np.int64)
        matched_t = np.zeros(T, bool)
        if S and T:
            both = self.started[:, None] & finite[None]                 # (T, S, C)
            diff = p[:, None] - np.where(finite[..., None], X, 0.0)[None]
            d = np.sqrt(np.add.reduce(diff * diff, axis=-1))  # np.linalg.norm's numbers
            n = both.sum(-1)
            with np.errstate(invalid='ignore', divide='ignore'):
                dist = np.where(both, d, 0.0).sum(-1) / n
            allowed = (n > 0) & (dist <= self._gate)
            big = 1e6 * (self._gate + 1.0)
            rows, cols = linear_sum_assignment(np.where(allowed, dist, big))
            ok = allowed[rows, cols]
            rows, cols = rows[ok], cols[ok]
            out[cols] = self.ids[rows]
            matched_t[rows] = True
            self._update(p, P, rows, X[cols], finite[cols])
            self.joint_seen[rows] = np.where(finite[cols], stamp_ns, self.joint_seen[rows])
        else:
            self.p, self.P = p, P
        self.last_seen[matched_t] = stamp_ns
        born = (out < 0) & (finite.sum(-1) >= self.config.min_keypoints)
        if born.any():
            out[born] = self._birth(X[born], finite[born], stamp_ns)
        self.started &= (stamp_ns - self.joint_seen) <= self.config.max_missed_s * 1e9
        old = (stamp_ns - self.last_seen) > self.config.max_missed_s * 1e9
        if old.any():
            self.deaths += int(old.sum())
            keep = ~old
            self.ids, self.p, self.v = self.ids[keep], self.p[keep], self.v[keep]
            self.P, self.started = self.P[:, keep], self.started[keep]
            self.last_seen, self.joint_seen = self.last_seen[keep], self.joint_seen[keep]
        self.stamp = stamp_ns
        return out

    def _update(self, p, P, rows, X, finite):
        """Kalman update of the tracks `rows` with their subjects X (k, C, 3) (finite (k, C):
        their triangulated keypoints); p, P: the prediction (new arrays, updated in place)."""
        v = self.v
        pr, vr, Pr = p[rows].reshape(-1, 3), v[rows].reshape(-1, 3), P[:, rows].reshape(3, -1)
        Xr, fr = X.reshape(-1, 3), finite.reshape(-1)
        started = self.started[rows].reshape(-1)
        # innovation's `measured` is `fr`: a keypoint is finite in all 3 coordinates or missing
        y, S, _, measured = cv_kalman.innovation(pr, Pr, Xr, self._r2)
        pr, vr, Pr = cv_kalman.update(pr, vr, Pr, y, S, measured & started)
        new = fr & ~started
        if new.any():  # (after a track's first frames, rarely)
            cv_kalman.start(pr, vr, Pr, Xr, new, self._r2, self._v0)
        p[rows], P[:, rows] = pr.reshape(-1, self.C, 3), Pr.reshape(3, -1, self.C)
        v = v.copy()
        v[rows] = vr.reshape(-1, self.C, 3)
        self.p, self.v, self.P = p, v, P
        self.started[rows] |= finite

    def _birth(self, X, finite, stamp_ns):
        k = len(X)
        ids = np.arange(self.next_id, self.next_id + k)
        self.next_id += k
        self.births += k
        p, v = np.zeros((k * self.C, 3)), np.zeros((k * self.C, 3))
        P = np.zeros((3, k * self.C))
        cv_kalman.start(p, v, P, X.reshape(-1, 3), finite.reshape(-1), self._r2, self._v0)
        self.ids = np.concatenate([self.ids, ids])
        self.p = np.concatenate([self.p, p.reshape(k, self.C, 3)])
        self.v = np.concatenate([self.v, v.reshape(k, self.C, 3)])
        self.P = np.concatenate([self.P, P.reshape(3, k, self.C)], axis=1)
        self.started = np.concatenate([self.started, finite])
        self.last_seen = np.concatenate([self.last_seen, np.full(k, stamp_ns)])
        self.joint_seen = np.concatenate([self.joint_seen, np.full((k, self.C), stamp_ns)])
        return ids
