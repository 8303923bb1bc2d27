"""Several synthetic subjects and their per-camera instances (no ROS), for tests and
bench/subjects.py: ground-truth identities known, instance order shuffled.

Subjects walk the synthetic subject's path (synth.subject) on rings of different radii
(PATH_RADII m), so their angular speeds differ and they pass each other (and stand
between each other and cameras) again and again.
"""
import numpy as np

from monet_ros.geometry.camera import project_views
from monet_ros.synth.render import occlusion
from monet_ros.synth.subject import Subject, SubjectConfig

PATH_RADII = (0.7, 1.4, 2.1)     # m: one ring per subject


def make_subjects(skeleton, num_subjects, seed=0):
    """num_subjects (1..len(PATH_RADII)) synth.Subject: subject k walks ring
    PATH_RADII[k], seeded by seed * 1000 + k. Raises ValueError for another count."""
    if not 1 <= num_subjects <= len(PATH_RADII):
        raise ValueError(f'num_subjects must be in 1..{len(PATH_RADII)}, got {num_subjects}')
    return [Subject(skeleton, SubjectConfig(path_radius=PATH_RADII[k]), seed=seed * 1000 + k)
            for k in range(num_subjects)]


def subjects_keypoints(skeleton, num_subjects, times, seed=0):
    """(T, S, C, 3) ground-truth keypoints (m) of make_subjects' subjects at `times` (s)."""
    return np.stack([s.keypoints3d(times) for s in make_subjects(skeleton, num_subjects, seed)],
                    axis=1)


def subjects_occlusion(subjects, times, cameras):
    """(X (T, S, C, 3), hidden (T, S, V, C) bool): each keypoint hidden in a view by any
    limb (capsule) of any subject not attached to it, another subject's body included
    (synth.render.occlusion over all subjects' capsules)."""
    joints = [s.joints(times) for s in subjects]
    X = np.stack([np.stack([j[k] for k in s.skeleton.keypoints], axis=1)
                  for s, j in zip(subjects, joints)], axis=1)            # (T, S, C, 3)
    caps = [s.capsule_arrays(times, j) for s, j in zip(subjects, joints)]
    A = np.concatenate([a for a, _ in caps], axis=1)                     # (T, S P, 3)
    B = np.concatenate([b for _, b in caps], axis=1)
    radii = np.concatenate([s.radii for s in subjects])
    T, S, C, _ = X.shape
    attached = np.zeros((len(radii), S * C), bool)                       # block diagonal
    row = 0
    for k, s in enumerate(subjects):
        P = len(s.radii)
        attached[row:row + P, k * C:(k + 1) * C] = s.attached
        row += P
    hidden = occlusion(cameras, X.reshape(T, S * C, 3), A, B, radii, attached)
    return X, hidden.reshape(T, len(cameras), S, C).transpose(0, 2, 1, 3)


def shuffled_instances(X, cameras, noise_px=1.0, seen=None, seed=0, hidden=None):
    """Per-camera instances of subjects X (T, S, C, 3): (points (T, V, S, C, 2) px with
    Gaussian noise noise_px per axis, instance slots in a random order per camera and
    frame; owner (T, V, S) int: the subject of each slot, -1 = an empty slot (all NaN)).
    seen (T, S, V) bool or None: which cameras see which subject (unseen: the slot is
    empty); keypoints projecting outside an image, or hidden (T, S, V, C) bool, are NaN."""
    X = np.asarray(X, np.float64)
    T, S, C, _ = X.shape
    V = len(cameras)
    rng = np.random.default_rng(seed)
    uv = project_views(cameras, X.reshape(T * S, C, 3)).reshape(T, S, V, C, 2)
    uv = uv + rng.normal(0.0, noise_px, uv.shape)
    size = np.array([[c.width, c.height] for c in cameras], np.float64)   # (V, 2)
    inside = ((uv >= -0.5) & (uv <= size[None, None, :, None] - 0.5)).all(-1)
    if hidden is not None:
        inside &= ~np.asarray(hidden, bool)
    uv = np.where(inside[..., None], uv, np.nan)
    owner = np.broadcast_to(np.arange(S), (T, V, S)).copy()
    if seen is not None:
        owner = np.where(np.asarray(seen, bool).transpose(0, 2, 1), owner, -1)
    perm = np.argsort(rng.random((T, V, S)), axis=-1)
    owner = np.take_along_axis(owner, perm, axis=-1)
    src = np.maximum(owner, 0)
    points = uv.transpose(0, 2, 1, 3, 4)[np.arange(T)[:, None, None],
                                          np.arange(V)[None, :, None], src]   # (T, V, S, C, 2)
    points[owner < 0] = np.nan
    return points, owner
