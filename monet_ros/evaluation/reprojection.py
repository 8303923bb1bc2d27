"""Multiview consistency: triangulate every view without RANSAC and project back.

Two figures (both in original image pixels):
- consistency: distance from each view's detection to the reprojection of the point
  triangulated from all views' detections (the paper's reprojection error: zero when the
  detections agree geometrically);
- ground truth: distance from that reprojection to the ground-truth 2D keypoint
  (the projection of the ground-truth 3D keypoint), i.e. the accuracy of the fused 3D.
"""
from dataclasses import dataclass

import numpy as np

from monet_ros.geometry import project_views, reprojection_error, triangulate


@dataclass(frozen=True)
class ErrorStats:
    """mean / std / median of `count` finite values; failures: finite values beyond the
    limit given to `of` (counted apart, in none of the figures)."""
    mean: float
    std: float
    median: float
    count: int
    failures: int = 0

    @classmethod
    def of(cls, values, limit=None):
        """Stats of the finite values; limit (broadcastable to values, e.g. (V, 1) px: each
        view's image diagonal): larger values are failures, counted and left out (a badly
        trained model's triangulation can reproject 1e15 px away, which no mean survives)."""
        v = np.asarray(values, dtype=np.float64)
        finite = np.isfinite(v)
        failed = np.zeros_like(finite)
        if limit is not None:
            failed = finite & (v > np.broadcast_to(limit, v.shape))
        v = v[finite & ~failed]
        failures = int(failed.sum())
        if v.size == 0:
            return cls(float('nan'), float('nan'), float('nan'), 0, failures)
        return cls(float(v.mean()), float(v.std()), float(np.median(v)), int(v.size),
                   failures)

    def __str__(self):
        return f'{self.mean:.2f} +- {self.std:.2f}'


@dataclass(frozen=True)
class ReprojectionResult:
    """points3d (T, C, 3); consistency (T, V, C) px; gt_error (T, V, C) px or None;
    error3d (T, C) world units or None; summary ErrorStats of each; diagonal (V,) px: each
    view's image diagonal, beyond which a reprojection error is a failure (capped_stats)."""
    points3d: np.ndarray
    consistency: np.ndarray
    gt_error: np.ndarray
    error3d: np.ndarray
    diagonal: np.ndarray = None

    def capped_stats(self, errors):
        """ErrorStats of a (T, V, C) px error array with the errors beyond each view's image
        diagonal counted as failures, apart from the figures."""
        return ErrorStats.of(errors, None if self.diagonal is None
                             else self.diagonal[None, :, None])

    @property
    def consistency_stats(self):
        return ErrorStats.of(self.consistency)

    @property
    def gt_stats(self):
        return ErrorStats.of(self.gt_error) if self.gt_error is not None else None

    @property
    def error3d_stats(self):
        return ErrorStats.of(self.error3d) if self.error3d is not None else None


def multiview_reprojection(detections, cameras, gt3d=None):
    """Triangulate (no RANSAC) and measure reprojection errors, all instants in one batch.

    detections: (T, V, C, 2) image pixels of each view's detection, NaN = missing.
    cameras: V geometry.Camera. gt3d: (T, C, 3) ground-truth points or None.
    The consistency error is taken over the views that took part in the triangulation;
    the ground-truth error over every view where the ground truth projects
    (the points count as detected only when triangulated from >= 2 views).
    """
    det = np.asarray(detections, dtype=np.float64)
    if det.ndim != 4 or det.shape[-1] != 2 or det.shape[1] != len(cameras):
        raise ValueError(f'detections must be (T, V={len(cameras)}, C, 2), got {det.shape}')
    T, V, C, _ = det.shape
    flat = det.transpose(1, 0, 2, 3).reshape(V, T * C, 2)               # (V, T*C, 2)
    X = triangulate(flat, cameras)                                     # (T*C, 3)
    consistency = reprojection_error(X, flat, cameras)                 # (V, T*C)
    consistency = consistency.reshape(V, T, C).transpose(1, 0, 2)
    gt_error = error3d = None
    if gt3d is not None:
        gt = np.asarray(gt3d, dtype=np.float64)
        if gt.shape != (T, C, 3):
            raise ValueError(f'gt3d must be (T={T}, C={C}, 3), got {gt.shape}')
        gt_flat = gt.reshape(T * C, 3)
        gt2d = project_views(cameras, gt_flat)                         # (V, T*C, 2)
        gt_error = reprojection_error(X, gt2d, cameras).reshape(V, T, C).transpose(1, 0, 2)
        error3d = np.linalg.norm(X - gt_flat, axis=-1).reshape(T, C)
    diagonal = np.array([np.hypot(c.width, c.height) for c in cameras], np.float64)
    return ReprojectionResult(X.reshape(T, C, 3), consistency, gt_error, error3d, diagonal)

