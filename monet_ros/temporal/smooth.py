"""The offline 3D filters behind `monet process --filter` and `monet triangulate
--filter`: one entry point over a whole recording's fused results (no ROS).

smooth_points(...) takes the frame-by-frame robust triangulation (X, its confidence) and
the 2D detections it came from, and returns a Smoothed: the filtered points, a per-joint
confidence, the reprojection error / inlier views of the filtered points against the same
detections, the per-frame change filtered - raw (mm) and which frames were bridged.
"""
from dataclasses import dataclass, field
import time

import numpy as np

from monet_ros.geometry.camera import project_views
from monet_ros.geometry.units import rig_units, to_mm
from monet_ros.temporal.bones import bone_lengths
from monet_ros.temporal.config import FilterConfig
from monet_ros.temporal.kalman import kalman_smooth
from monet_ros.temporal.optim import optimise


@dataclass
class Smoothed:
    """A filter's output over T frames and C keypoints.

    method: FilterConfig.method; X (T, C, 3) filtered points (units), NaN where nothing was
    kept; raw (T, C, 3) the input; score (T, C) confidence in [0, 1] (kalman: the fused
    confidence where the point was accepted, 0 where gated out or bridged; optim: mean over
    the views of score x robust loss weight, 0 where no view supports it); error (T, C)
    mean reprojection error (px) of the filtered point over the views within threshold_px;
    ncams (T, C) those views; change_mm (T, C) |filtered - raw| (mm, NaN where either is
    missing); bridged (T, C) bool: filtered point where the raw one was missing (a gap of
    at most max_gap_s); rejected (T, C) bool: raw point the Kalman gate left out;
    lengths (B,) bone lengths used (units); seconds: wall time; notes: what was left out;
    units: the rig's length unit ('m', 'cm', 'mm'), that of X, raw and lengths."""
    method: str
    X: np.ndarray
    raw: np.ndarray
    score: np.ndarray
    error: np.ndarray
    ncams: np.ndarray
    change_mm: np.ndarray
    bridged: np.ndarray
    rejected: np.ndarray
    lengths: np.ndarray
    seconds: float = 0.0
    notes: list = field(default_factory=list)
    units: str = 'm'

    def summary(self):
        """One line: the filter, points kept / bridged / rejected / emptied, median and
        p90 change (mm)."""
        raw = np.isfinite(self.raw).all(-1)
        out = np.isfinite(self.X).all(-1)
        change = self.change_mm[np.isfinite(self.change_mm)]
        med, p90 = (np.median(change), np.percentile(change, 90)) if change.size else (0, 0)
        return (f'filter {self.method}: {int(out.sum())} points out of {int(raw.sum())} '
                f'triangulated; {int(self.bridged.sum())} bridged over gaps, '
                f'{int(self.rejected.sum())} gated out as outliers, '
                f'{int((raw & ~out).sum())} left empty (gaps longer than the limit or '
                f'isolated); change filtered - raw median {med:.1f} mm, p90 {p90:.1f} mm; '
                f'{self.seconds:.2f} s')


def reprojection_stats(X, points2d, score, cameras, confidence_threshold, threshold_px):
    """(error (T, C) mean px over the views within threshold_px, ncams (T, C)) of points
    X (T, C, 3) against detections points2d (T, V, C, 2) with score (T, V, C) >=
    confidence_threshold."""
    proj = project_views(cameras, X)                                   # (T, V, C, 2)
    with np.errstate(invalid='ignore'):
        err = np.linalg.norm(proj - points2d, axis=-1)
        used = (score >= confidence_threshold) & (err <= threshold_px)
    ncams = used.sum(axis=1)
    with np.errstate(invalid='ignore', divide='ignore'):
        error = np.where(ncams > 0, np.where(used, err, 0.0).sum(1) / np.maximum(ncams, 1),
                         np.nan)
    return error, ncams


