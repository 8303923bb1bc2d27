"""PCK (percentage of correct keypoints) normalised by the heatmap window, as in MONET.

Definition used throughout monet_ros (the paper normalises by the 46-pixel heatmap):
a detection of keypoint c in one view is correct at threshold alpha when

    || p_hat - p ||_heat / W_heat <= alpha

where both points are in the pixels of the heatmap's virtual camera (the crop box
scaled to the heatmap grid: K_heat = S K, S = geometry.crop_transform(box, (W_heat, H_heat)))
and W_heat is the heatmap width. For a square crop box of width b image pixels this is
the image-pixel distance divided by b, so it does not depend on the heatmap resolution.
"""
from dataclasses import dataclass

import numpy as np

# The paper's Figure 6 x-axis: 0.01 .. 0.20 of the heatmap window.
PCK_THRESHOLDS = np.round(np.arange(1, 21) * 0.01, 2)


def normalised_distances(pred, gt, window):
    """Distances divided by the window.

    pred, gt: (..., C, 2) points in heatmap pixels, NaN = missing.
    window: scalar or array broadcastable to (..., C) (heatmap width in heatmap pixels).
    Returns (..., C) float64, NaN where either point is missing.
    """
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    if pred.shape != gt.shape or pred.shape[-1] != 2:
        raise ValueError(f'pred {pred.shape} and gt {gt.shape} must both be (..., C, 2)')
    window = np.asarray(window, dtype=np.float64)
    if np.any(window <= 0):
        raise ValueError('window must be positive')
    return np.linalg.norm(pred - gt, axis=-1) / window


@dataclass(frozen=True)
class PCKResult:
    """PCK per threshold, per keypoint and overall.

    thresholds (T,); per_keypoint (T, C) in [0, 1] (NaN for a keypoint never evaluated);
    overall (T,) over all evaluated (sample, keypoint) pairs; counts (C,) evaluated pairs.
    """
    thresholds: np.ndarray
    per_keypoint: np.ndarray
    overall: np.ndarray
    counts: np.ndarray
    keypoints: tuple = ()

    def at(self, alpha):
        """Overall PCK at one of the thresholds (e.g. 0.05)."""
        index = np.flatnonzero(np.isclose(self.thresholds, alpha))
        if index.size == 0:
            raise KeyError(f'threshold {alpha} not among {self.thresholds.tolist()}')
        return float(self.overall[index[0]])

    def as_dict(self):
        return {'thresholds': self.thresholds.tolist(), 'overall': self.overall.tolist(),
                'per_keypoint': {name: self.per_keypoint[:, c].tolist()
                                 for c, name in enumerate(self.keypoints)},
                'counts': self.counts.tolist()}


def pck(distances, thresholds=PCK_THRESHOLDS, keypoints=()):
    """PCK from normalised distances.

    distances: (N, C) normalised distances (normalised_distances), NaN = not evaluated.
    Returns a PCKResult; a distance equal to the threshold counts as correct.
    """
    d = np.asarray(distances, dtype=np.float64)
    if d.ndim != 2:
        raise ValueError(f'distances must be (N, C), got {d.shape}')
    thresholds = np.asarray(thresholds, dtype=np.float64)
    valid = np.isfinite(d)
    counts = valid.sum(axis=0)
    correct = (d[None] <= thresholds[:, None, None]) & valid[None]      # (T, N, C)
    hits = correct.sum(axis=1).astype(np.float64)                        # (T, C)
    with np.errstate(invalid='ignore', divide='ignore'):
        per_keypoint = np.where(counts > 0, hits / np.maximum(counts, 1), np.nan)
    total = counts.sum()
    overall = hits.sum(axis=1) / total if total else np.full(len(thresholds), np.nan)
    names = tuple(keypoints) if keypoints else tuple(str(c) for c in range(d.shape[1]))
    if len(names) != d.shape[1]:
        raise ValueError(f'{len(names)} keypoint names for {d.shape[1]} columns')
    return PCKResult(thresholds, per_keypoint, overall, counts, names)
