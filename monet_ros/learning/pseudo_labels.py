"""Pseudo-labels for the paper's baselines: spatial and spatiotemporal augmentation and
bootstrapping (Simon et al. 2017). All points are in original image pixels.

- spatial: triangulate the labelled views of an instant, project into every view;
- spatiotemporal: from the 3D points of labelled instants, track each keypoint forward and
  backward in time with pyramidal Lucas-Kanade flow in every view, RANSAC-triangulate the
  tracked points, and keep a view only when (a) its flow agrees with the projected 3D motion
  (RANSAC inlier), (b) forward-backward flow returns to the start and (c) the image patch
  around the projection matches the previous one (normalised cross-correlation);
- bootstrapping: detections above a confidence, RANSAC triangulation, reprojection into every
  view as labels (round II repeats this with the retrained detector).
"""
from dataclasses import dataclass

import cv2
import numpy as np

from monet_ros.geometry import project_views, triangulate, triangulate_robust


@dataclass(frozen=True)
class PseudoLabels:
    """points (T, V, C, 2) image pixels, NaN = no label; points3d (T, C, 3) NaN = none;
    frames_from_seed (T, C): for tracked labels, how many frames the kept track ran from its
    seed (0 at a seed, inf where none; None for untracked kinds). Tracks drift: their error
    grows with this distance (bench/results/accuracy.md, issue 22). agreement (T, V, C) px:
    for tracked labels, the distance between the kept label and the label of the track of
    another seed that reached the same cell (the next nearest; NaN where no second track):
    two independent tracks that agree verify each other."""
    points: np.ndarray
    points3d: np.ndarray
    frames_from_seed: np.ndarray = None
    agreement: np.ndarray = None

    @property
    def count(self):
        return int(np.isfinite(self.points[..., 0]).sum())


def _inside(points, cameras, margin=0.0):
    """(V, N, 2) -> same with NaN where outside camera v's image (pixel-edge bounds)."""
    out = points.copy()
    for v, cam in enumerate(cameras):
        u, w = out[v, :, 0], out[v, :, 1]
        bad = (u < -0.5 - margin) | (u > cam.width - 0.5 + margin) | \
              (w < -0.5 - margin) | (w > cam.height - 0.5 + margin)
        out[v, bad] = np.nan
    return out


def _in_front(X, cameras):
    """(N, 3) -> (V, N) bool: point in front of each camera."""
    depth = np.stack([cam.to_camera(X)[:, 2] for cam in cameras])
    return depth > 1e-9


def project_to_views(X, cameras):
    """(N, 3) world points -> (V, N, 2) pixels, NaN where missing, behind or outside the image."""
    X = np.asarray(X, dtype=np.float64)
    proj = project_views(cameras, X)
    with np.errstate(invalid='ignore'):
        front = _in_front(np.nan_to_num(X), cameras) & np.all(np.isfinite(X), axis=1)[None]
    proj[~front] = np.nan
    return _inside(proj, cameras)


def spatial_pseudo_labels(labels, cameras):
    """Spatial augmentation.

    labels: (T, V, C, 2) image pixels, NaN = unlabelled view/keypoint.
    Returns PseudoLabels with the projections of the triangulation (>= 2 labelled views)
    into every view where it is visible (labelled views included).
    """
    labels = np.asarray(labels, dtype=np.float64)
    T, V, C, _ = labels.shape
    flat = labels.transpose(1, 0, 2, 3).reshape(V, T * C, 2)
    X = triangulate(flat, cameras)                                        # (T*C, 3)
    points = project_to_views(X, cameras).reshape(V, T, C, 2).transpose(1, 0, 2, 3)
    return PseudoLabels(points, X.reshape(T, C, 3))


def bootstrap_pseudo_labels(detections, confidence, cameras, min_confidence=0.3,
                            threshold_px=10.0, min_views=3):
    """Bootstrapping (Simon et al.): confident detections -> RANSAC triangulation -> labels.

    detections: (T, V, C, 2) image pixels; confidence: (T, V, C).
    Keeps a 3D point when at least `min_views` confident views agree within threshold_px;
    its reprojection into every view where it is visible becomes the label.
    """
    det = np.asarray(detections, dtype=np.float64).copy()
    conf = np.asarray(confidence, dtype=np.float64)
    T, V, C, _ = det.shape
    det[~(conf >= min_confidence)] = np.nan
    flat = det.transpose(1, 0, 2, 3).reshape(V, T * C, 2)
    X, inliers = triangulate_robust(flat, cameras, threshold_px=threshold_px,
                                    min_views=min_views, method='ransac')
    X = np.where((inliers.sum(axis=0) >= min_views)[:, None], X, np.nan)
    points = project_to_views(X, cameras).reshape(V, T, C, 2).transpose(1, 0, 2, 3)
    return PseudoLabels(points, X.reshape(T, C, 3))


