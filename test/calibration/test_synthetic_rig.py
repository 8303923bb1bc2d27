"""A rendered board seen by a known synthetic rig (`monet synth`'s cameras): the calibration
recovers the intrinsics and the extrinsics (truth: the rig that rendered the images)."""
from dataclasses import replace

from helpers.boards import board_poses_facing_up, render_view
import numpy as np
import pytest

from monet_ros.calibration.board import Board
from monet_ros.calibration.detect import BoardDetector, detect_frames
from monet_ros.calibration.extrinsics import rotation_angle_deg
from monet_ros.calibration.rig import CalibrationConfig, calibrate_rig
from monet_ros.synth import RigConfig, make_rig

pytestmark = pytest.mark.slow   # renders, detects, bundle-adjusts: ~1 min loaded

# A mouse-arena-sized rig: 3 cameras 0.35 m around and 0.35 m above the board, metres.
RIG = RigConfig(num_cameras=3, radius=0.35, camera_height=1.25, target=(0.0, 0.0, 0.9),
                image_width=800, image_height=600, hfov_deg=55.0, distortion=(-0.08, 0.02))
BOARD = Board(8, 11, 0.02, 'charuco', 0.015, 4, 1000)
VIEWS = 20


def world_to_camera(camera):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = camera.R, camera.t
    return T


@pytest.fixture(scope='module')
def scene():
    cameras = make_rig(RIG, seed=1)
    rng = np.random.default_rng(0)
    poses = board_poses_facing_up(VIEWS, RIG.target, BOARD.square_length, BOARD, rng,
                                  tilt_deg=45.0, spread=0.08)
    detector = BoardDetector(BOARD)
    detections = [detect_frames(cam.name, (render_view(BOARD, cam, world_to_camera(cam) @ T,
                                                       rng=rng) for T in poses),
                                BOARD, progress=False, detector=detector)
                  for cam in cameras]
    return cameras, detections


def relative_truth(cameras, root):
    """{name: (R, t)} world -> camera of the true rig, with the root camera as the world."""
    T_root = world_to_camera(next(c for c in cameras if c.name == root))
    out = {}
    for cam in cameras:
        T = world_to_camera(cam) @ np.linalg.inv(T_root)
        out[cam.name] = (T[:3, :3], T[:3, 3])
    return out


def check_extrinsics(result, cameras, rot_deg=0.2, trans=1e-3):
    truth = relative_truth(cameras, result.root)
    for cam in result.cameras:
        R, t = truth[cam.name]
        assert rotation_angle_deg(cam.R @ R.T) < rot_deg, cam.name
        assert np.linalg.norm(cam.t - t) < trans, (cam.name, np.linalg.norm(cam.t - t))


@pytest.fixture(scope='module')
def calibrated(scene):
    _, detections = scene
    return calibrate_rig(detections, BOARD, CalibrationConfig(distortion='k1k2',
                                                              square_pixels=False))


def test_recovers_intrinsics_within_half_a_percent(scene, calibrated):
    cameras, _ = scene
    truth = {c.name: c for c in cameras}
    assert sorted(c.name for c in calibrated.cameras) == ['cam0', 'cam1', 'cam2']
    for cam in calibrated.cameras:
        K = truth[cam.name].K
        for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)):
            assert abs(cam.K[i, j] / K[i, j] - 1) < 0.005, (cam.name, i, j, cam.K[i, j], K[i, j])
        # the k1k2 model fits the rig's k1 k2 (p1, p2, k3 of the rig are 0)
        assert abs(cam.dist[0] - truth[cam.name].dist[0]) < 0.01
    assert calibrated.errors.mean() < 0.2
    assert not calibrated.warnings


def test_recovers_extrinsics_within_02_deg_and_1_mm(scene, calibrated):
    check_extrinsics(calibrated, scene[0])


def test_board_units_are_kept(scene, calibrated):
    """The same detections with the board described in millimetres: the translations are
    1000 times those in metres, rotations and intrinsics unchanged (to the bundle
    adjustment's convergence: the two solves stop at slightly different points, a few
    thousandths of a pixel apart, by BLAS and CPU)."""
    _, detections = scene
    board_mm = replace(BOARD, square_length=20.0, marker_length=15.0)
    mm = calibrate_rig(detections, board_mm, CalibrationConfig(distortion='k1k2',
                                                               square_pixels=False))
    metres = {c.name: c for c in calibrated.cameras}
    for cam in mm.cameras:
        np.testing.assert_allclose(cam.t, 1000 * metres[cam.name].t, rtol=1e-4, atol=0.01)
        assert rotation_angle_deg(cam.R @ metres[cam.name].R.T) < 1e-3
        np.testing.assert_allclose(cam.K, metres[cam.name].K, rtol=0, atol=0.05)


def test_chained_over_the_spanning_tree(scene):
    """cam0 and cam2 share no view (cam0 sees the first half, cam2 the second): both are
    posed through cam1 (each from half the views, so 0.3 deg / 3 mm)."""
    cameras, detections = scene
    half = VIEWS // 2
    cut = [replace(d, corners=d.corners.copy()) for d in detections]
    cut[0].corners[half:] = np.nan
    cut[2].corners[:half] = np.nan
    result = calibrate_rig(cut, BOARD, CalibrationConfig(distortion='k1k2',
                                                         square_pixels=False))
    assert result.root == 'cam1'
    assert sorted((a, b) for a, b, _ in result.tree) == [('cam1', 'cam0'), ('cam1', 'cam2')]
    assert result.shared[0, 2] == 0
    check_extrinsics(result, cameras, rot_deg=0.3, trans=3e-3)


def test_unconnected_camera_is_left_out_loudly(scene):
    _, detections = scene
    half = VIEWS // 2
    cut = [replace(d, corners=d.corners.copy()) for d in detections]
    cut[0].corners[half:] = np.nan
    cut[1].corners[half:] = np.nan
    cut[2].corners[:half] = np.nan
    result = calibrate_rig(cut, BOARD, CalibrationConfig(distortion='k1k2'))
    assert [c.name for c in result.cameras] == ['cam0', 'cam1']
    assert 'cam2' in result.left_out
    assert any("'cam2' is NOT calibrated: no board view shared" in w for w in result.warnings)


def test_known_intrinsics_fit_extrinsics_only(scene):
    cameras, detections = scene
    result = calibrate_rig(detections, BOARD, fixed_intrinsics={c.name: c for c in cameras})
    truth = {c.name: c for c in cameras}
    for cam in result.cameras:
        np.testing.assert_array_equal(cam.K, truth[cam.name].K)
        np.testing.assert_array_equal(cam.dist, truth[cam.name].dist)
    check_extrinsics(result, cameras)
    assert result.intrinsics_rms == {}


def test_few_views_and_high_error_are_warned(scene):
    _, detections = scene
    cut = [replace(d, corners=d.corners.copy()) for d in detections]
    seen = np.flatnonzero(np.isfinite(cut[2].corners[..., 0]).any(axis=1))
    cut[2].corners[seen[4:]] = np.nan                    # cam2: 4 board views left
    result = calibrate_rig(cut, BOARD, CalibrationConfig(distortion='k1k2', min_views=5,
                                                         high_error_px=0.01))
    assert "camera 'cam2': only 4 board views (fewer than 5)" in result.warnings[0]
    high = [w for w in result.warnings if 'is high (> 0.01 px)' in w]
    assert len(high) == 3                                # every camera is above 0.01 px
