"""An articulated subject walking on a curved path: keypoints over time and limb capsules.

Two body models, chosen by the skeleton's keypoint names: a human (the human14 preset's
joints) and a quadruped (quadruped13's). A custom skeleton file works when its keypoints
are a subset of one body's joints (any order: the order of `Skeleton.keypoints` is kept).
World frame 'world', z up, metres; keypoints3d has shape (T, C, 3).

The body frame has x forward, y to the subject's left, z up, origin on the ground below
the pelvis. Motion: a smooth closed-ish path around the origin (circle whose radius
breathes), heading along the path, a gait cycle (legs and arms swing, knees and elbows
flex), slow seeded arm raises, torso twist and head turns. Everything is a smooth function
of time and of values drawn from a seeded generator.
"""
from dataclasses import dataclass

import numpy as np

BODIES = ('auto', 'human', 'quadruped')


class SubjectError(ValueError):
    """The skeleton does not fit a body model, or a subject parameter is invalid."""


@dataclass(frozen=True)
class Capsule:
    """A limb: a capsule from point a to point b (keypoint or helper point names) with
    `radius` metres; `part` picks its material; `attached` are the keypoints it covers
    (a capsule never counts as occluding those)."""

    a: str
    b: str
    radius: float
    part: str
    attached: tuple


HUMAN_JOINTS = ('head', 'neck', 'r_shoulder', 'r_elbow', 'r_wrist', 'l_shoulder', 'l_elbow',
                'l_wrist', 'r_hip', 'r_knee', 'r_ankle', 'l_hip', 'l_knee', 'l_ankle')
QUADRUPED_JOINTS = ('nose', 'neck', 'tail_base', 'lf_shoulder', 'lf_paw', 'rf_shoulder',
                    'rf_paw', 'lh_hip', 'lh_paw', 'rh_hip', 'rh_paw', 'spine_mid', 'tail_tip')

# Left and right limbs use the same part (same material): the symmetric ambiguity is real.
HUMAN_CAPSULES = (
    Capsule('pelvis', 'chest', 0.15, 'torso',
            ('neck', 'r_shoulder', 'l_shoulder', 'r_hip', 'l_hip')),
    Capsule('r_shoulder', 'l_shoulder', 0.065, 'torso', ('r_shoulder', 'l_shoulder', 'neck')),
    Capsule('r_hip', 'l_hip', 0.1, 'hips', ('r_hip', 'l_hip')),
    Capsule('neck', 'head', 0.05, 'skin', ('neck', 'head')),
    Capsule('head', 'head', 0.11, 'head', ('head',)),
    Capsule('r_shoulder', 'r_elbow', 0.05, 'arm', ('r_shoulder', 'r_elbow')),
    Capsule('r_elbow', 'r_wrist', 0.04, 'arm', ('r_elbow', 'r_wrist')),
    Capsule('r_wrist', 'r_hand', 0.045, 'skin', ('r_wrist',)),
    Capsule('l_shoulder', 'l_elbow', 0.05, 'arm', ('l_shoulder', 'l_elbow')),
    Capsule('l_elbow', 'l_wrist', 0.04, 'arm', ('l_elbow', 'l_wrist')),
    Capsule('l_wrist', 'l_hand', 0.045, 'skin', ('l_wrist',)),
    Capsule('r_hip', 'r_knee', 0.075, 'leg', ('r_hip', 'r_knee')),
    Capsule('r_knee', 'r_ankle', 0.055, 'leg', ('r_knee', 'r_ankle')),
    Capsule('r_ankle', 'r_toe', 0.045, 'shoe', ('r_ankle',)),
    Capsule('l_hip', 'l_knee', 0.075, 'leg', ('l_hip', 'l_knee')),
    Capsule('l_knee', 'l_ankle', 0.055, 'leg', ('l_knee', 'l_ankle')),
    Capsule('l_ankle', 'l_toe', 0.045, 'shoe', ('l_ankle',)),
)
QUADRUPED_CAPSULES = (
    Capsule('neck', 'tail_base', 0.12, 'torso',
            ('neck', 'spine_mid', 'tail_base', 'lf_shoulder', 'rf_shoulder', 'lh_hip',
             'rh_hip')),
    Capsule('neck', 'nose', 0.07, 'head', ('neck', 'nose')),
    Capsule('head_top', 'head_top', 0.09, 'head', ('neck',)),
    Capsule('tail_base', 'tail_tip', 0.025, 'tail', ('tail_base', 'tail_tip')),
    Capsule('lf_shoulder', 'lf_paw', 0.04, 'leg', ('lf_shoulder', 'lf_paw')),
    Capsule('rf_shoulder', 'rf_paw', 0.04, 'leg', ('rf_shoulder', 'rf_paw')),
    Capsule('lh_hip', 'lh_paw', 0.045, 'leg', ('lh_hip', 'lh_paw')),
    Capsule('rh_hip', 'rh_paw', 0.045, 'leg', ('rh_hip', 'rh_paw')),
    Capsule('lf_paw', 'lf_paw', 0.045, 'paw', ('lf_paw',)),
    Capsule('rf_paw', 'rf_paw', 0.045, 'paw', ('rf_paw',)),
    Capsule('lh_paw', 'lh_paw', 0.045, 'paw', ('lh_paw',)),
    Capsule('rh_paw', 'rh_paw', 0.045, 'paw', ('rh_paw',)),
)