def smooth_points(X, score, points2d, conf2d, cameras, stamps_ns, edges=(),
                  config=None, error=None, progress=False):
    """Smoothed of a recording.

    X (T, C, 3) frame-by-frame triangulated points (in the cameras' length unit,
    Camera.units: the filters' mm and m/s^2 settings are converted to it; NaN = missing);
    score (T, C) their
    confidence; points2d (T, V, C, 2) the detections (source px, NaN = missing); conf2d
    (T, V, C) their scores; cameras: V Camera; stamps_ns (T,) increasing; edges: (B, 2)
    keypoint index pairs of the skeleton's bones (optim's bone term; none: no bone term);
    config: FilterConfig with method 'kalman' or 'optim' (None: kalman); error (T, C): the mean
    reprojection error (px) of each raw point over its inlier views (fusion's), None =
    computed here (Kalman measurement noise grows with it); progress: optim's iterations
    as a tqdm bar on stderr. Raises ValueError on shapes."""
    start = time.perf_counter()
    config = config or FilterConfig(method='kalman')
    X = np.asarray(X, np.float64)
    T, C = X.shape[:2]
    points2d = np.asarray(points2d, np.float64)
    conf2d = np.nan_to_num(np.asarray(conf2d, np.float64), nan=0.0)
    if points2d.shape != (T, len(cameras), C, 2) or conf2d.shape != points2d.shape[:3]:
        raise ValueError(f'points2d must be (T={T}, V={len(cameras)}, C={C}, 2) and its '
                         f'scores (T, V, C), got {points2d.shape} and {conf2d.shape}')
    score = np.nan_to_num(np.asarray(score, np.float64), nan=0.0)
    if config.method not in ('kalman', 'optim'):
        raise ValueError(f"filter method must be 'kalman' or 'optim', got {config.method!r}")
    notes = []
    if error is None:
        error = reprojection_stats(X, points2d, conf2d, cameras, config.confidence_threshold,
                                   config.threshold_px)[0]
    noise = 1.0 + (np.nan_to_num(np.asarray(error, np.float64), nan=0.0)
                   / config.reprojection_px) ** 2
    units = rig_units(cameras)
    kalman = kalman_smooth(X, stamps_ns, config, noise, units)
    rejected = kalman.rejected
    lengths = np.zeros(0)
    if config.method == 'kalman':
        out = kalman.X
        conf = np.where(kalman.accepted, score, 0.0)
    else:
        edges = np.asarray(edges, np.int64).reshape(-1, 2)
        if len(edges):
            # confident: accepted by the gate with most of the views
            lengths = bone_lengths(X, edges, kalman.accepted & (score >= 0.5))
            unseen = int(np.isnan(lengths).sum())
            if unseen:
                notes.append(f'{unseen} bones never triangulated: no bone term for them')
        else:
            notes.append('no skeleton bones: no bone-length term')
        keep = np.isfinite(kalman.X).all(-1)
        result = optimise(kalman.X, keep, points2d, conf2d, cameras, stamps_ns, edges,
                          lengths, config, progress=progress)
        out, conf = result.X, result.support
        rejected = np.zeros_like(rejected)      # the robust loss weighs, nothing is gated
    finite = np.isfinite(out).all(-1)
    raw_ok = np.isfinite(X).all(-1)
    error, ncams = reprojection_stats(out, points2d, conf2d, cameras,
                                      config.confidence_threshold, config.threshold_px)
    with np.errstate(invalid='ignore'):
        change = to_mm(np.linalg.norm(out - X, axis=-1), units)
    return Smoothed(method=config.method, X=out, raw=X, score=np.where(finite, conf, np.nan),
                    error=np.where(finite, error, np.nan),
                    ncams=np.where(finite, ncams, 0), change_mm=change,
                    bridged=finite & ~raw_ok, rejected=rejected & raw_ok, lengths=lengths,
                    seconds=time.perf_counter() - start, notes=notes, units=units)
