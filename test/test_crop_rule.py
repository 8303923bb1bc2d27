"""The crop rule: boxes around the projection of the last 3D keypoints (robust to a wild
joint), fallbacks, the tracked state over a stream."""
from helpers.scenes import cv2_project, ring_rig
import numpy as np

from monet_ros.crop_rule import TrackedCrops, TrackedRule, crop_boxes, subject_boxes


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


def test_one_wild_joint_does_not_blow_the_box_up():
    rig = ring_rig(4)
    X = np.random.default_rng(1).uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))
    wild = X.copy()
    wild[5] = X[5] + np.array([0.0, 0.0, 1.5])   # 1.5 m off: well outside the body
    boxes = subject_boxes(rig, wild, margin=0.25)
    for cam, box in zip(rig, boxes):
        uv = cv2_project(cam, np.delete(X, 5, axis=0))          # the other 13 joints
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        pad = 0.25 * (hi - lo)
        np.testing.assert_allclose(box[:2], lo - pad + 0.5, atol=1e-6)
        np.testing.assert_allclose(box[2:], hi + pad + 0.5, atol=1e-6)
    untrimmed = subject_boxes(rig, wild, margin=0.25, trim=0)
    assert ((untrimmed[:, 3] - untrimmed[:, 1]) > 1.5 * (boxes[:, 3] - boxes[:, 1])).all()


def test_tracked_state_uses_fresh_keypoints_of_earlier_stamps_only():
    rig = ring_rig(2)
    X = np.random.default_rng(2).uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))
    tracker = TrackedCrops(TrackedRule(timeout_ns=100))
    full = crop_boxes(rig, None)
    np.testing.assert_array_equal(tracker.boxes(rig, 0), full)          # nothing yet
    tracker.update(X, 1000)
    # float32, as /monet/keypoints3d carries them
    want = crop_boxes(rig, X.astype(np.float32).astype(np.float64))
    np.testing.assert_array_equal(tracker.boxes(rig, 1050), want)
    np.testing.assert_array_equal(tracker.boxes(rig, 1100), want)
    np.testing.assert_array_equal(tracker.boxes(rig, 1101), full)       # too old
    np.testing.assert_array_equal(tracker.boxes(rig, 999), full)        # from the future
    fallback = np.array([[1, 2, 30, 40], [5, 6, 70, 80]], float)
    np.testing.assert_array_equal(tracker.boxes(rig, 5000, fallback), fallback)
