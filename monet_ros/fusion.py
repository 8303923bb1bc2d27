"""Multiview fusion core: heatmaps of V views -> 3D keypoints (no ROS).

Used by the fusion node and by the offline `monet process`. A heatmap is an image of a
virtual camera (K_heat = S K, S the crop/scale of the source image), so a sub-pixel peak
in heatmap pixels maps back to source-image pixels through S^-1; triangulation, its
inlier threshold and the reported reprojection errors are all in source-image pixels.

Several hypotheses per view (peaks_per_view = K > 1): the best peaks are fused first
(exactly the K = 1 fusion); the keypoints where a view was left out are decoded again with
the K highest local maxima of their maps (models.decode_heatmap_peaks),
geometry.select_candidates picks per keypoint the candidate of each view most consistent
with the others (two-view hypotheses of candidate pairs, cheirality-checked, scored by the
views that agree), the picks go through the same robust triangulation, and the answer
with more inlier views is kept. A view whose best peak is another joint (the other leg)
then contributes its second peak instead of being dropped; where all views agree nothing
changes and nothing more is computed. Default K = 2 (bench/peaks.py: on two-peak
synthetic heatmaps with 15% of the maps' best peak on the wrong joint, p90 3D error
119 -> 103 mm at threshold_px 15 and 68 -> 35 mm at 8; K = 3 adds nothing there; the same
answers as K = 1 on clean and non-swapped two-peak maps; with the trained demo model of
`monet pipeline` about the same (p90 84.6 -> 85.4 mm): its second peaks are rarely above
the confidence threshold).
"""
from collections import Counter
from dataclasses import dataclass, field
import time

import numpy as np

from monet_ros.config import setting, validate_config
from monet_ros.geometry import select_candidates, stack_cameras, triangulate_robust
from monet_ros.models import decode_heatmap_peaks, decode_heatmap_views
from monet_ros.timing import NO_TIMER

_CHUNK = 16384          # keypoint columns per batched triangulation (bounded memory)

# Largest |S[0, 1]|, |S[1, 0]|, |S[2] - (0, 0, 1)| accepted for a crop/scale S.
_CROP_TOL = 1e-6
_OFF = [1, 3, 6, 7, 8]
_OFF_TARGET = np.array([0.0, 0.0, 0.0, 0.0, 1.0])
# Default candidates per view (bench/peaks.py: measured on two-peak synthetic heatmaps).
PEAKS_PER_VIEW = 2
MAX_PEAKS_PER_VIEW = 5
# Two-view hypotheses per keypoint in select_candidates (every pair up to this many:
# 4 views x 2 peaks = 24, 4 x 3 = 54; random ones beyond).
MAX_HYPOTHESES = 64


@dataclass(frozen=True)
class FusionConfig:
    """Triangulation settings shared by the fusion node and `monet process`."""
    confidence_threshold: float = setting(
        0.1, 'heatmap peak value below which a view of a keypoint is ignored', minimum=0.0)
    threshold_px: float = setting(
        15.0, 'reprojection error (source-image pixels) above which a view is an outlier',
        minimum=0.0, exclusive_minimum=True)
    min_views: int = setting(2, 'fewest inlier views to triangulate a keypoint', minimum=2)
    method: str = setting('exclusion', 'outlier rejection: worst-view exclusion or RANSAC',
                          choices=('exclusion', 'ransac'))
    peaks_per_view: int = setting(
        PEAKS_PER_VIEW, 'heatmap local maxima per view and keypoint tried where a view '
        'disagrees: the most consistent combination across views is triangulated (1 = the '
        'highest peak only)',
        minimum=1, maximum=MAX_PEAKS_PER_VIEW)

    def __post_init__(self):
        validate_config(self)


