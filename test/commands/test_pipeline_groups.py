"""`monet pipeline --detector-processes`: the cameras split between detector processes."""
from types import SimpleNamespace

import pytest

from monet_ros.commands.pipeline import (
    SPLIT_PRECISIONS,
    TWO_DETECTORS_FROM,
    detector_groups,
    detector_threads,
    groups_line,
)
from monet_ros.config import ConfigError


def slots(n):
    return [SimpleNamespace(name=f'cam{i}') for i in range(n)]


@pytest.mark.parametrize('cameras,processes', [(16, 2), (5, 2), (7, 3), (4, 4), (3, 1)])
def test_groups_are_contiguous_near_equal_and_cover_every_camera(cameras, processes):
    groups = detector_groups(slots(cameras), processes, 'bfloat16')
    assert len(groups) == processes
    assert [name for group in groups for name in group] == [f'cam{i}' for i in range(cameras)]
    sizes = [len(group) for group in groups]
    assert max(sizes) - min(sizes) <= 1 and min(sizes) >= 1


@pytest.mark.parametrize('precision', SPLIT_PRECISIONS)
def test_auto_is_two_processes_from_the_measured_camera_count_in_slow_precisions(precision):
    assert len(detector_groups(slots(TWO_DETECTORS_FROM), 0, precision)) == 2
    assert detector_groups(slots(TWO_DETECTORS_FROM - 1), 0, precision) == [
        [f'cam{i}' for i in range(TWO_DETECTORS_FROM - 1)]]


def test_auto_is_one_process_in_bfloat16_at_any_camera_count():
    for cameras in (1, TWO_DETECTORS_FROM, 2 * TWO_DETECTORS_FROM):
        assert detector_groups(slots(cameras), 0, 'bfloat16') == [
            [f'cam{i}' for i in range(cameras)]]


def test_the_line_says_the_count_and_why_when_auto():
    groups = detector_groups(slots(TWO_DETECTORS_FROM), 0, 'float32')
    assert groups_line(groups, 0, 'float32') == (
        f'2 detector processes for {TWO_DETECTORS_FROM} cameras (--detector-processes auto: '
        f'2 from {TWO_DETECTORS_FROM} cameras in float32 or int8, else 1; precision float32)')
    assert groups_line(detector_groups(slots(3), 1, 'float32'), 1, 'float32') == (
        '1 detector process for 3 cameras')


def test_more_processes_than_cameras_is_an_error_naming_the_option():
    with pytest.raises(ConfigError, match='detector_processes.*3 detector processes for 2'):
        detector_groups(slots(2), 3, 'float32')


@pytest.mark.parametrize('threads,processes,cores,expected', [
    (0, 1, 2, 0),      # one process: the backend default (every core)
    (0, 2, 2, 1),      # two on 2 cores: one each, not 2 x 2
    (0, 2, 16, 8),
    (0, 3, 16, 5),
    (0, 4, 2, 1),      # never 0 (which would mean every core again)
    (3, 2, 2, 3),      # --threads given: as given
])
def test_detector_threads_share_the_cores_between_processes(threads, processes, cores,
                                                            expected):
    assert detector_threads(threads, processes, cores) == expected
