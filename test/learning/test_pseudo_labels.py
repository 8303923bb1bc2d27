"""Pseudo-labels: spatial augmentation, bootstrapping and optical-flow tracking on exact data."""
from helpers.ring import random_points, ring_rig
import numpy as np

from monet_ros.learning.pseudo_labels import (
    TrackingConfig,
    bootstrap_pseudo_labels,
    patch_ncc,
    spatial_pseudo_labels,
    spatiotemporal_pseudo_labels,
)


def projections(cams, X):
    """(T, C, 3) -> (T, V, C, 2)"""
    return np.stack([np.stack([c.project(x) for c in cams]) for x in X])


def test_spatial_augmentation_reproduces_ground_truth_projections():
    cams = ring_rig(6, dist=np.array([-0.1, 0.02, 0.0, 0.0, 0.0]))
    X = np.stack([random_points(5, seed=s) for s in range(3)])             # (T=3, C=5, 3)
    truth = projections(cams, X)
    labels = np.full_like(truth, np.nan)
    labels[0, :2] = truth[0, :2]                  # instant 0: views 0, 1 labelled
    labels[1, [0, 3, 5]] = truth[1, [0, 3, 5]]    # instant 1: views 0, 3, 5
    labels[2, 4, 1] = truth[2, 4, 1]              # instant 2: one view only -> nothing
    result = spatial_pseudo_labels(labels, cams)
    np.testing.assert_allclose(result.points[:2], truth[:2], atol=1e-6)
    np.testing.assert_allclose(result.points3d[:2], X[:2], atol=1e-8)
    assert np.isnan(result.points[2]).all()
    assert result.count == 2 * 6 * 5


def test_spatial_labels_outside_the_image_are_dropped():
    cams = ring_rig(3, width=160, height=120)
    X = np.array([[[0.0, 0.0, 1.0], [0.0, 0.0, 4.0]]])                    # 2nd far above
    truth = projections(cams, X)
    result = spatial_pseudo_labels(truth, cams)
    assert np.isfinite(result.points[0, :, 0]).all()
    assert np.isnan(result.points[0, :, 1]).all()
    assert np.isfinite(result.points3d[0, 1]).all()


def test_bootstrap_rejects_outlier_view_and_low_confidence():
    cams = ring_rig(6)
    X = random_points(4, seed=3)[None]
    det = projections(cams, X)
    truth = det.copy()
    det[0, 2, 0] += 40.0                          # view 2 wrong on keypoint 0
    conf = np.ones(det.shape[:3])
    conf[0, :4, 3] = 0.1                          # keypoint 3 confident in 2 views only
    result = bootstrap_pseudo_labels(det, conf, cams, min_confidence=0.5, threshold_px=5,
                                     min_views=3)
    np.testing.assert_allclose(result.points[0, :, :3], truth[0, :, :3], atol=1e-6)
    assert np.isnan(result.points[0, :, 3]).all()


def render(cams, X, sizes, blank=()):
    """Frames (T, V, H, W, 3): a Gaussian blob per keypoint on a dark background."""
    T = len(X)
    H, W = cams[0].height, cams[0].width
    yy, xx = np.mgrid[0:H, 0:W]
    frames = np.zeros((T, len(cams), H, W, 3), np.uint8)
    for t in range(T):
        for v, c in enumerate(cams):
            if (t, v) in blank:
                continue
            img = np.zeros((H, W))
            for (u, w), s in zip(c.project(X[t]), sizes):
                img += np.exp(-((xx - u) ** 2 + (yy - w) ** 2) / (2 * s ** 2))
            frames[t, v] = np.clip(img * 220, 0, 255).astype(np.uint8)[..., None]
    return frames


def test_spatiotemporal_tracks_moving_points_and_drops_bad_views():
    cams = ring_rig(5, width=200, height=160, focal=180.0)
    T = 7
    base = np.array([[0.0, 0.0, 1.0], [0.35, 0.1, 0.8], [-0.3, -0.2, 1.3]])
    velocity = np.array([0.02, -0.015, 0.01])
    X = base[None] + np.arange(T)[:, None, None] * velocity                 # (T, C, 3)
    frames = render(cams, X, sizes=[3.0, 3.5, 4.0], blank={(4, 2)})
    seeds = np.full_like(X, np.nan)
    seeds[3] = X[3]
    result = spatiotemporal_pseudo_labels(frames, cams, seeds,
                                          TrackingConfig(horizon=3, min_views=3))
    truth = projections(cams, X)
    err = np.linalg.norm(result.points - truth, axis=-1)                   # (T, V, C)
    assert np.nanmax(err) < 1.0, np.nanmax(err)
    found = np.isfinite(err)
    assert found[3].all()                                                  # the seed instant
    assert found[[0, 1, 2, 5, 6]].mean() > 0.9                             # tracked both ways
    assert not found[4, 2].any()                                           # blank view dropped
    assert found[4, [0, 1, 3, 4]].all()
    assert np.nanmax(np.linalg.norm(result.points3d - X, axis=-1)) < 0.01


def test_patch_ncc_is_one_for_identical_patches_and_low_for_flat():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 255, size=(40, 40)).astype(np.uint8)
    p = np.array([[20.0, 20.0], [10.5, 12.25]])
    np.testing.assert_allclose(patch_ncc(a, p, a, p, 7), 1.0, atol=1e-9)
    shifted = np.roll(a, 3, axis=1)
    np.testing.assert_allclose(patch_ncc(a, p, shifted, p + [3, 0], 7), 1.0, atol=1e-6)
    assert patch_ncc(a, p, np.zeros_like(a), p, 7).max() == 0.0


def test_tracks_say_how_far_they_ran_from_their_seed():
    """frames_from_seed: 0 at the seed, |t - seed| along a track, the nearer seed's length
    where two tracks reach an instant, inf where none does."""
    cams = ring_rig(5, width=200, height=160, focal=180.0)
    T = 9
    base = np.array([[0.0, 0.0, 1.0], [0.35, 0.1, 0.8], [-0.3, -0.2, 1.3]])
    X = base[None] + np.arange(T)[:, None, None] * np.array([0.02, -0.015, 0.01])
    frames = render(cams, X, sizes=[3.0, 3.5, 4.0])
    seeds = np.full_like(X, np.nan)
    seeds[[1, 6]] = X[[1, 6]]
    seeds[6, 2] = np.nan                           # keypoint 2 seeded at instant 1 only
    result = spatiotemporal_pseudo_labels(frames, cams, seeds,
                                          TrackingConfig(horizon=3, min_views=3))
    d = result.frames_from_seed
    t = np.arange(T)[:, None]
    nearest = np.minimum(np.abs(t - 1), np.abs(t - 6))                      # keypoints 0, 1
    np.testing.assert_array_equal(d[:, :2], np.where(nearest <= 3, nearest, np.inf)[:, [0, 0]])
    np.testing.assert_array_equal(d[:, 2], np.where(np.abs(t[:, 0] - 1) <= 3,
                                                    np.abs(t[:, 0] - 1), np.inf))
    # a cell holds a label exactly where a track reached it
    np.testing.assert_array_equal(np.isfinite(result.points[..., 0]).any(axis=1),
                                  np.isfinite(d))
    # agreement: where both seeds' tracks reach (instants 3, 4 of keypoints 0, 1; exact
    # renderings, so they agree to a pixel), NaN where one track only
    both = np.zeros((T, 3), bool)
    both[[3, 4], :2] = True
    agree = result.agreement                                                # (T, V, C)
    assert np.isfinite(agree).any(axis=1).tolist() == both.tolist()
    assert np.nanmax(agree) < 1.0
