"""Acceptance on real data: Pose2Sim's demo triangulation and DANNCE's 3D labels."""
import numpy as np
import pytest

from monet_ros.geometry import load_rig, reprojection_error, triangulate, triangulate_robust
from monet_ros.geometry.pose2sim import (
    BODY_25B_IDS,
    read_openpose_folder,
    read_trc,
    trc_to_world,
)

TRIAL = 'pose2sim_demo_balancing/S00_P00_SingleParticipant/S00_P00_T01_BalancingTrial'


def _pose2sim_inputs(root):
    trial = root / TRIAL
    cams = load_rig(root / 'pose2sim_demo_balancing/S00_Calibration/Calib_qualisys.toml')
    folders = sorted((trial / 'pose-associated').glob('cam*_json'))
    detections = np.stack([read_openpose_folder(f) for f in folders])  # (V, F, 25, 3)
    names, frames, trc = read_trc(next((trial / 'pose-3d').glob('*.trc')))
    return cams, folders, detections, names, frames, trc


def test_pose2sim_demo_reproduces_trc(shared_data):
    cams, folders, det, names, frames, trc = _pose2sim_inputs(shared_data)
    assert [f.name for f in folders] == ['cam01_json', 'cam02_json', 'cam03_json',
                                         'cam04_json']
    assert len(names) == 21 and det.shape == (4, 100, 25, 3)
    assert list(frames) == list(range(1, 101))  # trc frame k = json frame k - 1
    ids = [BODY_25B_IDS[name] for name in names]
    V, F = det.shape[:2]
    points = det[:, :, ids, :2].reshape(V, F * 21, 2)
    likelihood = det[:, :, ids, 2].reshape(V, F * 21)
    weights = np.where(likelihood >= 0.3, likelihood, 0.0)
    # Pose2Sim ran with undistort_points = false: pinhole P = K [R | t], no distortion
    pinhole = [c.without_distortion() for c in cams]
    X, inliers = triangulate_robust(points, pinhole, weights, threshold_px=15.0, min_views=2,
                                    method='exclusion')
    expected = trc_to_world(trc).reshape(F * 21, 3)
    diff = np.linalg.norm(X - expected, axis=1)
    close = diff < 1e-4
    assert close.sum() >= 2090, f'{close.sum()} of {F * 21} points within 0.1 mm'
    # the others are points Pose2Sim could not triangulate (NaN) and filled by interpolation
    assert np.all(np.isnan(X[~close]))
    assert np.nanmax(diff) < 1e-9
    # all accepted points have a mean reprojection error <= 15 px over the views used
    err = reprojection_error(X, points, pinhole)
    mean = np.nanmean(np.where(inliers, err, np.nan)[:, close], axis=0)
    assert np.all(mean <= 15.0)
    # excluding nothing does not reproduce it: the exclusion rule matters on this data
    plain = triangulate(points, pinhole, weights)
    assert (np.linalg.norm(plain - expected, axis=1) < 1e-4).sum() < close.sum()


def test_dannce_labels_triangulate_to_3d_labels(shared_data):
    import scipy.io
    path = shared_data / 'dannce_markerless_mouse_1' / 'label3d_dannce.mat'
    cams = load_rig(path, image_size=(1152, 1024))
    mat = scipy.io.loadmat(str(path))
    labels = [mat['labelData'][v, 0] for v in range(6)]
    points = np.stack([lab['data_2d'][0, 0].reshape(-1, 2) for lab in labels])  # (6, N, 2)
    truth = labels[0]['data_3d'][0, 0].reshape(-1, 3)
    for lab in labels[1:]:
        np.testing.assert_array_equal(lab['data_3d'][0, 0].reshape(-1, 3), truth)
    X = triangulate(points, cams)
    ok = np.isfinite(truth).all(axis=1)
    assert ok.sum() > 1000
    assert np.all(np.isnan(X[~ok]))
    assert np.abs(X[ok] - truth[ok]).max() < 1e-6  # mm
    # ignoring the skew (as cv2 does) would be off by far more than that
    no_skew = [c.replace(K=c.K * [[1, 0, 1], [1, 1, 1], [1, 1, 1]]) for c in cams]
    assert np.abs(triangulate(points, no_skew)[ok] - truth[ok]).max() > 1e-3


@pytest.mark.parametrize('method', ['exclusion', 'ransac'])
def test_dannce_robust_keeps_clean_labels(shared_data, method):
    path = shared_data / 'dannce_markerless_mouse_1' / 'label3d_dannce.mat'
    import scipy.io
    cams = load_rig(path, image_size=(1152, 1024))
    mat = scipy.io.loadmat(str(path))
    points = np.stack([mat['labelData'][v, 0]['data_2d'][0, 0].reshape(-1, 2)
                       for v in range(6)])[:, :200]
    truth = mat['labelData'][0, 0]['data_3d'][0, 0].reshape(-1, 3)[:200]
    X, inl = triangulate_robust(points, cams, threshold_px=1.0, method=method)
    ok = np.isfinite(truth).all(axis=1)
    assert np.abs(X[ok] - truth[ok]).max() < 1e-6
    assert inl[:, ok].all()
