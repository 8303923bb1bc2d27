"""subjects.detection: the discovery's grouping rule and its config."""
import numpy as np
import pytest

from monet_ros.config import ConfigError
from monet_ros.subjects.detection import SubjectsConfig, group_points


def test_two_whole_subjects_never_merge_through_a_pair_closer_than_the_link():
    # subject A: keypoints 0, 1, 2 in a column 0.3 apart; subject B the same 0.45 to the
    # side: A's keypoint 0 and B's keypoint 1 are 0.54 apart, within the link (0.6), which
    # plain single linkage would follow into one group
    A = np.array([[0.0, 0, 1.6], [0.0, 0, 1.3], [0.0, 0, 1.0]])
    B = A + [0.45, 0.0, 0.0]
    loose = np.array([[3.0, 3.0, 0.0]])
    points = np.concatenate([B, A, loose])
    keypoint = np.array([0, 1, 2, 0, 1, 2, 1])
    views = np.array([3, 3, 3, 4, 4, 4, 2])
    groups = group_points(points, keypoint, views, link=0.6)
    # most keypoints first, then most views: A (4 views each) before B
    assert [g.tolist() for g in groups] == [[3, 4, 5], [0, 1, 2], [6]]
    groups = group_points(points[:6], keypoint[:6], views[:6], link=0.2)   # too short
    assert [g.tolist() for g in groups] == [[3], [4], [5], [0], [1], [2]]


def test_no_points_no_groups():
    assert group_points(np.zeros((0, 3)), np.zeros(0, int), np.zeros(0, int), 0.6) == []


@pytest.mark.parametrize('field, value', [('subjects', 0), ('candidates', 0),
                                          ('link_mm', 0.0), ('crop_peaks', 99),
                                          ('duplicate_mm', -1.0)])
def test_config_names_the_bad_field(field, value):
    with pytest.raises(ConfigError, match=field):
        SubjectsConfig(**{field: value})


def test_only_recently_matched_tracks_get_crops_at_most_n():
    # the rule of the module docstring, step 1: tracks matched within crop_missed frames,
    # at most N, the most recently matched first; a track missed longer still lives in the
    # tracker (its identity kept for a later match) but gets no crop
    from types import SimpleNamespace

    from monet_ros.subjects.detection import SubjectsStep

    step = SubjectsStep(SimpleNamespace(keypoints=['a', 'b', 'c']), 'm',
                        SubjectsConfig(subjects=2, crop_missed=2))
    body = np.array([[0.0, 0.0, 1.6], [0.0, 0.0, 1.3], [0.0, 0.0, 1.0]])
    bodies = np.stack([body, body + [2.0, 0, 0], body + [0, 2.0, 0]])

    def frame(k, subjects):
        before = dict(zip(step.tracker.ids.tolist(), step._missed.tolist()))
        ids = step.tracker.step(bodies[subjects], k * 33_333_333)
        step.count_misses(before, ids)
        return step.tracker.ids[step.cropped_tracks()].tolist()

    assert frame(0, [0, 1, 2]) == [0, 1]            # three born, N = 2: the oldest two
    assert frame(1, [2, 0]) == [0, 2]               # 1 missed once: still allowed, but 0, 2
    assert frame(2, [0]) == [0, 2]                  # 2 missed once, 1 twice: 0, 2
    assert frame(3, [1]) == [1, 0]                  # 1 back (same identity), 0 missed once
    assert frame(4, []) == [1]                      # 0 missed twice now
    assert frame(5, []) == []                       # all missed twice or more: none
    assert step.tracker.ids.tolist() == [0, 1, 2]   # alive (max_missed_s 0.5 s)
