"""Identities of subjects over time (no ROS): each track keeps two constant-velocity
Kalman filters (temporal.cv_kalman, the live filter's step): one per joint (its prediction
places the next frame's crops: SubjectTracker.predicted) and one of the subject's body,
which alone decides identity; each frame's subjects are assigned to the tracks' bodies.

Why a body filter: a subject's triangulated joints are poor in some frames (two people
passing: a crop decodes part of the neighbour, 250-450 mm off), and the per-joint filter
(15 mm measurement noise, 20 m/s^2) takes such a jump as velocity, so its next
prediction overshoots by about as much again; the mean joint distance to it then crossed
the gate or preferred the neighbour (measured: bench/results/subjects_process.md, change
6). The median displacement of a subject's joints moves with its body, not with one limb
or a few captured joints, and a body does not accelerate at 20 m/s^2.

Rule, per frame (stamps increasing):
1. predict every track's joints and body to the frame's time (cv_kalman.predict; the body
   with body_acceleration_m_s2);
2. body measurement of subject s against track t: the track's body as measured at its
   last match (step 4) plus the median (per axis) over the keypoints finite in both (the
   track's last joints, the subject's triangulated ones) of the subject's joint minus the
   track's (rig units); distance(track, subject) = |body measurement - the track's predicted
   body|; inf with no common keypoint or above the track's gate: gate_mm + max_speed_m_s
   x the time the track has been unmatched (0 for a track matched in the previous frame;
   mm and m/s converted into the rig's unit, so m and mm rigs gate alike): a lost
   subject may have walked off its prediction;
3. the assignment minimising the total distance (Hungarian, scipy.optimize.
   linear_sum_assignment, Kuhn 1955 / Munkres 1957) among the gated pairs; one track per
   subject and one subject per track, so no identity is held by two subjects at once;
4. matched tracks are updated: the joints (cv_kalman.update; a joint seen for the first
   time is started, cv_kalman.start), the body (cv_kalman.update of its measurement with
   body_noise_mm), and the track's last joints and body (the measured joints, the others
   moved with the body measurement; that measurement);
5. birth: a subject left unmatched with >= min_keypoints triangulated keypoints starts a
   new track with a new identity (identities count up from 0 and are never reused;
   its body at the median of its joints), but with max_tracks (the N of `--subjects N`)
   tracks alive (matched or lost, not yet dead) it is left untracked (-1, counted in
   `untracked`): N subjects are all known, so a subject no track takes is a poor
   decode of one of them (a mixture, or one body decoded twice) and a new identity
   would be a switch; its lost track takes it back within step 2's growing gate;
6. death: a track not matched for longer than max_missed_s is removed; a joint of a
   live track not measured for longer than max_missed_s is unstarted (predicted NaN,
   started again from its next measurement): its prediction would drift on its last
   velocity.
"""
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from monet_ros.config import setting, validate_config
from monet_ros.geometry.units import check_units, from_m, from_mm
from monet_ros.jit import kernel
from monet_ros.temporal import cv_kalman


def masked_median(values, mask):
    """Per-axis median of values (..., C, 3) over the entries `mask` (..., C) -> (..., 3);
    NaN where the mask is empty (np.nanmedian's numbers). _displacement_medians against a
    reference of zeros."""
    values = np.asarray(values, np.float64)
    lead, C = values.shape[:-2], values.shape[-2]
    L = int(np.prod(lead))
    med, _ = _displacement_medians(values.reshape(L, C, 3),
                                   np.asarray(mask, np.bool_).reshape(L, C), np.zeros((1, C, 3)))
    return med[0].reshape(lead + (3,))


