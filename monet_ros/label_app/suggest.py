"""Instants worth labelling, spread over time and pose (no ROS).

With a detector checkpoint: the detector + fusion of `monet process` (Detector.predict,
fusion.fuse_heatmaps) run on an evenly spaced subsample of instants; the features are the
root-relative 3D poses (NaN joints filled with the mean pose), and each instant's
disagreement is the mean reprojection error of its all-view triangulation. Without one:
the features are the instant's grey thumbnails (16x12 per view, all views concatenated).
Both append the instant's normalised time so that picks spread over time too; k-means
(scipy.cluster.vq.kmeans2, seeded) makes `k` clusters and the instant nearest to each
centre is suggested.
"""
import numpy as np


def kmeans_picks(features, k, times=None, time_weight=1.0, seed=0):
    """Indices (sorted, unique) of the rows of `features` (N, D) nearest to the centres of
    a k-means with min(k, N) clusters. Features are standardised per column; times (N,)
    (any unit) are scaled to 0..1 and appended with weight time_weight x sqrt(D)."""
    from scipy.cluster.vq import kmeans2

    F = np.asarray(features, np.float64)
    N = len(F)
    if N == 0:
        return []
    k = min(int(k), N)
    std = F.std(axis=0)
    F = (F - F.mean(axis=0)) / np.where(std > 1e-12, std, 1.0)
    if times is not None:
        t = np.asarray(times, np.float64)
        span = t.max() - t.min()
        t = (t - t.min()) / span if span > 0 else np.zeros_like(t)
        F = np.hstack([F, time_weight * np.sqrt(F.shape[1]) * t[:, None]])
    centres, assign = kmeans2(F, k, minit='++', seed=seed)
    picks = set()
    for c in range(k):
        members = np.flatnonzero(assign == c)
        if len(members):
            d = np.linalg.norm(F[members] - centres[c], axis=1)
            picks.add(int(members[np.argmin(d)]))
    return sorted(picks)


def suggest_from_images(session, k):
    """Suggested instant indices from image thumbnails (session.thumbnails())."""
    return kmeans_picks(session.thumbnails(), k, times=session.stamps.astype(np.float64))


class Predictor:
    """The detector + fusion of `monet process` (Detector.predict on full frames,
    fusion.fuse_heatmaps) on instants of a LabelSession, cached per instant.

    Raises ValueError / CheckpointError naming the model when it cannot be loaded or its
    keypoints differ from the session's skeleton (checked on construction)."""

    def __init__(self, session, model, device=None):
        from monet_ros.fusion import FusionConfig
        from monet_ros.models import Detector

        self.session = session
        self.detector = Detector.from_checkpoint(model, device=device)
        if list(self.detector.keypoints) != list(session.keypoints):
            raise ValueError(f'--model {model}: keypoints {list(self.detector.keypoints)} '
                             f'differ from the skeleton {list(session.keypoints)} (give '
                             '--skeleton)')
        self.config = FusionConfig()
        self.cache = {}

    def instants(self, instants):
        """{instant index: dict(points2d (V, C, 2) peaks px (NaN below the confidence
        threshold), confidence (V, C), X (C, 3), error (mean reprojection px of the
        all-view triangulation, NaN when nothing was triangulated))} of the complete ones
        among `instants`. One instant at a time holds session.work (a stop waits for it
        only)."""
        session = self.session
        out = {}
        for t in instants:
            t = int(t)
            if not session.complete[t]:
                continue
            if t not in self.cache:
                if session.stopping.is_set():
                    raise InterruptedError('monet label is stopping')
                with session.work:
                    self.cache[t] = self._detect(t)
            out[t] = self.cache[t]
        return out

    def subsample(self, max_instants):
        """instants() of at most max_instants evenly spaced complete instants."""
        complete = np.flatnonzero(self.session.complete)
        if len(complete) > max_instants:
            pick = np.linspace(0, len(complete) - 1, max_instants).round().astype(int)
            complete = complete[pick]
        return self.instants(complete)

    def _detect(self, t):
        from monet_ros.fusion import fuse_heatmaps

        session, detector, config = self.session, self.detector, self.config
        images = session.images(t)
        views = [images[name] for name in session.names]
        boxes = detector.boxes_for(session.cameras, None)
        heat, heat_cameras = detector.predict(views, session.cameras, boxes, keep_aspect=False)
        result = fuse_heatmaps(heat, np.stack([c.K for c in heat_cameras]), session.cameras,
                               config)
        points = np.where((result.peak_confidence >= config.confidence_threshold)[..., None],
                          result.points2d, np.nan)
        finite = np.isfinite(result.reprojection_error)
        error = float(np.mean(result.reprojection_error[finite])) if finite.any() \
            else float('nan')
        return {'points2d': points, 'confidence': result.peak_confidence, 'X': result.X,
                'error': error}


def suggest_from_predictions(predictions, k):
    """Suggested instant indices from the detector's 3D poses (Predictor.instants' output)."""
    index = sorted(predictions)
    if not index:
        return []
    X = np.stack([predictions[t]['X'] for t in index])            # (N, C, 3)
    X = X - np.nanmean(X, axis=1, keepdims=True)                  # root-relative pose
    mean = np.nanmean(X, axis=0)
    X = np.where(np.isfinite(X), X, np.where(np.isfinite(mean), mean, 0.0)[None])
    picks = kmeans_picks(X.reshape(len(index), -1), k, times=np.array(index, np.float64))
    return [index[i] for i in picks]
