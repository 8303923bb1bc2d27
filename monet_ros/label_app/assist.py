"""Geometry assist of `monet label`: triangulate an instant's clicks, project them into
every view (ghosts), per-view reprojection errors, flagged views and epipolar polylines
(no ROS; batched over keypoints).

Pixels are those of the original images (pixel centres on integers, lens distortion not
removed), as in the labels table.
"""
import numpy as np

from monet_ros.geometry.camera import project_views
from monet_ros.geometry.triangulation import reprojection_error, triangulate, triangulate_robust
from monet_ros.geometry.units import from_m


def assist_instant(points, cameras, threshold_px=15.0, flag_px=10.0):
    """Triangulation of every keypoint of one instant with >= 2 clicked views.

    points: (V, C, 2) clicked pixels, NaN = not clicked; cameras: V Camera.
    The project's robust triangulation (triangulate_robust, worst-view exclusion with
    threshold_px); where it leaves a keypoint out (its views disagree beyond threshold_px)
    the plain DLT of all clicked views is used so that ghosts still show (and the
    disagreeing views are flagged).
    Returns dict: X (C, 3) world points (NaN: fewer than 2 views); projections (V, C, 2)
    Camera.project of X in every view (NaN where X is NaN or behind the camera); errors
    (V, C) px distance between click and projection (NaN where not clicked); flagged (V, C)
    bool: clicked views with error > flag_px; robust (C,) bool: X from the robust
    triangulation (False: DLT fallback or none)."""
    points = np.asarray(points, np.float64)
    V, C = points.shape[:2]
    if len(cameras) != V:
        raise ValueError(f'{len(cameras)} cameras for {V} views')
    clicked = np.isfinite(points).all(axis=-1)
    enough = clicked.sum(axis=0) >= 2
    X = np.full((C, 3), np.nan)
    robust = np.zeros(C, bool)
    if enough.any():
        sub = points[:, enough]
        Xr, _ = triangulate_robust(sub, cameras, threshold_px=threshold_px, min_views=2)
        ok = np.isfinite(Xr).all(axis=1)
        if not ok.all():
            Xr[~ok] = triangulate(sub[:, ~ok], cameras)
        X[enough] = Xr
        robust[np.flatnonzero(enough)[ok]] = True
    projections = project_views(cameras, X)                     # (V, C, 2)
    depth = np.einsum('vij,cj->vci', np.stack([c.R for c in cameras]), X)[..., 2] + \
        np.stack([c.t for c in cameras])[:, 2:3]
    projections = np.where((depth > 0)[..., None], projections, np.nan)
    errors = np.where(clicked, reprojection_error(X, points, cameras), np.nan)
    with np.errstate(invalid='ignore'):
        flagged = clicked & (errors > flag_px)
    return {'X': X, 'projections': projections, 'errors': errors, 'flagged': flagged,
            'robust': robust}


def assist_to_json(result, names, keypoints):
    """The assist dict -> {keypoint: {X, views: {camera: {ghost, error, flagged}}}} for the
    keypoints that were triangulated (JSON: floats, None for NaN)."""
    def num(x):
        return float(x) if np.isfinite(x) else None

    out = {}
    for c, kp in enumerate(keypoints):
        X = result['X'][c]
        if not np.isfinite(X).all():
            continue
        views = {}
        for j, cam in enumerate(names):
            uv = result['projections'][j, c]
            views[cam] = {'ghost': [float(uv[0]), float(uv[1])] if np.isfinite(uv).all()
                          else None,
                          'error': num(result['errors'][j, c]),
                          'flagged': bool(result['flagged'][j, c])}
        out[kp] = {'X': [float(x) for x in X], 'robust': bool(result['robust'][c]),
                   'views': views}
    return out


def epipolar_polyline(source, uv, target, near=0.05, far=50.0, samples=96):
    """The epipolar curve, in `target`'s image, of the pixel `uv` of camera `source`: the
    3D ray through uv (lens distortion undone, Camera.undistort_normalized) sampled at
    `samples` log-spaced depths in [near, far] (metres along the source's optical axis,
    whatever the rig's unit: converted with source.units) and projected with
    target.project (its distortion applied: a curve, not a straight line). Points behind
    the target camera or farther than one image size outside its image are cut; returns a
    list of polylines, each a list of [u, v] (empty when the ray never shows in the
    target's view)."""
    xy = source.undistort_normalized(source.pixels_to_normalized(np.asarray(uv, np.float64)))
    if not np.isfinite(xy).all():
        return []
    depths = np.geomspace(from_m(near, source.units), from_m(far, source.units), samples)
    ray = np.array([xy[0], xy[1], 1.0])
    X = (depths[:, None] * ray[None, :] - source.t[None, :]) @ source.R      # R^T (d - t)
    Xc = target.to_camera(X)
    with np.errstate(invalid='ignore', divide='ignore'):
        uv_t = target.project(X)
    W, H = target.width, target.height
    inside = (Xc[:, 2] > 1e-6) & np.isfinite(uv_t).all(axis=1) & \
        (uv_t[:, 0] > -W) & (uv_t[:, 0] < 2 * W) & (uv_t[:, 1] > -H) & (uv_t[:, 1] < 2 * H)
    lines, current = [], []
    for keep, p in zip(inside, uv_t):
        if keep:
            current.append([float(p[0]), float(p[1])])
        elif current:
            lines.append(current)
            current = []
    if current:
        lines.append(current)
    return [line for line in lines if len(line) >= 2]
