"""select_candidates: which of K candidates per view to triangulate, against known points."""
from helpers.scenes import cv2_project, ring_rig
import numpy as np
import pytest

from monet_ros.geometry import select_candidates


def _scene(rng, count=4, keypoints=14):
    rig = ring_rig(count)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(keypoints, 3))
    uv = np.stack([cv2_project(cam, X) for cam in rig])        # OpenCV, not our projection
    return rig, X, uv


def test_the_true_candidate_is_chosen_wherever_it_lies():
    """The true projection hidden at a random index among 3 candidates (the others 40-200 px
    away): chosen in every view; a view without it supports nothing and gets 0."""
    rng = np.random.default_rng(0)
    rig, X, uv = _scene(rng)
    V, N, K = len(rig), len(X), 3
    angle = rng.uniform(0, 2 * np.pi, (V, N, K))
    radius = rng.uniform(40, 200, (V, N, K))
    offsets = radius[..., None] * np.stack([np.cos(angle), np.sin(angle)], -1)
    points = uv[:, :, None] + offsets
    truth = rng.integers(0, K, (V, N))
    np.put_along_axis(points, truth[..., None, None], uv[:, :, None], axis=2)
    points[3, 5] = uv[3, 5] + np.array([[80.0, 0], [0, 90], [-70, 0]])   # no true candidate
    weights = rng.uniform(0.3, 1.0, (V, N, K))
    choice, support = select_candidates(points, rig, weights, threshold_px=5.0)
    expected = truth.copy()
    expected[3, 5] = 0
    np.testing.assert_array_equal(choice, expected)
    assert support.sum() == V * N - 1 and not support[3, 5]


def test_a_pair_meeting_behind_the_cameras_is_not_chosen():
    """Three views; candidate 0 of each (the stronger) is the projection of a point behind
    all three cameras: its rays meet there and reproject with 0 px, so only cheirality
    tells it from the true point (candidate 1, weaker)."""
    rng = np.random.default_rng(1)
    rig = ring_rig(16)[:3]      # 22.5 degrees apart: the backward view cones overlap
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(6, 3))
    centres = np.stack([-cam.R.T @ cam.t for cam in rig])
    outward = centres.mean(axis=0) - np.array([0.0, 0.0, 1.0])
    behind = centres.mean(axis=0) + 12.0 * outward / np.linalg.norm(outward)
    behind = behind + rng.normal(0, 0.05, (6, 3))
    assert all(((cam.R @ behind.T).T + cam.t)[:, 2].max() < 0 for cam in rig)
    fake = np.stack([cv2_project(cam, behind) for cam in rig])   # behind: still pixels
    assert (np.abs(fake - [320, 240]) < [320, 240]).all()            # inside the images
    true = np.stack([cv2_project(cam, X) for cam in rig])
    points = np.stack([fake, true], axis=2)                 # (V, N, 2, 2)
    weights = np.broadcast_to([1.0, 0.5], points.shape[:3])
    choice, support = select_candidates(points, rig, weights, threshold_px=5.0)
    np.testing.assert_array_equal(choice, 1)
    assert support.all()


def test_bad_shapes_are_named():
    rig, _, uv = _scene(np.random.default_rng(2))
    with pytest.raises(ValueError, match=r'points2d must have shape \(V=4, N, K, 2\)'):
        select_candidates(uv, rig)
    with pytest.raises(ValueError, match='weights must have shape'):
        select_candidates(uv[:, :, None], rig, np.ones((4, 14)))