@dataclass
class FusionResult:
    """One frame's fused keypoints. C keypoints, V views (in the order of the cameras given).

    X (C, 3) world points, NaN where not triangulated; confidence (C,) mean peak value of
    the inlier views; reprojection_error (C,) mean over the inlier views (source px);
    num_views (C,) inlier count; inliers (V, C) bool; view_errors (V, C) source px of the
    inlier views (NaN elsewhere); points2d (V, C, 2) decoded peaks in source px (NaN where
    below the confidence threshold), with several candidates per view the chosen ones;
    peak_confidence (V, C); peak_index (V, C) int: which candidate of each view was used
    (0 = the highest peak; all 0 with one candidate); seconds: wall time;
    skipped_views {view index: reason} of the views fuse_heatmaps could not use (too small
    a grid, wrong channel count, non-finite values, K not a crop of the rig camera); they
    count as missing, the other views are fused.
    """
    X: np.ndarray
    confidence: np.ndarray
    reprojection_error: np.ndarray
    num_views: np.ndarray
    inliers: np.ndarray
    view_errors: np.ndarray
    points2d: np.ndarray
    peak_confidence: np.ndarray
    peak_index: np.ndarray = None
    seconds: float = 0.0
    skipped_views: dict = field(default_factory=dict)  # view index -> why it was left out

    def view_mean_errors(self):
        """(V,) mean reprojection error of each view over its inlier keypoints (NaN: none)."""
        counts = np.isfinite(self.view_errors).sum(axis=1)
        sums = np.nansum(self.view_errors, axis=1)
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def crop_scales(K_heat, K_source, K_source_inv=None):
    """(S (V, 3, 3) with K_heat = S K_source, bad (V,) bool): bad where S is not a crop/scale
    (rotation/shear, non-positive or non-finite scales). K_* (V, 3, 3); K_source_inv: its
    inverse when at hand (stack_cameras' K_inv)."""
    K_heat = np.asarray(K_heat, np.float64).reshape(-1, 3, 3)
    if K_source_inv is None:
        K_source_inv = np.linalg.inv(np.asarray(K_source, np.float64).reshape(-1, 3, 3))
    with np.errstate(all='ignore'):
        S = K_heat @ K_source_inv
        flat = S.reshape(-1, 9)
        # S[0, 1], S[1, 0], S[2, 0], S[2, 1] must be 0 and S[2, 2] 1
        off = np.abs(flat[:, _OFF] - _OFF_TARGET).max(axis=1)
        sx, sy = flat[:, 0], flat[:, 4]
        # (absurd scales, e.g. K = 1e300: not a crop)
        good = (off <= _CROP_TOL * np.maximum(np.abs(sx), 1.0)) \
            & (np.minimum(sx, sy) > 1e-6) & (np.maximum(sx, sy) < 1e6)
    good &= np.isfinite(flat).all(axis=1)
    return S, ~good


def heat_to_source(K_heat, K_source):
    """S (V, 3, 3) with K_heat = S K_source, checked to be a crop/scale (positive scales,
    no rotation/shear). K_* (V, 3, 3). Raises ValueError naming the view index."""
    S, bad = crop_scales(K_heat, K_source)
    if np.any(bad):
        view = int(np.flatnonzero(bad)[0])
        raise ValueError(f'view {view}: heatmap K is not a crop/scale of the source K '
                         f'(S = K_heat K^-1 = {np.round(S[view], 6).tolist()})')
    return S


def heat_to_source_points(peaks, S):
    """Heatmap pixels (V, ..., 2) (e.g. (V, C, 2) or (V, C, K, 2)) -> source-image pixels
    of the same shape through S^-1 (V, 3, 3)."""
    peaks = np.asarray(peaks, np.float64)
    # S is a per-axis scale + offset: u = (u' - S[0, 2]) / S[0, 0], v likewise.
    shape = (len(S),) + (1,) * (peaks.ndim - 2) + (2,)
    offset = S[:, :2, 2].reshape(shape)
    return (peaks - offset) / np.diagonal(S, axis1=1, axis2=2)[:, :2].reshape(shape)


