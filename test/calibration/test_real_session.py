"""Calibration of the real sleap-anipose session (4 cameras, 21 ChArUco images each)
against the calibration sleap-anipose made from the same images (only back and mid are
real there; side and top are placeholders, see the data's MANIFEST)."""
import cv2
import numpy as np
import pytest

from monet_ros.calibration.board import load_board
from monet_ros.calibration.detect import BoardDetector, detect_frames
from monet_ros.calibration.extrinsics import rotation_angle_deg
from monet_ros.calibration.rig import CalibrationConfig, calibrate_rig, stack_detections
from monet_ros.calibration.summary import board_geometry, camera_table, pair_table
from monet_ros.geometry import load_rig

pytestmark = pytest.mark.slow   # detects and bundle-adjusts (about a minute on a loaded machine)

CAMERAS = ('back', 'mid', 'side', 'top')


@pytest.fixture(scope='module')
def session(shared_data):
    root = shared_data / 'sleap_anipose_minimal_session'
    board = load_board(root / 'board.toml')
    detector = BoardDetector(board)
    detections = []
    for name in CAMERAS:
        files = sorted((root / name / 'calibration_images').glob('*.jpg'))
        detections.append(detect_frames(name, (cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
                                               for f in files), board, progress=False,
                                        detector=detector))
    reference = {c.name: c for c in load_rig(root / 'calibration.toml')}
    return board, detections, reference


def relative(a, b):
    """Pose of camera b relative to camera a: (R, t) with x_b = R x_a + t."""
    R = b.R @ a.R.T
    return R, b.t - R @ a.t


def angle_between(u, v):
    return np.degrees(np.arccos(np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1, 1)))


def test_corners_found_in_every_image(session):
    _, detections, _ = session
    for d in detections:
        counts = np.isfinite(d.corners[..., 0]).sum(axis=1)
        assert len(counts) == 21 and d.no_board == [], d.name
        assert counts.min() >= 63 and counts.max() <= 70, (d.name, counts)
        assert d.size == (1280, 1024)


def check_against_reference(result, reference, detections, board):
    cams = {c.name: c for c in result.cameras}
    assert result.errors.mean() <= 1.0
    for name in ('back', 'mid'):
        assert abs(cams[name].K[0, 0] / reference[name].K[0, 0] - 1) < 0.05, name
    R, t = relative(cams['back'], cams['mid'])
    R0, t0 = relative(reference['back'], reference['mid'])
    assert rotation_angle_deg(R @ R0.T) < 2.0
    assert angle_between(t, t0) < 3.0
    geometry = board_geometry(result, stack_detections(detections), board)
    assert abs(geometry['median'] - 24.0) <= 0.5, geometry
    assert geometry['count'] > 1000


@pytest.mark.parametrize('names', [('back', 'mid'), CAMERAS], ids=['back+mid', 'all four'])
def test_joint_calibration_matches_sleap_anipose(session, names):
    board, detections, reference = session
    chosen = [d for d in detections if d.name in names]
    result = calibrate_rig(chosen, board, CalibrationConfig(distortion='k1k2'))
    assert [c.name for c in result.cameras] == list(names) and not result.left_out
    check_against_reference(result, reference, chosen, board)
    table = camera_table(result)
    assert all(row['mean_px'] <= 1.0 and row['views'] == 21 for row in table)
    assert sum(row['corners'] for row in table) == len(result.errors)
    pairs = pair_table(result, stack_detections(chosen))
    assert len(pairs) == len(names) * (len(names) - 1) // 2
    assert all(p['views'] == 21 and p['stereo_px'] < 0.5 for p in pairs)


def test_reference_model_k1_centred_principal_point(session):
    """The model sleap-anipose fitted (k1 only, principal point at the centre)."""
    board, detections, reference = session
    chosen = detections[:2]
    result = calibrate_rig(chosen, board, CalibrationConfig(distortion='k1',
                                                            fix_principal_point=True))
    for cam in result.cameras:
        np.testing.assert_allclose(cam.K[:2, 2], [639.5, 511.5])
        assert cam.K[0, 0] == cam.K[1, 1]
        assert np.count_nonzero(cam.dist) == 1
        assert abs(cam.dist[0] - reference[cam.name].dist[0]) < 0.05
    check_against_reference(result, reference, chosen, board)


def test_inverted_real_images(session, shared_data):
    """The first image of each camera inverted (a board printed white on black): the same
    corners are found."""
    board, detections, _ = session
    detector = BoardDetector(board)
    root = shared_data / 'sleap_anipose_minimal_session'
    for d in detections:
        first = sorted((root / d.name / 'calibration_images').glob('*.jpg'))[0]
        image = cv2.imread(str(first), cv2.IMREAD_GRAYSCALE)
        ids, corners = detector.detect(255 - image)
        expected = np.flatnonzero(np.isfinite(d.corners[0, :, 0]))
        np.testing.assert_array_equal(np.sort(ids), expected)
        order = np.argsort(ids)
        assert np.abs(corners[order] - d.corners[0, expected]).max() < 0.5
