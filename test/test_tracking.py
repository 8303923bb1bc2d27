"""Crop boxes around the projection of the last 3D keypoints, with fallbacks."""
from helpers.scenes import cv2_project, ring_rig
import numpy as np

from monet_ros.tracking import crop_boxes, subject_boxes


def test_boxes_bound_the_opencv_projections_with_margin():
    rig = ring_rig(3)
    X = np.random.default_rng(0).uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))
    X[3] = np.nan
    boxes = subject_boxes(rig, X, margin=0.25, min_points=3)
    for cam, box in zip(rig, boxes):
        uv = cv2_project(cam, X[np.isfinite(X).all(axis=1)])
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        pad = 0.25 * (hi - lo)
        np.testing.assert_allclose(box[:2], lo - pad + 0.5, atol=1e-6)
        np.testing.assert_allclose(box[2:], hi + pad + 0.5, atol=1e-6)


def test_points_behind_or_too_few_fall_back():
    rig = ring_rig(2)
    behind = rig[0].center + (rig[0].center - np.array([0.0, 0.0, 1.0]))  # behind cam0
    X = np.stack([behind + d for d in np.eye(3) * 0.05])
    assert np.isnan(subject_boxes(rig[:1], X)).all()
    boxes = crop_boxes(rig, X, fallback_box=(10, 20, 110, 220))
    np.testing.assert_array_equal(boxes[0], (10, 20, 110, 220))
    boxes = crop_boxes(rig, None)
    np.testing.assert_array_equal(boxes, [[0, 0, 640, 480]] * 2)
