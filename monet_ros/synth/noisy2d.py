"""Noisy 2D detections of known 3D keypoints, for testing and benchmarking 3D filters
(no ROS): projections with Gaussian pixel noise, gross outliers and dropped views.

Gross outliers are what a detector produces when its peak lands on the wrong limb or on
clutter: half of them are the projection of another keypoint of the same frame (e.g.
the other leg), half are moved 50-150 px (uniform) in a random direction. Their scores
are drawn from the same distribution as the good detections', so a score threshold
cannot find them.
"""
from dataclasses import dataclass

import numpy as np

from monet_ros.geometry.camera import project_views


@dataclass
class Noisy2D:
    """points2d (T, V, C, 2) source px, NaN where dropped; score (T, V, C) in [0.5, 1],
    0 where dropped; outlier (T, V, C) bool: gross outliers; dropped (T, V, C) bool."""
    points2d: np.ndarray
    score: np.ndarray
    outlier: np.ndarray
    dropped: np.ndarray


def noisy_detections(X, cameras, noise_px=1.0, outlier_fraction=0.1, drop_fraction=0.05,
                     offset_px=(50.0, 150.0), seed=0):
    """Noisy2D of X (T, C, 3) world points seen by `cameras` (V Camera).

    noise_px: standard deviation of the pixel noise per axis (px); outlier_fraction: share
    of the (frame, view, keypoint) detections made gross outliers; drop_fraction: share
    left out (NaN); offset_px: (min, max) displacement of the moved outliers (px).
    Deterministic for `seed`."""
    X = np.asarray(X, np.float64)
    if X.ndim != 3 or X.shape[-1] != 3:
        raise ValueError(f'X must be (T, C, 3), got {X.shape}')
    rng = np.random.default_rng(seed)
    uv = project_views(cameras, X)                       # (T, V, C, 2)
    T, V, C = uv.shape[:3]
    points = uv + rng.normal(0.0, noise_px, uv.shape)
    outlier = rng.random((T, V, C)) < outlier_fraction
    swap = outlier & (rng.random((T, V, C)) < 0.5)
    if C > 1:                                        # another keypoint's projection
        other = (np.arange(C) + rng.integers(1, C, (T, V, C))) % C
        swapped = np.take_along_axis(uv, other[..., None], axis=2)
        points = np.where(swap[..., None], swapped + rng.normal(0.0, noise_px, uv.shape),
                          points)
    else:
        swap[:] = False
    moved = outlier & ~swap
    angle = rng.uniform(0, 2 * np.pi, (T, V, C))
    radius = rng.uniform(offset_px[0], offset_px[1], (T, V, C))
    shift = np.stack([np.cos(angle), np.sin(angle)], -1) * radius[..., None]
    points = np.where(moved[..., None], uv + shift, points)
    dropped = rng.random((T, V, C)) < drop_fraction
    points[dropped] = np.nan
    score = np.where(dropped, 0.0, rng.uniform(0.5, 1.0, (T, V, C)))
    return Noisy2D(points2d=points, score=score, outlier=outlier & ~dropped, dropped=dropped)