@dataclass(frozen=True)
class TrackingConfig:
    """Spatiotemporal tracking parameters (pixels of the original images)."""
    horizon: int = 10               # frames tracked forward and backward from each seed
    window: int = 21                # LK window (px)
    levels: int = 3                 # LK pyramid levels
    forward_backward_px: float = 1.0
    ransac_px: float = 4.0          # RANSAC inlier threshold: flow vs projected 3D motion
    min_views: int = 3
    patch: int = 11                 # appearance patch size (px, odd)
    min_ncc: float = 0.7            # appearance: normalised cross-correlation to keep a view

    def __post_init__(self):
        for name in ('horizon', 'window', 'levels', 'min_views', 'patch'):
            value = getattr(self, name)
            if not isinstance(value, int) or value < (0 if name == 'horizon' else 1):
                raise ValueError(f'TrackingConfig.{name} must be a positive int, got {value!r}')
        if self.patch % 2 == 0:
            raise ValueError(f'TrackingConfig.patch must be odd, got {self.patch}')
        if self.min_views < 2:
            raise ValueError('TrackingConfig.min_views must be >= 2')
        for name in ('forward_backward_px', 'ransac_px'):
            if not getattr(self, name) > 0:
                raise ValueError(f'TrackingConfig.{name} must be > 0')
        if not -1.0 <= self.min_ncc <= 1.0:
            raise ValueError('TrackingConfig.min_ncc must be in [-1, 1]')


def _gray(image):
    image = np.asarray(image)
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


def patch_ncc(gray_a, points_a, gray_b, points_b, size):
    """Normalised cross-correlation of size x size patches (bilinear), batched.

    points_*: (N, 2) pixels (NaN allowed -> NaN score). Returns (N,) in [-1, 1].
    """
    n = len(points_a)
    out = np.full(n, np.nan)
    ok = np.all(np.isfinite(points_a), 1) & np.all(np.isfinite(points_b), 1)
    if not ok.any():
        return out
    r = (size - 1) / 2.0
    offs = np.arange(size, dtype=np.float32) - r
    dy, dx = np.meshgrid(offs, offs, indexing='ij')                        # (s, s)

    def sample(gray, pts):
        mx = (pts[:, 0, None, None] + dx[None]).astype(np.float32).reshape(-1, size)
        my = (pts[:, 1, None, None] + dy[None]).astype(np.float32).reshape(-1, size)
        patches = cv2.remap(gray.astype(np.float32), mx, my, cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REFLECT)
        return patches.reshape(-1, size * size).astype(np.float64)

    a = sample(gray_a, points_a[ok])
    b = sample(gray_b, points_b[ok])
    a -= a.mean(1, keepdims=True)
    b -= b.mean(1, keepdims=True)
    denom = np.sqrt((a * a).sum(1) * (b * b).sum(1))
    out[ok] = np.where(denom > 1e-9, (a * b).sum(1) / np.maximum(denom, 1e-12), 0.0)
    return out


