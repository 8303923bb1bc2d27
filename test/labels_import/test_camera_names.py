"""Which rig camera a source (a video folder, a file name, an OpenPose folder) belongs to:
exact names and --camera-map first, then anipose's containment rule, then the same ignoring
case and separators, so Pose2Sim's cam01_json folders find its calibration's cam_01."""
from pathlib import Path

import pytest

from monet_ros.labels_import import camera_for

RIG = ('cam_01', 'cam_02', 'cam_03', 'cam_04')


@pytest.mark.parametrize('source, expected', [
    ('cam_02', 'cam_02'),                     # exact
    ('trial1_cam_03.mp4', 'cam_03'),          # contained (anipose)
    ('cam01_json', 'cam_01'),                 # Pose2Sim's folder for its calibration's cam_01
    ('CAM04-json', 'cam_04'),
    ('top', 'top'),                           # no match: the validator names it
])
def test_a_source_name_finds_its_camera(source, expected):
    assert camera_for(source, RIG) == expected


def test_the_camera_map_and_an_explicit_camera_come_first():
    assert camera_for('cam01_json', RIG, camera_map={'cam01_json': 'cam_03'}) == 'cam_03'
    assert camera_for('cam01_json', RIG, camera='cam_04') == 'cam_04'


def test_two_equally_good_loose_matches_are_no_match():
    assert camera_for('cam1x', ('cam_1', 'c_am1')) == 'cam1x'


def test_pose2sim_demo_folders_match_its_calibration(shared_data):
    trial = (Path(shared_data) / 'pose2sim_demo_balancing' / 'S00_P00_SingleParticipant' /
             'S00_P00_T01_BalancingTrial' / 'pose')
    if not trial.is_dir():
        pytest.skip('Pose2Sim demo not in shared data')
    folders = sorted(p.name for p in trial.iterdir())
    assert [camera_for(f, RIG) for f in folders] == list(RIG)
