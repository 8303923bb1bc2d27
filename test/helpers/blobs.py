"""A tiny learnable multiview scene in memory: coloured blobs moving in front of a ring rig."""
import numpy as np

from helpers.ring import ring_rig
from monet_ros.learning.recording import Recording

COLOURS = np.array([[255, 40, 40], [40, 255, 40], [60, 60, 255], [255, 255, 40],
                    [255, 40, 255], [40, 255, 255]], dtype=np.float64)


def blob_motion(T, C, seed=0):
    """(T, C, 3) smooth trajectories around (0, 0, 1)."""
    rng = np.random.default_rng(seed)
    base = rng.uniform(-0.35, 0.35, size=(C, 3)) + [0.0, 0.0, 1.0]
    phase = rng.uniform(0, 2 * np.pi, size=(C, 3))
    t = np.arange(T)[:, None, None]
    return base[None] + 0.12 * np.sin(0.15 * t + phase[None])


def render_blobs(cameras, X, radius_px=3.0):
    """V frame arrays (T, H, W, 3) uint8: one coloured Gaussian blob per keypoint on grey."""
    T, C, _ = X.shape
    frames = []
    for cam in cameras:
        yy, xx = np.mgrid[0:cam.height, 0:cam.width]
        f = np.empty((T, cam.height, cam.width, 3), np.uint8)
        for t in range(T):
            img = np.full((cam.height, cam.width, 3), 60.0)
            for c, (u, v) in enumerate(cam.project(X[t])):
                g = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * radius_px ** 2))[..., None]
                img = img * (1 - g) + COLOURS[c % len(COLOURS)] * g
            f[t] = np.clip(img, 0, 255).astype(np.uint8)
        frames.append(f)
    return frames


def blob_recording(num_views=4, T=24, C=3, labelled=(2,), label_views=None, seed=0,
                   width=96, height=80, focal=110.0):
    """Recording with labels (exact projections) at `labelled` instants in `label_views`."""
    cams = ring_rig(num_views, width=width, height=height, focal=focal, radius=3.0)
    X = blob_motion(T, C, seed)
    frames = render_blobs(cams, X)
    labels = np.full((T, num_views, C, 2), np.nan)
    views = range(num_views) if label_views is None else label_views
    for t in labelled:
        for v in views:
            labels[t, v] = cams[v].project(X[t])
    return Recording('blobs', cams, np.arange(T, dtype=np.int64) * 33_000_000 + 10**18,
                     frames, tuple(f'k{c}' for c in range(C)), labels, X)