def fuse_points(points2d, peak_confidence, cameras, config=FusionConfig(), timer=None):
    """Robust triangulation of decoded peaks.

    points2d (V, C, 2) source-image pixels, or (V, C, K, 2) with K candidates per view and
    keypoint (best first, NaN = none); peak_confidence (V, C) or (V, C, K); cameras: V
    source cameras (Camera). Candidates below config.confidence_threshold are left out;
    the rest are weighted by confidence. The best candidates (index 0) are triangulated
    first (exactly the single-peak fusion); with K > 1 the keypoints where a view was left
    out are tried again with every candidate (retry_with_candidates) and take the answer
    with more inlier views. timer: a monet_ros.timing.StageTimer given the wall time of
    'undistort', 'triangulate' and 'errors' (reprojection errors) of the first pass and
    'candidates' of the retry. Returns a FusionResult. Raises ValueError on mismatched
    shapes.
    """
    start = time.perf_counter()
    points2d = np.asarray(points2d, np.float64)
    conf = np.asarray(peak_confidence, np.float64)
    if points2d.ndim == 3:
        points2d, conf = points2d[:, :, None], conf[:, :, None]
    if points2d.ndim != 4 or points2d.shape[-1] != 2 or conf.shape != points2d.shape[:3]:
        raise ValueError(f'points2d must be (V, C, 2) or (V, C, K, 2) and confidence (V, C) '
                         f'or (V, C, K), got {points2d.shape} and {conf.shape}')
    if len(cameras) != points2d.shape[0]:
        raise ValueError(f'{len(cameras)} cameras for {points2d.shape[0]} views')
    result = _fuse_best(points2d[:, :, 0], conf[:, :, 0], cameras, config, timer)
    if points2d.shape[2] > 1:
        cols = np.flatnonzero(retry_columns(result))
        if cols.size:
            with (timer or NO_TIMER)('candidates'):
                retry_with_candidates(result, cols, points2d[:, cols], conf[:, cols], cameras,
                                      config)
    result.seconds = time.perf_counter() - start
    return result


def fuse_frames(points, score, cameras, config=FusionConfig()):
    """Frame-by-frame fusion of every frame at once: points (T, V, C, 2), score (T, V, C)
    -> dict X (T, C, 3), error, ncams, score (T, C), inliers (T, V, C), points2d (T, V, C,
    2) as fused (NaN below the confidence threshold). Columns are independent, so this is
    fuse_points per frame, batched in chunks of _CHUNK keypoints (`monet triangulate`, the
    benches' frame-by-frame rows)."""
    points, score = np.asarray(points, np.float64), np.asarray(score, np.float64)
    T, V, C = score.shape
    p = points.transpose(1, 0, 2, 3).reshape(V, T * C, 2)
    s = np.nan_to_num(score.transpose(1, 0, 2).reshape(V, T * C), nan=0.0)
    X = np.full((T * C, 3), np.nan)
    error, conf = np.full(T * C, np.nan), np.zeros(T * C)
    ncams = np.zeros(T * C, np.uint32)
    inliers = np.zeros((V, T * C), bool)
    fused = np.full((V, T * C, 2), np.nan)
    for a in range(0, T * C, _CHUNK):
        b = min(a + _CHUNK, T * C)
        r = fuse_points(p[:, a:b], s[:, a:b], cameras, config)
        X[a:b], error[a:b], conf[a:b], ncams[a:b] = (r.X, r.reprojection_error,
                                                     r.confidence, r.num_views)
        inliers[:, a:b], fused[:, a:b] = r.inliers, r.points2d
    return dict(X=X.reshape(T, C, 3), error=error.reshape(T, C), score=conf.reshape(T, C),
                ncams=ncams.reshape(T, C),
                inliers=inliers.reshape(V, T, C).transpose(1, 0, 2),
                points2d=fused.reshape(V, T, C, 2).transpose(1, 0, 2, 3))


