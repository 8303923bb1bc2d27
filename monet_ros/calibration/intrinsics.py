"""Per-camera intrinsics from board views (OpenCV calibrateCamera, Zhang's method), no ROS.

Distortion models (OpenCV order k1, k2, p1, p2, k3): 'k1' (one radial term, as anipose's
default), 'k1k2' (two radial terms), 'full' (k1, k2, p1, p2, k3). Pixels are square
(fx = fy) unless square_pixels=False; the principal point is free unless
fix_principal_point (held at the image centre ((w - 1) / 2, (h - 1) / 2)).
"""
import numpy as np

from monet_ros.calibration.detect import MIN_CORNERS

DISTORTION_MODELS = ('k1', 'k1k2', 'full')
# Free distortion coefficients of each model, as indices into (k1, k2, p1, p2, k3).
FREE_DISTORTION = {'k1': (0,), 'k1k2': (0, 1), 'full': (0, 1, 2, 3, 4)}


def check_model(distortion):
    if distortion not in DISTORTION_MODELS:
        raise ValueError(f'--distortion: must be one of {", ".join(DISTORTION_MODELS)}, got '
                         f'{distortion!r}')


def _flags(distortion, square_pixels, fix_principal_point):
    import cv2
    flags = {'k1': cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
             'k1k2': cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
             'full': 0}[distortion]
    if square_pixels:
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
    if fix_principal_point:
        flags |= cv2.CALIB_FIX_PRINCIPAL_POINT
    return flags


def view_points(corners, board):
    """(object points list of (n, 3) float32, image points list of (n, 2) float32, frame
    indices) of the views in corners (F, N, 2) (NaN = missing) with >= MIN_CORNERS (6)."""
    seen = np.isfinite(corners[..., 0])
    frames = np.flatnonzero(seen.sum(axis=1) >= MIN_CORNERS)
    obj = [board.object_points[seen[f]].astype(np.float32) for f in frames]
    img = [corners[f][seen[f]].astype(np.float32) for f in frames]
    return obj, img, frames


def calibrate_intrinsics(corners, board, size, distortion='k1k2', square_pixels=True,
                         fix_principal_point=False):
    """Intrinsics of one camera from its board views.

    corners: (F, N, 2) px (NaN = missing); size: (width, height) px.
    Returns dict K (3, 3), dist (5,) (k1, k2, p1, p2, k3), rms (px, OpenCV's RMS
    reprojection error), frames (indices of the views used), rvecs / tvecs ((n, 3) board ->
    camera poses, board units). Raises ValueError when fewer than 3 views have a board."""
    import cv2
    check_model(distortion)
    obj, img, frames = view_points(corners, board)
    if len(frames) < 3:
        raise ValueError(f'intrinsics need at least 3 board views, got {len(frames)}')
    width, height = size
    # Initial guess: a 60 degree horizontal field of view, centred principal point.
    focal = width / 2.0 / np.tan(np.radians(30.0))
    K0 = np.array([[focal, 0.0, (width - 1) / 2.0], [0.0, focal, (height - 1) / 2.0],
                   [0.0, 0.0, 1.0]])
    flags = _flags(distortion, square_pixels, fix_principal_point)
    if fix_principal_point:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-9)
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, (int(width), int(height)),
                                                     K0, np.zeros(5), flags=flags,
                                                     criteria=criteria)
    return {'K': np.asarray(K, np.float64), 'dist': np.asarray(dist, np.float64).reshape(-1)[:5],
            'rms': float(rms), 'frames': frames,
            'rvecs': np.asarray(rvecs, np.float64).reshape(-1, 3),
            'tvecs': np.asarray(tvecs, np.float64).reshape(-1, 3)}


def board_poses(corners, board, K, dist):
    """Board -> camera poses of every view with >= MIN_CORNERS corners, given intrinsics.

    Returns (frames (n,), rvecs (n, 3), tvecs (n, 3)) by cv2.solvePnP (iterative, from the
    IPPE planar solution)."""
    import cv2
    obj, img, frames = view_points(corners, board)
    rvecs, tvecs = [], []
    for o, i in zip(obj, img):
        ok, rvec, tvec = cv2.solvePnP(o, i, K, dist, flags=cv2.SOLVEPNP_IPPE)
        if ok:
            ok, rvec, tvec = cv2.solvePnP(o, i, K, dist, rvec, tvec, useExtrinsicGuess=True,
                                          flags=cv2.SOLVEPNP_ITERATIVE)
        rvecs.append(rvec.reshape(3) if ok else np.full(3, np.nan))
        tvecs.append(tvec.reshape(3) if ok else np.full(3, np.nan))
    rvecs, tvecs = np.array(rvecs).reshape(-1, 3), np.array(tvecs).reshape(-1, 3)
    good = np.isfinite(rvecs).all(1) & np.isfinite(tvecs).all(1)
    return frames[good], rvecs[good], tvecs[good]
