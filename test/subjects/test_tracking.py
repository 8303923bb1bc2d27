"""Identities over time (subjects.tracking, module docstring steps 2 and 5): constructed
subjects walking past each other, with frames missing, poor or spurious, checked against
the ground-truth identities that made them."""
import numpy as np
import pytest

from monet_ros.skeleton import load_skeleton
from monet_ros.subjects.tracking import SubjectTracker, TrackerConfig
from monet_ros.synth.subjects import subjects_keypoints

FPS = 30.0
SKELETON = load_skeleton('human14')
C = SKELETON.num_keypoints


@pytest.fixture(scope='module')
def crossing():
    """(times (120,), X (120, 2, C, 3) m) two subjects walking past each other (closest
    ~0.6 m) with 5 mm noise."""
    times = np.arange(120) / FPS
    X = subjects_keypoints(SKELETON, 2, times)
    X = X + np.random.default_rng(0).normal(0, 0.005, X.shape)
    return times, X


def _gap(X):
    return np.linalg.norm(X[:, 0, :, :2].mean(1) - X[:, 1, :, :2].mean(1), axis=-1)


def _track(times, frames, **kwargs):
    """Feed (frame k -> list of (gt subject, X (C, 3))) to a tracker, in a shuffled order
    each frame -> (tracker, {gt subject: set of identities given}, ids per frame)."""
    tracker = SubjectTracker(C, kwargs.pop('config', None), **kwargs)
    rng = np.random.default_rng(1)
    given, per_frame = {}, []
    for k, t in enumerate(times):
        subjects = frames(k)
        order = rng.permutation(len(subjects))
        X = np.array([subjects[i][1] for i in order]).reshape(-1, C, 3)
        ids = tracker.step(X, round(t * 1e9))
        per_frame.append({subjects[i][0]: int(j) for i, j in zip(order, ids)})
        for i, j in zip(order, ids):
            given.setdefault(subjects[i][0], set()).add(int(j))
    return tracker, given, per_frame


def test_the_subjects_pass_close(crossing):
    _, X = crossing
    assert _gap(X).min() < 0.7 and _gap(X).max() > 1.5


def test_a_subject_missing_for_k_frames_keeps_its_identity_near_its_prediction(crossing):
    # subject 1 is not decoded for 12 frames (0.4 s < max_missed_s) while the two approach;
    # it comes back where it walked (its body ~0.4 m from where it was last seen, more
    # than the 250 mm gate): the lost track's body prediction (its last velocity) and its
    # gate grown by max_speed_m_s x 0.4 s take it back
    times, X = crossing
    missing = range(30, 42)
    config = TrackerConfig(gate_mm=250.0)
    tracker, given, _ = _track(times, lambda k: [(g, X[k, g]) for g in (0, 1)
                                                 if not (g == 1 and k in missing)],
                               config=config, max_tracks=2)
    moved = np.linalg.norm(X[42, 1].mean(0) - X[29, 1].mean(0))
    assert moved > 0.3
    assert given == {0: {0}, 1: {1}}
    assert tracker.births == 2 and tracker.deaths == 0


def test_a_subject_far_from_every_lost_track_is_a_birth(crossing):
    # subject 1 is lost for 12 frames; meanwhile a third subject (subject 0's body 3 m
    # away) appears: far from every track, with room for a third identity it is born;
    # subject 1 still comes back as itself
    times, X = crossing
    far = X[:, 0] + [3.0, 3.0, 0.0]

    def frames(k):
        out = [(0, X[k, 0])] + ([] if 30 <= k < 42 else [(1, X[k, 1])])
        return out + ([(2, far[k])] if k >= 35 else [])

    tracker, given, per_frame = _track(times, frames, max_tracks=3)
    assert given == {0: {0}, 1: {1}, 2: {2}}
    assert per_frame[35][2] == 2 and tracker.births == 3


def test_with_n_identities_alive_a_subject_no_track_takes_is_left_untracked(crossing):
    # N = 2 subjects, both tracked; in frame 50 subject 0 is decoded 1.5 m off (a poor
    # decode, far from every track) and subject 1 not at all: no third identity is born
    # (-1, counted), and subject 0's track takes it back when it is decoded well again
    times, X = crossing

    def frames(k):
        if k == 50:
            return [(0, X[k, 0] + [1.5, 0.0, 0.0])]
        return [(0, X[k, 0]), (1, X[k, 1])]

    tracker, given, per_frame = _track(times, frames, max_tracks=2)
    assert per_frame[50] == {0: -1}
    assert given == {0: {0, -1}, 1: {1}}
    assert tracker.births == 2 and tracker.untracked == 1
    # without the limit the poor decode is a new identity (the rule's reason)
    tracker, given, _ = _track(times, frames)
    assert given[0] == {0, 2} and tracker.births == 3


def test_poor_frames_during_the_pass_keep_both_identities(crossing):
    # where the two pass (~0.6 m apart) three frames decode each subject poorly: every
    # joint pulled 40% of the way towards the other subject and 4 of its 14 joints (an
    # arm and a leg) taken from the other. Each subject keeps its identity in every frame:
    # the body (median displacement) moves less than the mean joint, and the body filter
    # does not take the jump as velocity as the per-joint filter does.
    times, X = crossing
    k0 = int(np.argmin(_gap(X)))
    poor = range(k0 - 1, k0 + 2)
    limbs = [SKELETON.keypoints.index(k) for k in
             ('l_elbow', 'l_wrist', 'l_knee', 'l_ankle')]

    def frames(k):
        if k not in poor:
            return [(0, X[k, 0]), (1, X[k, 1])]
        out = []
        for g in (0, 1):
            Y = X[k, g] + 0.4 * (X[k, 1 - g] - X[k, g])
            Y[limbs] = X[k, 1 - g, limbs]
            out.append((g, Y))
        return out

    assert 0.5 < _gap(X)[k0] < 0.7
    tracker, given, per_frame = _track(times, frames, max_tracks=2)
    assert all(f == {0: 0, 1: 1} for f in per_frame), [
        (k, f) for k, f in enumerate(per_frame) if f != {0: 0, 1: 1}][:3]
    assert tracker.births == 2


def test_gate_settings_are_checked():
    from monet_ros.config import ConfigError

    for field in ('body_noise_mm', 'body_acceleration_m_s2', 'max_speed_m_s'):
        with pytest.raises(ConfigError, match=field):
            TrackerConfig(**{field: -1.0})


def test_masked_median_is_numpys_nanmedian():
    from monet_ros.subjects.tracking import masked_median

    rng = np.random.default_rng(2)
    for shape in [(4, 5, 14, 3), (3, 14, 3), (2, 1, 3), (2, 0, 3)]:
        values = rng.normal(size=shape)
        mask = rng.random(shape[:-1]) < 0.6
        mask[0] = False                                     # rows of no entry: NaN
        expected = np.full(shape[:-2] + (3,), np.nan)
        some = mask.any(-1)
        expected[some] = np.nanmedian(np.where(mask[some][..., None], values[some], np.nan),
                                      axis=-2)
        np.testing.assert_array_equal(masked_median(values, mask), expected)
