"""Articulated subject: rigid bone lengths, smooth motion, ground contact, heading along the
path, seeding, skeleton matching."""
import numpy as np
import pytest

from monet_ros.skeleton import Skeleton, load_skeleton
from monet_ros.synth.subject import Subject, SubjectConfig, SubjectError

TIMES = np.arange(150) / 30.0


def _bone_lengths(X, skeleton, a, b):
    return np.linalg.norm(X[:, skeleton.index(a)] - X[:, skeleton.index(b)], axis=-1)


def test_human_bones_are_rigid_and_symmetric():
    skeleton = load_skeleton('human14')
    X = Subject(skeleton, seed=4).keypoints3d(TIMES)
    assert X.shape == (150, 14, 3) and np.all(np.isfinite(X))
    for a, b, length in (('elbow', 'shoulder', 0.29), ('wrist', 'elbow', 0.26),
                         ('knee', 'hip', 0.44), ('ankle', 'knee', 0.44)):
        for side in 'lr':
            np.testing.assert_allclose(
                _bone_lengths(X, skeleton, f'{side}_{a}', f'{side}_{b}'), length, atol=1e-9)
    np.testing.assert_allclose(_bone_lengths(X, skeleton, 'l_hip', 'r_hip'),
                               _bone_lengths(X, skeleton, 'l_hip', 'r_hip')[0], atol=1e-9)
    # standing up: ankles near the ground, the head on top
    ankles = X[:, [skeleton.index('l_ankle'), skeleton.index('r_ankle')], 2]
    assert ankles.min() > -0.05 and ankles.max() < 0.35
    assert np.all(X[:, skeleton.index('head'), 2] >= X[:, :, 2].max(axis=1) - 0.25)
    assert 1.5 < X[:, skeleton.index('head'), 2].mean() < 1.8


def test_motion_is_smooth_walks_forward_and_covers_a_turn():
    skeleton = load_skeleton('human14')
    X = Subject(skeleton, seed=7).keypoints3d(TIMES)
    speed = np.linalg.norm(np.diff(X, axis=0), axis=-1) * 30.0
    assert speed.max() < 8.0                       # m/s of the fastest joint (wrist swing)
    accel = np.linalg.norm(np.diff(X, 2, axis=0), axis=-1) * 900.0
    assert accel.max() < 150.0
    pelvis = X[:, [skeleton.index('l_hip'), skeleton.index('r_hip')]].mean(1)
    velocity = np.gradient(pelvis[:, :2], axis=0)
    across = X[:, skeleton.index('l_hip'), :2] - X[:, skeleton.index('r_hip'), :2]
    facing = np.stack([across[:, 1], -across[:, 0]], 1)      # left x up = forward
    cos = (velocity * facing).sum(1) / np.linalg.norm(velocity, axis=1) / np.linalg.norm(
        facing, axis=1)
    assert np.median(cos) > 0.9
    heading = np.unwrap(np.arctan2(velocity[:, 1], velocity[:, 0]))
    assert abs(heading[-1] - heading[0]) > np.radians(90)    # it turns
    assert np.hypot(pelvis[:, 0], pelvis[:, 1]).max() < 1.5   # and stays near the centre
    # arms and legs move: the gait swings limbs
    wrist = X[:, skeleton.index('r_wrist')] - X[:, skeleton.index('r_shoulder')]
    assert np.ptp(wrist, axis=0).max() > 0.2


def test_seeded():
    skeleton = load_skeleton('human14')
    a = Subject(skeleton, seed=1).keypoints3d(TIMES)
    np.testing.assert_array_equal(a, Subject(skeleton, seed=1).keypoints3d(TIMES))
    assert np.abs(a - Subject(skeleton, seed=2).keypoints3d(TIMES)).max() > 0.1
    # evaluating a sub-range gives the same values (a function of time, not of frame count)
    np.testing.assert_allclose(Subject(skeleton, seed=1).keypoints3d(TIMES[40:60]), a[40:60],
                               atol=1e-12)


def test_quadruped():
    skeleton = load_skeleton('quadruped13')
    subject = Subject(skeleton, seed=0)
    assert subject.body == 'quadruped'
    X = subject.keypoints3d(TIMES)
    assert X.shape == (150, 13, 3) and np.all(np.isfinite(X))
    paws = X[:, [skeleton.index(k) for k in ('lf_paw', 'rf_paw', 'lh_paw', 'rh_paw')], 2]
    assert paws.min() > -0.05 and paws.max() < 0.15
    for leg in ('lf_shoulder', 'rf_shoulder'):
        paw = leg.replace('shoulder', 'paw')
        np.testing.assert_allclose(_bone_lengths(X, skeleton, leg, paw).min(), 0.42 - 0.06,
                                   atol=0.07)
    assert np.linalg.norm(np.diff(X, axis=0), axis=-1).max() * 30 < 6.0


def test_capsules_and_attachments():
    skeleton = load_skeleton('human14')
    subject = Subject(skeleton, seed=0)
    A, B = subject.capsule_arrays(TIMES[:5])
    assert A.shape == B.shape == (5, len(subject.capsules), 3)
    assert subject.attached.shape == (len(subject.capsules), 14)
    assert subject.attached.any(axis=0).all()          # every keypoint lies in some limb
    # left and right limbs share their material and radius
    parts = dict(zip([(c.a, c.b) for c in subject.capsules], zip(subject.parts, subject.radii)))
    assert parts[('l_elbow', 'l_wrist')] == parts[('r_elbow', 'r_wrist')]
    assert parts[('l_hip', 'l_knee')] == parts[('r_hip', 'r_knee')]


def test_custom_skeleton_subset_keeps_its_order_and_unknown_names_fail():
    custom = Skeleton('arms', ('r_wrist', 'l_wrist', 'neck'), bones=(('r_wrist', 'neck'),))
    human = load_skeleton('human14')
    X = Subject(custom, seed=5).keypoints3d(TIMES[:10])
    full = Subject(human, seed=5).keypoints3d(TIMES[:10])
    np.testing.assert_array_equal(X, full[:, [human.index(k) for k in custom.keypoints]])
    with pytest.raises(SubjectError, match='tail'):
        Subject(Skeleton('odd', ('head', 'tail')))
    with pytest.raises(SubjectError, match='body'):
        SubjectConfig(body='fish')
    with pytest.raises(SubjectError, match=r"\['head'\]"):
        Subject(Skeleton('h', ('head', 'nose')),
                SubjectConfig(body='quadruped'))
