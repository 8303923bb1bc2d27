"""Crop boxes around the subject from its last 3D keypoints (no ROS).

The detector node and `monet process` crop each view around the projection of the latest
fused keypoints, so the network sees the subject at a useful scale; without a usable
projection they fall back to a configured box or the full frame.
"""
import numpy as np

from monet_ros.geometry import project_views, stack_cameras


def subject_boxes(cameras, X, margin=0.3, min_points=3, min_size=32.0):
    """Boxes (V, 4) (x0, y0, x1, y1) edge coordinates around the projections of X.

    cameras: V Camera (full images); X (N, 3) world points, NaN = missing. A view's box is
    the bounding box of the projected points in front of the camera and within the image
    (one image size of slack), grown by `margin` x its size on each side and to at least
    `min_size` pixels; NaN rows where fewer than `min_points` points qualify.
    """
    X = np.asarray(X, np.float64).reshape(-1, 3)
    V = len(cameras)
    boxes = np.full((V, 4), np.nan)
    finite = np.isfinite(X).all(axis=1)
    if finite.sum() < min_points or V == 0:
        return boxes
    Xf = X[finite]
    uv = project_views(stack_cameras(cameras), Xf)          # (V, n, 2)
    R = np.stack([cam.R for cam in cameras])
    t = np.stack([cam.t for cam in cameras])
    depth = np.einsum('vj,nj->vn', R[:, 2], Xf) + t[:, 2, None]  # (V, n)
    size = np.array([[cam.width, cam.height] for cam in cameras], np.float64)  # (V, 2)
    inside = ((depth > 0) & np.isfinite(uv).all(axis=-1)
              & (uv > -size[:, None]).all(axis=-1) & (uv < 2 * size[:, None]).all(axis=-1))
    ok = inside.sum(axis=1) >= min_points
    uv = np.where(inside[..., None], uv, np.nan)
    uv[~ok] = 0.0                       # views without a box: no all-NaN reductions
    lo, hi = np.nanmin(uv, axis=1), np.nanmax(uv, axis=1)
    extent = np.maximum(hi - lo, 0.0)
    centre = (lo + hi) / 2
    half = np.maximum(extent * (0.5 + margin), min_size / 2)
    # +0.5: pixel centres are integers, the box is in edge coordinates.
    boxes[ok] = np.concatenate([centre - half + 0.5, centre + half + 0.5], axis=1)[ok]
    return boxes


def crop_boxes(cameras, X=None, fallback_box=None, margin=0.3, min_points=3):
    """The crop of each view (V, 4): around the projection of X (the latest 3D keypoints)
    where at least `min_points` project into the view, else `fallback_box` (x0, y0, x1, y1),
    else the full frame."""
    boxes = (subject_boxes(cameras, X, margin, min_points) if X is not None
             else np.full((len(cameras), 4), np.nan))
    for v, camera in enumerate(cameras):
        if np.isnan(boxes[v]).any():
            boxes[v] = fallback_box if fallback_box else (0, 0, camera.width, camera.height)
    return boxes