@dataclass(frozen=True)
class SubjectConfig:
    """body: 'auto' (from the skeleton's names), 'human' or 'quadruped'.
    path_radius: mean radius (m) of the walked path around the origin (None = body
    default). speed: walking speed m/s (None = body default, seeded). scale: body size."""

    body: str = 'auto'
    path_radius: float | None = None
    speed: float | None = None
    scale: float = 1.0

    def __post_init__(self):
        if self.body not in BODIES:
            raise SubjectError(f'subject config: field body must be one of {BODIES}, '
                               f'got {self.body!r}')
        for key in ('path_radius', 'speed'):
            value = getattr(self, key)
            if value is not None and not (np.isfinite(value) and 0 <= value <= 10):
                raise SubjectError(f'subject config: field {key} must be in 0..10, '
                                   f'got {value!r}')
        if not (np.isfinite(self.scale) and 0.05 <= self.scale <= 20):
            raise SubjectError(f'subject config: field scale must be in 0.05..20, '
                               f'got {self.scale!r}')


def body_for_skeleton(skeleton, body='auto'):
    """'human' or 'quadruped' for a Skeleton; SubjectError naming missing keypoints."""
    names = set(skeleton.keypoints)
    joints = {'human': HUMAN_JOINTS, 'quadruped': QUADRUPED_JOINTS}
    if body == 'auto':
        for candidate, known in joints.items():
            if names <= set(known):
                return candidate
        missing = {k: sorted(names - set(v)) for k, v in joints.items()}
        raise SubjectError(f'skeleton {skeleton.name!r}: keypoints fit no body model '
                           f'(unknown to human: {missing["human"]}, to quadruped: '
                           f'{missing["quadruped"]})')
    unknown = sorted(names - set(joints[body]))
    if unknown:
        raise SubjectError(f'skeleton {skeleton.name!r}: keypoints {unknown} are not joints '
                           f'of the {body} body model')
    return body


def _smooth_fn(rng, low_hz, high_hz, terms=3):
    """A smooth seeded signal f(t (T,)) -> (T,) in [-1, 1]: a sum of sinusoids."""
    freq = rng.uniform(low_hz, high_hz, terms)
    phase = rng.uniform(0, 2 * np.pi, terms)
    weight = rng.uniform(0.5, 1.0, terms)

    def signal(t):
        waves = np.sin(2 * np.pi * freq[:, None] * np.asarray(t)[None] + phase[:, None])
        return (weight[:, None] * waves).sum(0) / weight.sum()
    return signal


def _smooth(rng, t, low_hz, high_hz, terms=3):
    """_smooth_fn evaluated at t (T,)."""
    return _smooth_fn(rng, low_hz, high_hz, terms)(t)


def _direction(pitch, abduction, side):
    """(T, 3) unit limb directions in the body frame: `pitch` swings forward (about y),
    `abduction` lifts sideways (side +1 = left, -1 = right); 0, 0 points down."""
    ca = np.cos(abduction)
    return np.stack([np.sin(pitch) * ca, side * np.sin(abduction),
                     -np.cos(pitch) * ca], axis=-1)


def _rot_z(angle):
    """(T, 3, 3) rotations about z."""
    c, s = np.cos(angle), np.sin(angle)
    zero, one = np.zeros_like(angle), np.ones_like(angle)
    return np.stack([np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1),
                     np.stack([zero, zero, one], -1)], axis=-2)


