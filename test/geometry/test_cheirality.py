"""Cheirality in every triangulation path: a point behind a used camera is never published.

The stereo pair of issue 14 (12 cm baseline, both cameras looking along +z, a keypoint seen
at (310, 373.33) in `left` and (330, 373.33) in `right`: a left/right swap). The rays meet
3 m BEHIND both cameras with 0 px reprojection error; OpenCV's triangulatePoints (the
independent reference) finds that point, so the observations are exactly consistent - only
cheirality can refuse them.
"""
import cv2
from helpers.rigs import look_at
import numpy as np
import pytest

from monet_ros.fusion import FusionConfig, fuse_heatmaps, fuse_points
from monet_ros.geometry import Camera, triangulate, triangulate_robust
from monet_ros.learning.pseudo_labels import bootstrap_pseudo_labels, spatial_pseudo_labels
from monet_ros.models.heatmaps import render_heatmaps

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
OBS = np.array([[[310.0, 373.0 + 1 / 3]], [[330.0, 373.0 + 1 / 3]]])  # (V=2, N=1, 2)


def _stereo():
    return [Camera('left', K, [], np.eye(3), [0.06, 0.0, 0.0], 640, 480),
            Camera('right', K, [], np.eye(3), [-0.06, 0.0, 0.0], 640, 480)]


def test_reference_point_is_behind_both_cameras():
    """Independent check of the case: OpenCV's DLT puts the point 3 m behind both cameras."""
    cams = _stereo()
    h = cv2.triangulatePoints(cams[0].P, cams[1].P, OBS[0].T, OBS[1].T)
    X = (h[:3] / h[3]).ravel()
    assert np.allclose(X, [0.0, -0.8, -3.0], atol=1e-6)
    assert all(cam.to_camera(X[None])[0, 2] < 0 for cam in cams)


def test_triangulate_refuses_point_behind_cameras():
    assert np.isnan(triangulate(OBS, _stereo())).all()


@pytest.mark.parametrize('method', ['exclusion', 'ransac'])
def test_triangulate_robust_refuses_point_behind_cameras(method):
    X, inliers = triangulate_robust(OBS, _stereo(), method=method)
    assert np.isnan(X).all()
    assert not inliers.any()


def test_fuse_points_gives_nan_and_zero_views():
    result = fuse_points(OBS, np.ones((2, 1)), _stereo())
    assert np.isnan(result.X).all()
    assert result.num_views.tolist() == [0]
    assert not result.inliers.any()


def test_fuse_heatmaps_gives_nan_and_zero_views():
    cams = _stereo()
    heat = render_heatmaps(OBS / 8.0, (60, 80), 1.5)
    heat = np.asarray(heat, np.float32)  # (2, 1, 60, 80)
    S = np.diag([1 / 8.0, 1 / 8.0, 1.0])
    result = fuse_heatmaps(heat, np.stack([S @ K, S @ K]), cams)
    assert np.allclose(result.points2d, OBS, atol=0.2)  # the peaks decode where drawn
    assert np.isnan(result.X).all() and result.num_views.tolist() == [0]


def test_pseudo_labels_skip_point_behind_cameras():
    labels = OBS[None]  # (T=1, V=2, C=1, 2)
    spatial = spatial_pseudo_labels(labels, _stereo())
    assert np.isnan(spatial.points).all()
    boot = bootstrap_pseudo_labels(labels, np.ones((1, 2, 1)), _stereo(), min_views=2)
    assert np.isnan(boot.points).all()


def _ring_with_backward_camera():
    """3 cameras looking at the origin from 3 m, and a 4th at (0, 0, 3) looking AWAY."""
    cams = []
    for i, angle in enumerate(np.radians([0.0, 120.0, 240.0])):
        center = np.array([3 * np.cos(angle), 3 * np.sin(angle), 0.5])
        R = look_at(center, np.zeros(3))
        cams.append(Camera(f'cam{i}', K, [], R, -R @ center, 640, 480))
    center = np.array([0.0, 0.0, 3.0])
    R = look_at(center, np.array([0.0, 0.0, 6.0]), up=(0.0, 1.0, 0.0))
    cams.append(Camera('away', K, [], R, -R @ center, 640, 480))
    return cams


@pytest.mark.parametrize('method, limit', [('exclusion', 20), ('exclusion', 1),
                                           ('ransac', 20), ('ransac', 2)])
def test_view_behind_is_an_outlier_the_rest_triangulate(method, limit):
    """The backward camera's P maps the point to a pixel that fits the DLT exactly (0 px),
    yet the point is behind it: it must be left out, the other 3 views kept."""
    cams = _ring_with_backward_camera()
    X_true = np.array([[0.1, -0.2, 0.3], [-0.2, 0.1, 0.0]])
    h = np.einsum('vij,nj->vni', np.stack([c.P for c in cams]), np.c_[X_true, np.ones(2)])
    obs = h[..., :2] / h[..., 2:]  # pinhole projections, the backward one included
    assert (cams[3].to_camera(X_true)[:, 2] < 0).all()
    assert np.all((obs[3] > 0) & (obs[3] < [640, 480]))  # a plausible pixel
    # limit: the exhaustive subset / pair search, or the worst-view / random-pair fallback
    X, inliers = triangulate_robust(obs, cams, method=method, min_views=2, max_subsets=limit,
                                    max_hypotheses=limit)
    assert np.allclose(X, X_true, atol=1e-6)
    assert inliers.tolist() == [[True, True], [True, True], [True, True], [False, False]]
    # plain DLT: the backward view is left out and the point solved again from the rest
    assert np.allclose(triangulate(obs, cams), X_true, atol=1e-6)
    result = fuse_points(obs, np.ones((4, 2)), cams, FusionConfig(min_views=3))
    assert result.num_views.tolist() == [3, 3]
    with_four = fuse_points(obs, np.ones((4, 2)), cams, FusionConfig(min_views=4))
    assert np.isnan(with_four.X).all() and with_four.num_views.tolist() == [0, 0]