def _flow(gray_a, gray_b, points, config):
    """LK flow with forward-backward check: (N, 2) -> (N, 2), NaN where lost."""
    out = np.full_like(points, np.nan)
    ok = np.all(np.isfinite(points), 1)
    if not ok.any():
        return out
    p0 = points[ok].astype(np.float32).reshape(-1, 1, 2)
    params = dict(winSize=(config.window, config.window), maxLevel=config.levels,
                  criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
    p1, st1, _ = cv2.calcOpticalFlowPyrLK(gray_a, gray_b, p0, None, **params)
    p0b, st2, _ = cv2.calcOpticalFlowPyrLK(gray_b, gray_a, p1, None, **params)
    fb = np.linalg.norm((p0b - p0).reshape(-1, 2), axis=1)
    good = (st1.ravel() == 1) & (st2.ravel() == 1) & (fb <= config.forward_backward_px)
    tracked = np.where(good[:, None], p1.reshape(-1, 2).astype(np.float64), np.nan)
    out[ok] = tracked
    return out


def track_step(grays_a, grays_b, X, cameras, config):
    """Move 3D keypoints one frame: flow in every view, RANSAC-triangulate, verify.

    grays_*: V grayscale images at the current and the next instant; X (C, 3) current points.
    Returns (X_next (C, 3), labels (V, C, 2) kept views' projections, kept (V, C) bool).
    """
    V = len(cameras)
    start = project_to_views(X, cameras)                                  # (V, C, 2)
    flowed = np.stack([_flow(grays_a[v], grays_b[v], start[v], config) for v in range(V)])
    X_next, inliers = triangulate_robust(flowed, cameras, threshold_px=config.ransac_px,
                                         min_views=config.min_views, method='ransac')
    proj = project_to_views(X_next, cameras)                              # (V, C, 2)
    ncc = np.stack([patch_ncc(grays_a[v], start[v], grays_b[v], proj[v], config.patch)
                    for v in range(V)])
    with np.errstate(invalid='ignore'):
        kept = inliers & np.isfinite(flowed[..., 0]) & np.isfinite(proj[..., 0]) & \
            (ncc >= config.min_ncc)
    alive = kept.sum(axis=0) >= config.min_views
    X_next = np.where(alive[:, None], X_next, np.nan)
    kept &= alive[None]
    labels = np.where(kept[..., None], proj, np.nan)
    return X_next, labels, kept


def spatiotemporal_pseudo_labels(frames, cameras, seeds3d, config=TrackingConfig()):
    """Spatiotemporal augmentation.

    frames: sequence of T instants, each V images (H, W, 3) rgb or (H, W) gray (indexable,
        e.g. an array (T, V, H, W, 3) or a Recording's frame accessor).
    seeds3d: (T, C, 3) 3D keypoints of the seed (labelled) instants, NaN elsewhere.
    Returns PseudoLabels over all T instants: at seed instants the projections of the seeds,
    elsewhere the verified tracked labels, from the nearest seed in time when several reach
    an instant; frames_from_seed (T, C) the length of the kept track, agreement (T, V, C) px
    its distance to the next nearest seed's track in the same cell.
    """
    seeds = np.asarray(seeds3d, dtype=np.float64)
    T, C, _ = seeds.shape
    V = len(cameras)
    points = np.full((T, V, C, 2), np.nan)
    points3d = np.full((T, C, 3), np.nan)
    distance = np.full((T, C), np.inf)
    second = np.full((T, V, C, 2), np.nan)          # the next nearest track's labels
    second_distance = np.full((T, C), np.inf)
    gray_cache = {}

    def grays(t):
        if t not in gray_cache:
            gray_cache[t] = [_gray(image) for image in frames[t]]
        return gray_cache[t]

    seed_instants = np.flatnonzero(np.isfinite(seeds[..., 0]).any(axis=1))
    for t0 in seed_instants:
        alive = np.isfinite(seeds[t0, :, 0])
        points[t0][:, alive] = project_to_views(seeds[t0], cameras)[:, alive]
        points3d[t0, alive] = seeds[t0, alive]
        distance[t0, alive] = 0
        for direction in (1, -1):
            X = seeds[t0].copy()
            t = t0
            for step in range(1, config.horizon + 1):
                t_next = t + direction
                if t_next < 0 or t_next >= T or not np.isfinite(X[:, 0]).any():
                    break
                X, labels, _ = track_step(grays(t), grays(t_next), X, cameras, config)
                found = np.isfinite(X[:, 0])
                better = found & (step < distance[t_next])
                runner_up = found & ~better & (step < second_distance[t_next])
                demoted = better & np.isfinite(distance[t_next])
                second[t_next][:, demoted] = points[t_next][:, demoted]
                second_distance[t_next, demoted] = distance[t_next, demoted]
                second[t_next][:, runner_up] = labels[:, runner_up]
                second_distance[t_next, runner_up] = step
                points[t_next][:, better] = labels[:, better]
                points3d[t_next, better] = X[better]
                distance[t_next, better] = step
                t = t_next
    agreement = np.linalg.norm(points - second, axis=-1)                   # (T, V, C)
    return PseudoLabels(points, points3d, distance, agreement)
