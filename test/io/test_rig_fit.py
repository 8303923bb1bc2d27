"""Fitting a calibration file to a recording: the lab's full-resolution Pose2Sim
calibration (names cam_01, 1088 wide) on the half-resolution derived bag (topics /cam01,
540 wide) gives exactly the bag's own cameras; sizes that do not fit are named."""
from helpers.ring import ring_rig
import numpy as np
import pytest

from monet_ros.geometry import load_rig
from monet_ros.io import open_bag, rig_from_bag
from monet_ros.io.rig_fit import RigFitError, fit_camera, fit_rig_to_bag
from monet_ros.labels import LabelOptions
from monet_ros.learning.recording import load_recording

MAP = tuple((f'cam_0{i}', f'cam0{i}') for i in range(1, 5))


def test_fit_camera_scales_pads_or_refuses():
    cam = ring_rig(1, width=640, height=480)[0]
    same, note = fit_camera(cam, 640, 480, 'x')
    assert same is cam and note == ''
    half, note = fit_camera(cam, 320, 240, 'x')
    np.testing.assert_allclose(half.K[:2, 2], (cam.K[:2, 2] + 0.5) * 0.5 - 0.5)
    assert half.K[0, 0] == cam.K[0, 0] / 2 and 'K scaled by 0.5' in note
    padded, note = fit_camera(cam, 632, 480, 'x')
    np.testing.assert_array_equal(padded.K, cam.K)
    assert (padded.width, padded.height) == (632, 480) and 'codec padding' in note
    with pytest.raises(RigFitError, match=r'x: image 500x480 does not fit camera cam0'):
        fit_camera(cam, 500, 480, 'x')


def test_full_resolution_calibration_on_the_half_resolution_bag(shared_data):
    bag = shared_data / 'derived_pose2sim_4cam_mcap' / 'pose2sim_balancing_4cam'
    calib = shared_data / 'pose2sim_demo_balancing' / 'S00_Calibration' / 'Calib_qualisys.toml'
    reader = open_bag(bag)
    with pytest.raises(RigFitError, match=r"no image topic for calibration camera 'cam_01'.*"
                       r'--camera-map cam_01=NAME'):
        fit_rig_to_bag(load_rig(calib), reader)
    fitted, notes = fit_rig_to_bag(load_rig(calib), reader, MAP)
    own = {c.name: c for c in rig_from_bag(bag)}      # the bag's camera_info + /tf_static
    for cam in fitted:
        ref = own[cam.name]
        assert (cam.width, cam.height) == (ref.width, ref.height)
        assert cam.topic == f'/{cam.name}/image_raw/compressed'
        np.testing.assert_allclose(cam.K, ref.K, atol=1e-9)
        np.testing.assert_allclose(cam.R, ref.R, atol=1e-9)
    assert len(notes) == 4 and 'cam01: calibration 1088x1920' in notes[0]
    rec = load_recording(bag, rig=calib, skeleton=('a',), max_instants=2,
                         label_options=LabelOptions(camera_map=MAP))
    assert [c.name for c in rec.cameras] == ['cam01', 'cam02', 'cam03', 'cam04']
    assert rec.frames[0].shape == (2, 960, 540, 3) and len(rec.rig_notes) == 4
