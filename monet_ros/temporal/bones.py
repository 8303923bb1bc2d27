"""Bone lengths of a skeleton from triangulated frames (no ROS)."""
import numpy as np

MIN_FRAMES = 10        # confident frames needed before the other frames are not used


def bone_lengths(X, edges, confident=None):
    """(B,) median length (the points' unit) of each bone (a, b) in `edges` over the frames
    where both ends of X (T, C, 3) are finite and, when given, confident (T, C) bool; when
    fewer than MIN_FRAMES frames are confident for a bone, over every frame with both ends
    finite.
    NaN for a bone never seen. The median ignores the frames where one end was
    triangulated on the wrong limb."""
    X = np.asarray(X, np.float64)
    edges = np.asarray(edges, np.int64).reshape(-1, 2)
    if not len(edges):
        return np.zeros(0)
    length = np.linalg.norm(X[:, edges[:, 0]] - X[:, edges[:, 1]], axis=-1)     # (T, B)
    finite = np.isfinite(length)
    good = finite
    if confident is not None:
        confident = np.asarray(confident, bool)
        both = finite & confident[:, edges[:, 0]] & confident[:, edges[:, 1]]
        good = np.where(both.sum(axis=0) >= MIN_FRAMES, both, finite)
    with np.errstate(all='ignore'):
        return np.array([np.median(length[good[:, b], b]) if good[:, b].any() else np.nan
                         for b in range(len(edges))])