def _fuse_best(points2d, conf, cameras, config, timer=None):
    """The single-peak fusion: points2d (V, C, 2), conf (V, C) -> FusionResult."""
    points2d = np.array(points2d, np.float64)
    conf = np.array(conf, np.float64)           # (a copy: the result's, updated in place)
    weak = ~(conf >= config.confidence_threshold) | ~np.isfinite(points2d).all(axis=-1)
    points2d[weak] = np.nan
    weights = np.where(weak, 0.0, conf)
    X, inliers, errors = triangulate_robust(points2d, cameras, weights=weights,
                                            threshold_px=config.threshold_px,
                                            min_views=config.min_views,
                                            method=config.method, timer=timer, errors=True)
    X = np.asarray(X, np.float64)
    inliers = np.asarray(inliers, bool) & ~weak & np.isfinite(X).all(axis=1)[None, :]
    view_errors = np.where(inliers, errors, np.nan)
    num_views = inliers.sum(axis=0)
    count = np.maximum(num_views, 1)
    seen = num_views > 0
    with np.errstate(invalid='ignore', divide='ignore'):
        mean_error = np.where(seen, np.where(inliers, errors, 0.0).sum(axis=0) / count, np.nan)
        confidence = np.where(seen, (conf * inliers).sum(axis=0) / count, 0.0)
    return FusionResult(X=X, confidence=confidence, reprojection_error=mean_error,
                        num_views=num_views.astype(np.uint32), inliers=inliers,
                        view_errors=view_errors, points2d=points2d, peak_confidence=conf,
                        peak_index=np.zeros(conf.shape, np.intp))


def retry_columns(result):
    """(C,) bool: the keypoints of a FusionResult where a view with a usable peak is not an
    inlier (left out, or the keypoint not triangulated): only these can gain from other
    candidates (where every view agrees, the best peaks stay)."""
    usable = np.isfinite(result.points2d).all(axis=-1)
    return (usable & ~result.inliers).any(axis=0)


def retry_with_candidates(result, cols, points2d, conf, cameras, config=FusionConfig()):
    """Fuse the keypoints `cols` (n,) of `result` again from K candidates per view and keep
    the answer where it has more inlier views (result is updated in place).

    points2d (V, n, K, 2) source px (best first, NaN = none), conf (V, n, K) of those
    keypoints. geometry.select_candidates picks one candidate per view (the most
    consistent combination: two-view hypotheses of candidate pairs, cheirality-checked,
    scored by agreeing views), the picks go through the same robust triangulation
    (config.method, threshold_px, min_views) and replace the first answer only where they
    give more inlier views; result.peak_index says which candidate was used."""
    cols = np.asarray(cols, np.intp)
    weak = ~(conf >= config.confidence_threshold) | ~np.isfinite(points2d).all(axis=-1)
    has_other = (~weak[:, :, 1:]).any(axis=(0, 2))     # some view has a second candidate
    cols, points2d, conf, weak = (a[:, has_other] if a.ndim > 1 else a[has_other]
                                  for a in (cols, points2d, conf, weak))
    if not cols.size:
        return result
    choice, _ = select_candidates(np.where(weak[..., None], np.nan, points2d), cameras,
                                  weights=np.where(weak, 0.0, conf),
                                  threshold_px=config.threshold_px,
                                  max_hypotheses=MAX_HYPOTHESES)
    pick = choice[:, :, None]
    again = _fuse_best(np.take_along_axis(points2d, pick[..., None], axis=2)[:, :, 0],
                       np.take_along_axis(conf, pick, axis=2)[:, :, 0], cameras, config)
    better = again.num_views > result.num_views[cols]
    at, sub = cols[better], np.flatnonzero(better)
    for name in ('X', 'confidence', 'reprojection_error', 'num_views'):
        getattr(result, name)[at] = getattr(again, name)[sub]
    for name in ('inliers', 'view_errors', 'points2d', 'peak_confidence'):
        getattr(result, name)[:, at] = getattr(again, name)[:, sub]
    result.peak_index[:, at] = choice[:, sub]
    return result