class Subject:
    """The moving subject for a Skeleton (see the module docstring).

    keypoints3d(times) -> (T, C, 3) in `skeleton.keypoints` order; capsule_arrays(times)
    -> (A (T, P, 3), B (T, P, 3)) capsule axis end points; `capsules`, `radii` (P,),
    `parts` (P,) names, `attached` (P, C) bool.
    """

    def __init__(self, skeleton, config=None, seed=0):
        self.skeleton = skeleton
        self.config = config or SubjectConfig()
        self.body = body_for_skeleton(skeleton, self.config.body)
        self.seed = int(seed)
        self.capsules = HUMAN_CAPSULES if self.body == 'human' else QUADRUPED_CAPSULES
        s = self.config.scale
        self.radii = np.array([c.radius * s for c in self.capsules])
        self.parts = tuple(c.part for c in self.capsules)
        index = {k: i for i, k in enumerate(skeleton.keypoints)}
        self.attached = np.zeros((len(self.capsules), skeleton.num_keypoints), bool)
        for p, capsule in enumerate(self.capsules):
            for name in capsule.attached:
                if name in index:
                    self.attached[p, index[name]] = True

    @property
    def nominal_height(self):
        """Approximate standing height (m): rigs aim at about half of it."""
        return (1.75 if self.body == 'human' else 0.7) * self.config.scale

    @property
    def root_joint(self):
        """Name of the body point above the ground contact centre (pelvis / spine_mid)."""
        return 'pelvis' if self.body == 'human' else 'spine_mid'

    @property
    def default_path_radius(self):
        return (1.0 if self.body == 'human' else 0.6) * self.config.scale

    def _rng(self):
        return np.random.default_rng([self.seed, 0x5355])    # 'SU': subject stream

    def _trajectory(self, rng, t, speed):
        """Root position (T, 3) on the ground and heading (T,) along the path."""
        radius = self.config.path_radius
        if radius is None:
            radius = self.default_path_radius
        direction = rng.choice([-1.0, 1.0])
        theta0 = rng.uniform(0, 2 * np.pi)
        breathe = rng.uniform(0.15, 0.3)
        wobble = _smooth_fn(rng, 0.03, 0.12)

        def position(times):
            r = radius * (1 + breathe * wobble(times))
            angle = theta0 + direction * speed * times / max(radius, 1e-6)
            return np.stack([r * np.cos(angle), r * np.sin(angle)], axis=-1)

        xy = position(t)
        dt = 1e-3
        velocity = position(t + dt) - position(t - dt)
        heading = np.arctan2(velocity[:, 1], velocity[:, 0])
        return np.concatenate([xy, np.zeros((len(t), 1))], axis=1), heading

    def joints(self, times):
        """dict name -> (T, 3) world positions of every body point (keypoints and helpers)."""
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        rng = self._rng()
        local = self._human(rng, t) if self.body == 'human' else self._quadruped(rng, t)
        speed = local.pop('_speed')
        root, heading = self._trajectory(rng, t, speed)
        R = _rot_z(heading)                                   # (T, 3, 3) body -> world
        s = self.config.scale
        return {name: np.einsum('tij,tj->ti', R, p * s) + root for name, p in local.items()}

    def keypoints3d(self, times):
        """(T, C, 3) keypoints in skeleton order."""
        joints = self.joints(times)
        return np.stack([joints[k] for k in self.skeleton.keypoints], axis=1)

    def capsule_arrays(self, times, joints=None):
        """(A (T, P, 3), B (T, P, 3)) capsule end points for `times`."""
        joints = self.joints(times) if joints is None else joints
        A = np.stack([joints[c.a] for c in self.capsules], axis=1)
        B = np.stack([joints[c.b] for c in self.capsules], axis=1)
        return A, B

    # ------------------------------------------------------------------ body models

    def _human(self, rng, t):
        T = len(t)
        speed = self.config.speed if self.config.speed is not None else rng.uniform(0.8, 1.2)
        cadence = rng.uniform(0.8, 1.0)                       # strides per second
        phi = 2 * np.pi * cadence * t + rng.uniform(0, 2 * np.pi)
        swing_leg = rng.uniform(0.35, 0.5)
        swing_arm = rng.uniform(0.3, 0.5)
        knee_amp = rng.uniform(0.7, 1.0)
        raise_r = np.clip(0.6 * (1 + _smooth(rng, t, 0.1, 0.35)) - 0.3, 0, None)
        raise_l = np.clip(0.6 * (1 + _smooth(rng, t, 0.1, 0.35)) - 0.3, 0, None)
        elbow_extra = 0.4 * (1 + _smooth(rng, t, 0.15, 0.4))
        head_turn = 0.35 * _smooth(rng, t, 0.1, 0.3)
        lean = 0.08 + 0.05 * _smooth(rng, t, 0.1, 0.3)

        bob = 0.02 * np.cos(2 * phi)
        pelvis = np.stack([np.zeros(T), np.zeros(T), 0.95 + bob], axis=-1)
        twist = 0.12 * np.sin(phi)                            # shoulders counter-rotate hips
        spine = np.stack([np.sin(lean), np.zeros(T), np.cos(lean)], axis=-1)
        neck = pelvis + 0.52 * spine
        chest = pelvis + 0.36 * spine
        R_sh = _rot_z(twist)
        R_hip = _rot_z(-0.5 * twist)
        out = {'_speed': speed, 'pelvis': pelvis, 'chest': chest, 'neck': neck}
        R_head = _rot_z(head_turn)
        out['head'] = neck + np.einsum('tij,j->ti', R_head, [0.04, 0.0, 0.0]) + 0.2 * spine
        for side, sign, phase in (('l', 1.0, np.pi), ('r', -1.0, 0.0)):
            p = phi + phase
            shoulder = neck + np.einsum('tij,j->ti', R_sh, [0.0, sign * 0.18, -0.04])
            hip = pelvis + np.einsum('tij,j->ti', R_hip, [0.0, sign * 0.1, -0.02])
            # legs: hip flexion swings, the knee bends most while the leg swings forward
            hip_pitch = swing_leg * np.sin(p)
            knee = 0.1 + knee_amp * (0.5 * (1 + np.cos(p - 0.3))) ** 2
            knee_pos = hip + 0.44 * _direction(hip_pitch, np.full(T, 0.04), sign)
            ankle = knee_pos + 0.44 * _direction(hip_pitch - knee, np.full(T, 0.02), sign)
            toe = ankle + 0.14 * _direction(hip_pitch - knee + np.pi / 2 + 0.15,
                                            np.zeros(T), sign)
            # arms swing opposite to the same side's leg, plus slow seeded raises
            arm_pitch = -swing_arm * np.sin(p)
            abduction = 0.12 + (raise_l if sign > 0 else raise_r)
            elbow_flex = 0.25 + 0.3 * (0.5 * (1 + np.sin(p))) + elbow_extra * (sign > 0)
            elbow = shoulder + 0.29 * _direction(arm_pitch, abduction, sign)
            wrist = elbow + 0.26 * _direction(arm_pitch + elbow_flex, abduction, sign)
            hand = wrist + 0.08 * _direction(arm_pitch + elbow_flex, abduction, sign)
            out.update({f'{side}_shoulder': shoulder, f'{side}_elbow': elbow,
                        f'{side}_wrist': wrist, f'{side}_hand': hand, f'{side}_hip': hip,
                        f'{side}_knee': knee_pos, f'{side}_ankle': ankle, f'{side}_toe': toe})
        return out

    def _quadruped(self, rng, t):
        T = len(t)
        speed = self.config.speed if self.config.speed is not None else rng.uniform(0.5, 0.8)
        cadence = rng.uniform(1.3, 1.7)
        phi = 2 * np.pi * cadence * t + rng.uniform(0, 2 * np.pi)
        swing = rng.uniform(0.3, 0.45)
        head_turn = 0.4 * _smooth(rng, t, 0.1, 0.3)
        head_pitch = 0.2 * _smooth(rng, t, 0.1, 0.4)
        wag = 0.5 * np.sin(phi)
        bob = 0.015 * np.cos(2 * phi)
        z = np.zeros(T)
        neck = np.stack([z + 0.3, z, 0.55 + bob], axis=-1)
        spine_mid = np.stack([z, z, 0.53 + bob], axis=-1)
        tail_base = np.stack([z - 0.35, z, 0.52 + bob], axis=-1)
        R_head = _rot_z(head_turn)
        snout = np.stack([0.24 * np.cos(head_pitch), z, 0.05 - 0.24 * np.sin(head_pitch)], -1)
        out = {'_speed': speed, 'neck': neck, 'spine_mid': spine_mid, 'tail_base': tail_base,
               'nose': neck + np.einsum('tij,tj->ti', R_head, snout),
               'head_top': neck + np.einsum('tij,j->ti', R_head, [0.08, 0.0, 0.07]),
               'tail_tip': tail_base + 0.35 * np.stack(
                   [-np.cos(wag) * 0.9, np.sin(wag) * 0.9, z + 0.43], -1)}
        # trot: diagonal legs in phase (lf with rh, rf with lh)
        for name, x, sign, phase in (('lf', 0.28, 1, 0.0), ('rf', 0.28, -1, np.pi),
                                     ('lh', -0.3, 1, np.pi), ('rh', -0.3, -1, 0.0)):
            p = phi + phase
            top = np.stack([z + x, z + sign * 0.09, 0.45 + bob], axis=-1)
            paw = top + 0.42 * _direction(swing * np.sin(p), np.full(T, 0.03), sign)
            paw[:, 2] += 0.06 * (0.5 * (1 + np.cos(p))) ** 2        # lift while swinging
            joint = 'shoulder' if name[1] == 'f' else 'hip'
            out[f'{name}_{joint}'] = top
            out[f'{name}_paw'] = paw
        return out
