"""Reprojection statistics against an independent OpenCV computation on a hand case."""
import cv2
from helpers.ring import random_points, ring_rig
import numpy as np

from monet_ros.evaluation.reprojection import ErrorStats, multiview_reprojection


def test_exact_detections_have_zero_error_and_recover_ground_truth():
    cams = ring_rig(4)
    X = random_points(5, seed=2)[None].repeat(2, axis=0)                # (T=2, C=5, 3)
    det = np.stack([np.stack([c.project(X[t]) for c in cams]) for t in range(2)])
    result = multiview_reprojection(det, cams, gt3d=X)
    assert result.consistency_stats.mean < 1e-6
    assert result.gt_stats.mean < 1e-6
    np.testing.assert_allclose(result.points3d, X, atol=1e-8)


def test_two_view_offset_matches_opencv_triangulate_and_project():
    cams = ring_rig(2, radius=3.0)
    X = random_points(4, seed=7)
    det = np.stack([c.project(X) for c in cams])                        # (V, C, 2)
    det[0, :, 0] += 3.0                                                 # 3 px shift in view 0
    result = multiview_reprojection(det[None], cams, gt3d=X[None])
    # Independent: OpenCV's two-view DLT, then projectPoints.
    Xh = cv2.triangulatePoints(cams[0].P, cams[1].P, det[0].T, det[1].T)
    X_cv = (Xh[:3] / Xh[3]).T
    np.testing.assert_allclose(result.points3d[0], X_cv, atol=1e-6)
    expected = []
    expected_gt = []
    for v, c in enumerate(cams):
        proj, _ = cv2.projectPoints(X_cv, cv2.Rodrigues(c.R)[0], c.t, c.K, c.dist)
        expected.append(np.linalg.norm(proj[:, 0] - det[v], axis=1))
        expected_gt.append(np.linalg.norm(proj[:, 0] - c.project(X), axis=1))
    np.testing.assert_allclose(result.consistency[0], np.stack(expected), atol=1e-6)
    np.testing.assert_allclose(result.gt_error[0], np.stack(expected_gt), atol=1e-6)
    values = np.stack(expected).ravel()
    assert abs(result.consistency_stats.mean - values.mean()) < 1e-9
    assert abs(result.consistency_stats.std - values.std()) < 1e-9
    assert 0.5 < result.consistency_stats.mean < 3.0


def test_missing_views_and_empty_stats():
    cams = ring_rig(3)
    X = random_points(2, seed=1)
    det = np.stack([c.project(X) for c in cams])[None]
    det[0, 1:, 1] = np.nan                                              # keypoint 1 in 1 view
    result = multiview_reprojection(det, cams)
    assert np.isnan(result.points3d[0, 1]).all()
    assert np.isnan(result.consistency[0, :, 1]).all()
    assert result.consistency_stats.count == 3
    assert ErrorStats.of([np.nan]).count == 0