@kernel(example=lambda: (np.zeros((1, 2, 3)), np.ones((1, 2), bool), np.zeros((1, 2, 3))))
def _displacement_medians(X, finite, ref):
    """(med (T, S, 3), n (T, S)): the per-axis median over the keypoints common to subject
    s and reference t (finite[s, c] and ref[t, c] not NaN) of X[s, c] - ref[t, c], NaN
    where none is common (the mean of the middle two of an even count, as np.nanmedian),
    and how many are common. X (S, C, 3), finite (S, C) bool, ref (T, C, 3) NaN where not
    known. Compiled (monet_ros.jit): an insertion sort per axis (C is a skeleton's
    keypoints: a few dozen)."""
    S, C = finite.shape
    T = ref.shape[0]
    med = np.empty((T, S, 3))
    count = np.zeros((T, S), np.int64)
    buf = np.empty(C)
    for t in range(T):
        for s in range(S):
            for axis in range(3):
                n = 0
                for c in range(C):
                    if finite[s, c] and not np.isnan(ref[t, c, 0]):
                        x = X[s, c, axis] - ref[t, c, axis]
                        i = n
                        while i > 0 and buf[i - 1] > x:
                            buf[i] = buf[i - 1]
                            i -= 1
                        buf[i] = x
                        n += 1
                med[t, s, axis] = 0.5 * (buf[(n - 1) // 2] + buf[n // 2]) if n else np.nan
                count[t, s] = n
    return med, count


@dataclass(frozen=True)
class TrackerConfig:
    """Settings of the identity tracker (physical units whatever the rig's; validated,
    errors name the field)."""
    gate_mm: float = setting(
        400.0, "tracking: largest distance (mm) between a track's predicted body and a "
        "subject's body (the median displacement of its joints) for them to be the same",
        minimum=0.0, exclusive_minimum=True)
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
    body_noise_mm: float = setting(
        50.0, "tracking: standard deviation of a subject's body position (mm; the median "
        "displacement of its joints)", minimum=0.0, exclusive_minimum=True)
    body_acceleration_m_s2: float = setting(
        5.0, "tracking: standard deviation of a subject's body acceleration (m/s^2)",
        minimum=0.0, exclusive_minimum=True)
    max_speed_m_s: float = setting(
        2.0, 'tracking: fastest body speed (m/s): a track unmatched for t s takes a subject '
        'within gate_mm + this x t of its predicted body', minimum=0.0)

    def __post_init__(self):
        validate_config(self)


class SubjectTracker:
    """Tracks of subjects with identities (the module docstring's rule).

    step(X (S, C, 3), stamp_ns) -> ids (S,) int: the identity of each subject, -1 for a
    subject neither matched nor born (fewer than min_keypoints keypoints, or max_tracks
    tracks alive). Counters: births, deaths, untracked (subjects left out by max_tracks).
    units: the rig's length unit of X ('m', 'cm', 'mm'); max_tracks: the most tracks alive
    (None: no limit)."""

    def __init__(self, num_keypoints, config=None, units='m', max_tracks=None):
        self.config = config or TrackerConfig()
        self.max_tracks = max_tracks
        self.untracked = 0
        self.units = check_units(units)
        self.C = int(num_keypoints)
        c = self.config
        self._gate = from_mm(c.gate_mm, units)
        self._r2 = from_mm(c.measurement_noise_mm, units) ** 2
        self._q = from_m(c.acceleration_m_s2, units) ** 2
        self._v0 = from_m(cv_kalman.V0, units)
        self._body_r2 = from_mm(c.body_noise_mm, units) ** 2
        self._body_q = from_m(c.body_acceleration_m_s2, units) ** 2
        self._speed = from_m(c.max_speed_m_s, units)
        self.ids = np.zeros(0, np.int64)
        # the body model (module docstring step 2): each track's joints at its last match
        # (ref, NaN: never measured) and its body position measured then (ref_body)
        self.ref = np.zeros((0, self.C, 3))
        self.ref_body = np.zeros((0, 3))
        # the filters, one cv_kalman state of C + 1 rows per track: its C joints and, as
        # row C, its body (one predict and one update for both; per row noise)
        self.p = np.zeros((0, self.C + 1, 3))
        self.v = np.zeros((0, self.C + 1, 3))
        self.P = np.zeros((3, 0, self.C + 1))
        self._q_rows = np.array([self._q] * self.C + [self._body_q])
        self._r2_rows = np.array([self._r2] * self.C + [self._body_r2])
        self._tiled = {}                                       # k -> r2 of k tracks' rows
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
        return np.where(self.started[..., None], p[:, :self.C], np.nan)

    def _predict(self, stamp_ns):
        """The joints' and bodies' prediction (p (T, C + 1, 3), P (3, T, C + 1)): new
        arrays, row C the body."""
        if self.stamp is None or not len(self.ids):
            return self.p.copy(), self.P.copy()
        dt = (int(stamp_ns) - self.stamp) / 1e9
        return cv_kalman.predict(self.p, self.v, self.P, dt, self._q_rows)

    def _r2_tiled(self, k):
        """The measurement variances (k (C + 1),) of k tracks' rows."""
        r2 = self._tiled.get(k)
        if r2 is None:
            r2 = self._tiled[k] = np.tile(self._r2_rows, k)
        return r2

    def body_distance(self, X, stamp_ns):
        """Step 2's numbers: (z (T, S, 3) each subject's body position measured against
        each track's joints, dist (T, S) |z - the track's predicted body| (inf without a
        common joint), n (T, S) common joints) of subjects X (S, C, 3) (rig units) at
        stamp_ns."""
        return self._body_distance(np.asarray(X, np.float64).reshape(-1, self.C, 3),
                                   self._predict(stamp_ns)[0][:, self.C])

    def _body_distance(self, X, b, finite=None):
        """body_distance's numbers; finite (S, C): np.isfinite(X).all(-1) when at hand."""
        if finite is None:
            finite = np.isfinite(X).all(-1)
        # (ref is NaN at the joints never measured, X at those not triangulated)
        med, n = _displacement_medians(X, finite, self.ref)
        z = self.ref_body[:, None] + med
        gap = z - b[:, None]
        with np.errstate(invalid='ignore'):
            dist = np.where(n > 0, np.sqrt((gap * gap).sum(-1)), np.inf)
        return z, dist, n

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
            z, dist, n = self._body_distance(X, p[:, self.C], finite)
            lost_s = (self.stamp - self.last_seen) / 1e9 if self.stamp is not None else 0.0
            gate = self._gate + self._speed * np.asarray(lost_s, np.float64).reshape(-1, 1)
            allowed = (n > 0) & (dist <= gate)
            big = 1e6 * (float(gate.max()) + 1.0)
            rows, cols = linear_sum_assignment(np.where(allowed, dist, big))
            ok = allowed[rows, cols]
            rows, cols = rows[ok], cols[ok]
            out[cols] = self.ids[rows]
            matched_t[rows] = True
            self._update(p, P, rows, X[cols], finite[cols], z[rows, cols])
            self.joint_seen[rows] = np.where(finite[cols], stamp_ns, self.joint_seen[rows])
        else:
            self.p, self.P = p, P
        self.last_seen[matched_t] = stamp_ns
        born = (out < 0) & (finite.sum(-1) >= self.config.min_keypoints)
        if born.any() and self.max_tracks is not None:
            # at most max_tracks identities alive (step 5): a subject beyond is untracked
            dying = (stamp_ns - self.last_seen) > self.config.max_missed_s * 1e9
            alive = T - int(dying.sum())
            free = max(0, self.max_tracks - alive)
            over = np.flatnonzero(born)[free:]
            born[over] = False
            self.untracked += len(over)
        if born.any():
            out[born] = self._birth(X[born], finite[born], stamp_ns)
        self.started &= (stamp_ns - self.joint_seen) <= self.config.max_missed_s * 1e9
        old = (stamp_ns - self.last_seen) > self.config.max_missed_s * 1e9
        if old.any():
            self.deaths += int(old.sum())
            self._remove(~old)
        self.stamp = stamp_ns
        return out

    def _update(self, p, P, rows, X, finite, z):
        """Kalman update of the tracks `rows` with their subjects X (k, C, 3) (finite (k, C):
        their triangulated keypoints) and body measurements z (k, 3); p, P: the prediction
        (new arrays, updated in place). A joint measured for the first time is started
        (cv_kalman.start); the reference joints become the measured ones, the others moved
        with the body."""
        k, C = len(rows), self.C
        Z = np.empty((k, C + 1, 3))
        Z[:, :C], Z[:, C] = X, z
        measured = np.ones((k, C + 1), bool)
        measured[:, :C] = finite
        accept = measured.copy()
        accept[:, :C] &= self.started[rows]
        r2 = self._r2_tiled(k)
        pr, vr, Pr = p[rows].reshape(-1, 3), self.v[rows].reshape(-1, 3), P[:, rows]
        Pr, Zr = Pr.reshape(3, -1), Z.reshape(-1, 3)
        y, S, _, _ = cv_kalman.innovation(pr, Pr, Zr, r2, measured.reshape(-1))
        pr, vr, Pr = cv_kalman.update(pr, vr, Pr, y, S, accept.reshape(-1))
        new = measured & ~accept          # joints measured but not started (the body is)
        if new.any():  # (after a track's first frames, rarely)
            cv_kalman.start(pr, vr, Pr, Zr, new.reshape(-1), r2, self._v0)
        p[rows], P[:, rows] = pr.reshape(k, C + 1, 3), Pr.reshape(3, k, C + 1)
        v = self.v.copy()
        v[rows] = vr.reshape(k, C + 1, 3)
        self.p, self.v, self.P = p, v, P
        self.started[rows] |= finite
        moved = self.ref[rows] + (z - self.ref_body[rows])[:, None]
        ref = self.ref.copy()
        ref[rows] = np.where(finite[..., None], X, moved)
        self.ref = ref
        ref_body = self.ref_body.copy()
        ref_body[rows] = z
        self.ref_body = ref_body

    # per-track state: the track axis of each array (the covariances keep theirs second)
    _STATE = dict(ids=0, p=0, v=0, P=1, started=0, last_seen=0, joint_seen=0, ref=0,
                  ref_body=0)

    def _fresh(self, X, finite, stamp_ns):
        """The state of tracks started at subjects X (k, C, 3) (finite (k, C)): every
        measured joint started (cv_kalman.start), its body at the median of its joints."""
        k, C = len(X), self.C
        body = masked_median(X, finite)                                         # (k, 3)
        Z = np.concatenate([X, body[:, None]], axis=1)                 # (k, C + 1, 3)
        which = np.concatenate([finite, np.ones((k, 1), bool)], axis=1)
        p, v = np.zeros((k * (C + 1), 3)), np.zeros((k * (C + 1), 3))
        P = np.zeros((3, k * (C + 1)))
        cv_kalman.start(p, v, P, Z.reshape(-1, 3), which.reshape(-1), self._r2_tiled(k),
                        self._v0)
        return dict(p=p.reshape(k, C + 1, 3), v=v.reshape(k, C + 1, 3),
                    P=P.reshape(3, k, C + 1), started=finite.copy(),
                    last_seen=np.full(k, stamp_ns, np.int64),
                    joint_seen=np.full((k, C), stamp_ns, np.int64),
                    ref=np.where(finite[..., None], X, np.nan), ref_body=body)

    def _birth(self, X, finite, stamp_ns):
        k = len(X)
        ids = np.arange(self.next_id, self.next_id + k)
        self.next_id += k
        self.births += k
        fresh = self._fresh(X, finite, stamp_ns)
        fresh['ids'] = ids
        for name, axis in self._STATE.items():
            setattr(self, name, np.concatenate([getattr(self, name), fresh[name]], axis=axis))
        return ids

    def _remove(self, keep):
        for name, axis in self._STATE.items():
            value = getattr(self, name)
            setattr(self, name, value[:, keep] if axis else value[keep])