def _misshapen_views(heatmaps):
    """({view: reason}, C) for the heatmaps whose shape cannot be decoded: not (C, h, w)
    with h, w >= 3, or a channel count other than the majority's (C)."""
    skipped = {}
    shapes = [np.shape(h) for h in heatmaps]
    counts = Counter(shape[0] for shape in shapes if len(shape) == 3)
    channels = counts.most_common(1)[0][0] if counts else None
    for v, shape in enumerate(shapes):
        if len(shape) != 3:
            skipped[v] = f'view {v}: heatmaps must be (C, h, w), got {shape}'
        elif shape[1] < 3 or shape[2] < 3:
            skipped[v] = f'view {v}: heatmap grid {shape[2]}x{shape[1]} is smaller than 3x3'
        elif shape[0] != channels:
            skipped[v] = f'view {v}: {shape[0]} heatmap channels, the other views have ' \
                f'{channels}'
    return skipped, channels


def fuse_heatmaps(heatmaps, K_heat, cameras, config=FusionConfig(), timer=None):
    """Heatmaps of V views -> FusionResult.

    heatmaps: (V, C, h, w) array, or a list of V (C, h_v, w_v) arrays (grids may differ;
    the arrays are decoded where they lie, with models.decode_heatmap_views);
    K_heat (V, 3, 3): intrinsics of each heatmap's virtual camera (its camera_info);
    cameras: V source cameras (rig: K, dist, R, t of the full image).
    With config.peaks_per_view K > 1, the keypoints where a view was left out (and only
    those: the search costs nothing where the views agree) are decoded again with the K
    highest local maxima of their maps (models.decode_heatmap_peaks) and fused again from
    them (retry_with_candidates).
    A view that cannot be used (grid smaller than 3x3, other channel count, non-finite
    values, K not a crop/scale of its camera's K) is left out as missing and named in
    result.skipped_views; the other views are fused. ValueError (naming view 0's
    problem) only when no view is usable. timer: a monet_ros.timing.StageTimer given the
    wall time of 'decode' and fuse_points' stages ('candidates': the retry, decoding
    included).
    """
    start = time.perf_counter()
    if len(heatmaps) != len(cameras):
        raise ValueError(f'{len(heatmaps)} heatmaps for {len(cameras)} cameras')
    rig = stack_cameras(cameras)
    S, bad_K = crop_scales(K_heat, rig['K'], rig['K_inv'])
    heatmaps = [np.asarray(h) for h in heatmaps]
    skipped, channels = _misshapen_views(heatmaps)
    shaped = [v for v in range(len(cameras)) if v not in skipped]
    if shaped:
        p, c, finite = decode_heatmap_views([heatmaps[v] for v in shaped])
        usable = finite & ~bad_K[shaped]
        for i in np.flatnonzero(~usable):
            v = shaped[i]
            skipped[v] = (f'view {v}: heatmaps hold non-finite values' if not finite[i] else
                          f'view {v}: heatmap K is not a crop/scale of the source K '
                          f'(S = K_heat K^-1 = {np.round(S[v], 6).tolist()})')
    if len(skipped) == len(cameras):
        raise ValueError(skipped[0])
    good = np.asarray(shaped)[usable]
    if skipped:  # the skipped views are missing: NaN peaks, confidence 0
        peaks = np.full((len(cameras), channels, 2), np.nan)
        conf = np.zeros((len(cameras), channels))
        peaks[good], conf[good] = p[usable], c[usable]
    else:
        peaks, conf = p, c
    skipped = dict(sorted(skipped.items()))
    points = heat_to_source_points(peaks, S)
    (timer or NO_TIMER).add('decode', time.perf_counter() - start)
    result = fuse_points(points, conf, cameras, config, timer)
    if config.peaks_per_view > 1:
        cols = np.flatnonzero(retry_columns(result))
        if cols.size:
            with (timer or NO_TIMER)('candidates'):
                k = config.peaks_per_view
                p, c, _ = decode_heatmap_peaks([heatmaps[v] for v in good], k,
                                               floor=config.confidence_threshold,
                                               channels=cols)
                peaks = np.full((len(cameras), cols.size, k, 2), np.nan)
                conf = np.zeros((len(cameras), cols.size, k))
                peaks[good], conf[good] = p, c
                retry_with_candidates(result, cols, heat_to_source_points(peaks, S), conf,
                                      cameras, config)
    result.skipped_views = skipped
    result.seconds = time.perf_counter() - start
    return result
