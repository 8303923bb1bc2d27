"""Joint bundle adjustment of a rig's cameras and the board's poses (no ROS).

Unknowns: every camera's extrinsics (world -> camera Rodrigues vector and translation; the
root camera is the world frame and stays fixed: the gauge), optionally its intrinsics
(focal length(s), principal point, the free distortion terms of the model), and the pose
of every board view (board -> world). The board's corner positions are fixed, so the
scale is the board's unit (mm or m). Residuals: the pixel differences between the
detected corners and their projections by the OpenCV model (monet_ros.geometry.camera's
distortion, the same code every command projects with). Solved by scipy's sparse
trust-region least squares (least_squares 'trf', jac_sparsity, x_scale='jac') with a
robust loss (soft_l1 or huber, f_scale in px), as anipose / aniposelib do.
"""
from dataclasses import dataclass

import numpy as np

from monet_ros.calibration.intrinsics import FREE_DISTORTION
from monet_ros.geometry import Camera
from monet_ros.geometry.camera import _distort

LOSSES = ('soft_l1', 'huber', 'linear')


def _one_blas_thread():
    """threadpoolctl's limit to one BLAS thread, or nothing where it is not installed (it
    is pinned in requirements.txt; a speed-up, not a need)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:                                   # pragma: no cover
        from contextlib import nullcontext
        return nullcontext()
    return threadpool_limits(1, user_api='blas')


def rodrigues(rvecs):
    """Rotation matrices (n, 3, 3) of Rodrigues vectors (n, 3) (batched cv2.Rodrigues)."""
    rvecs = np.asarray(rvecs, np.float64)
    theta = np.linalg.norm(rvecs, axis=1)
    small = theta < 1e-12
    k = rvecs / np.where(small, 1.0, theta)[:, None]
    Kx = np.zeros((len(rvecs), 3, 3))
    Kx[:, 0, 1], Kx[:, 0, 2], Kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    Kx[:, 1, 0], Kx[:, 2, 0], Kx[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * Kx + (1.0 - c) * (Kx @ Kx)


@dataclass(frozen=True)
class Observations:
    """Detected corners as flat arrays: camera (M,), frame (M,), corner (M,) indices and
    uv (M, 2) px."""

    camera: np.ndarray
    frame: np.ndarray
    corner: np.ndarray
    uv: np.ndarray

    @classmethod
    def from_corners(cls, corners, cameras, frames):
        """From corners (C, F, N, 2) (NaN = missing), keeping cameras / frames listed."""
        sub = corners[np.ix_(cameras, frames)]
        c, f, n = np.nonzero(np.isfinite(sub[..., 0]))
        return cls(np.asarray(cameras)[c], np.asarray(frames)[f], n, sub[c, f, n])


class _Layout:
    """Parameter vector layout: per camera [rvec, tvec] (not the root) + intrinsics (if
    free), then per frame [rvec, tvec]."""

    def __init__(self, cameras, root, frames, distortion, fit_intrinsics, square_pixels,
                 fix_principal_point):
        self.cameras, self.root, self.frames = list(cameras), root, list(frames)
        self.free_dist = FREE_DISTORTION[distortion] if fit_intrinsics else ()
        self.n_focal = (1 if square_pixels else 2) if fit_intrinsics else 0
        self.n_pp = 0 if (fix_principal_point or not fit_intrinsics) else 2
        self.n_intr = self.n_focal + self.n_pp + len(self.free_dist)
        self.cam_start, start = {}, 0
        for c in self.cameras:
            self.cam_start[c] = start
            start += (0 if c == root else 6) + self.n_intr
        self.frame_start = {f: start + 6 * k for k, f in enumerate(self.frames)}
        self.size = start + 6 * len(self.frames)

    def cam_columns(self, c):
        n = (0 if c == self.root else 6) + self.n_intr
        return np.arange(self.cam_start[c], self.cam_start[c] + n)


def _pack(layout, intrinsics, extrinsics, board_poses):
    import cv2
    x = np.zeros(layout.size)
    for c in layout.cameras:
        s = layout.cam_start[c]
        if c != layout.root:
            x[s:s + 3] = cv2.Rodrigues(extrinsics[c][:3, :3])[0].reshape(3)
            x[s + 3:s + 6] = extrinsics[c][:3, 3]
            s += 6
        K, dist = intrinsics[c]
        values = [K[0, 0]] if layout.n_focal == 1 else [K[0, 0], K[1, 1]]
        values = values[:layout.n_focal] + ([K[0, 2], K[1, 2]] if layout.n_pp else [])
        values += [dist[i] for i in layout.free_dist]
        x[s:s + layout.n_intr] = values
    for f in layout.frames:
        s = layout.frame_start[f]
        x[s:s + 3] = cv2.Rodrigues(board_poses[f][:3, :3])[0].reshape(3)
        x[s + 3:s + 6] = board_poses[f][:3, 3]
    return x


def _unpack(layout, x, intrinsics):
    """(rvec (C, 3), tvec (C, 3), K (C, 3, 3), dist (C, 5), frame rvec (F, 3), tvec (F, 3))
    indexed by position in layout.cameras / layout.frames."""
    C = len(layout.cameras)
    rvec, tvec = np.zeros((C, 3)), np.zeros((C, 3))
    K = np.stack([intrinsics[c][0] for c in layout.cameras]).astype(np.float64)
    dist = np.stack([intrinsics[c][1] for c in layout.cameras]).astype(np.float64)
    for k, c in enumerate(layout.cameras):
        s = layout.cam_start[c]
        if c != layout.root:
            rvec[k], tvec[k] = x[s:s + 3], x[s + 3:s + 6]
            s += 6
        if layout.n_intr:
            v = x[s:s + layout.n_intr]
            K[k, 0, 0] = v[0]
            K[k, 1, 1] = v[layout.n_focal - 1]
            if layout.n_pp:
                K[k, 0, 2], K[k, 1, 2] = v[layout.n_focal], v[layout.n_focal + 1]
            dist[k, list(layout.free_dist)] = v[layout.n_focal + layout.n_pp:]
    s = layout.frame_start[layout.frames[0]]
    frames = x[s:].reshape(-1, 6)
    return rvec, tvec, K, dist, frames[:, :3], frames[:, 3:]


def project_observations(board_points, obs_cam, obs_frame, obs_corner, R_c, t_c, K, dist,
                         R_f, t_f):
    """Pixels (M, 2) of board corners obs_corner seen in view obs_frame by camera obs_cam
    (indices into the per-camera R_c (C, 3, 3), t_c, K, dist (C, 5) and per-view R_f
    (F, 3, 3), t_f (F, 3) board -> world)."""
    Xw = np.einsum('mij,mj->mi', R_f[obs_frame], board_points[obs_corner]) + t_f[obs_frame]
    Xc = np.einsum('mij,mj->mi', R_c[obs_cam], Xw) + t_c[obs_cam]
    x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    d = dist[obs_cam]                                   # (M, 5): k1 k2 p1 p2 k3
    zero = np.zeros(len(d))
    coeffs = (d[:, 0], d[:, 1], d[:, 2], d[:, 3], d[:, 4]) + (zero,) * 7
    xd, yd = _distort((coeffs, False, False, True), x, y)
    k = K[obs_cam]
    return np.stack([k[:, 0, 0] * xd + k[:, 0, 1] * yd + k[:, 0, 2],
                     k[:, 1, 1] * yd + k[:, 1, 2]], axis=1)


def bundle_adjust(board, obs, intrinsics, extrinsics, board_poses, root, distortion='k1k2',
                  fit_intrinsics=True, square_pixels=True, fix_principal_point=False,
                  loss='soft_l1', f_scale=1.0, max_nfev=200):
    """Refine cameras and board poses jointly.

    board: Board; obs: Observations (camera / frame indices are the caller's);
    intrinsics: {camera: (K (3, 3), dist (5,))}; extrinsics: {camera: T_cw (4, 4)} (the
    cameras to adjust; root's stays fixed); board_poses: (F, 4, 4) board -> world
    (rows of the frames in obs are used). loss: soft_l1, huber or linear; f_scale: px.
    Returns dict: intrinsics, extrinsics (same form), board_poses (F, 4, 4) (NaN rows
    for unused views), errors (M,) px after the fit, initial_errors (M,) px, cost,
    nfev, status (scipy's), message."""
    from scipy.optimize import least_squares
    from scipy.sparse import coo_matrix

    if loss not in LOSSES:
        raise ValueError(f'--loss: must be one of {", ".join(LOSSES)}, got {loss!r}')
    cameras = sorted(extrinsics)
    frames = sorted(set(np.asarray(obs.frame).tolist()))
    layout = _Layout(cameras, root, frames, distortion, fit_intrinsics, square_pixels,
                     fix_principal_point)
    cam_pos = np.searchsorted(cameras, obs.camera)
    frame_pos = np.searchsorted(frames, obs.frame)
    points = board.object_points

    def residuals(x):
        rvec, tvec, K, dist, frvec, ftvec = _unpack(layout, x, intrinsics)
        uv = project_observations(points, cam_pos, frame_pos, obs.corner, rodrigues(rvec),
                                  tvec, K, dist, rodrigues(frvec), ftvec)
        return (uv - obs.uv).ravel()

    # sparsity: the 2 residuals of an observation depend on its camera's and its view's
    # parameters only
    rows, cols = [], []
    M = len(obs.uv)
    for c in cameras:
        mine = np.flatnonzero(obs.camera == c)
        columns = layout.cam_columns(c)
        if mine.size and columns.size:
            r = np.concatenate([2 * mine, 2 * mine + 1])
            rows.append(np.repeat(r, columns.size))
            cols.append(np.tile(columns, r.size))
    frame_cols = np.array([layout.frame_start[f] for f in frames])[frame_pos]
    for k in range(6):
        for offset in (0, 1):
            rows.append(2 * np.arange(M) + offset)
            cols.append(frame_cols + k)
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    sparsity = coo_matrix((np.ones(rows.size, np.int8), (rows, cols)),
                          shape=(2 * M, layout.size)).tocsr()
    x0 = _pack(layout, intrinsics, extrinsics, board_poses)
    initial = np.linalg.norm(residuals(x0).reshape(-1, 2), axis=1)
    # One BLAS thread: lsmr's vector products (> 10,000 residuals: OpenBLAS threads them)
    # are tiny, and threads waiting on each other made a 4-camera fit 10x slower on 2
    # loaded cores (bench/calibrate.py).
    with _one_blas_thread():
        result = least_squares(residuals, x0, jac_sparsity=sparsity, x_scale='jac',
                               loss=loss, f_scale=float(f_scale), method='trf',
                               max_nfev=max_nfev)
    rvec, tvec, K, dist, frvec, ftvec = _unpack(layout, result.x, intrinsics)
    R_c, R_f = rodrigues(rvec), rodrigues(frvec)
    out_intr, out_extr = {}, {}
    for k, c in enumerate(cameras):
        out_intr[c] = (K[k], dist[k])
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R_c[k], tvec[k]
        out_extr[c] = T
    poses = np.full_like(np.asarray(board_poses, np.float64), np.nan)
    for k, f in enumerate(frames):
        poses[f] = np.eye(4)
        poses[f][:3, :3], poses[f][:3, 3] = R_f[k], ftvec[k]
    errors = np.linalg.norm(result.fun.reshape(-1, 2), axis=1)
    return {'intrinsics': out_intr, 'extrinsics': out_extr, 'board_poses': poses,
            'errors': errors, 'initial_errors': initial, 'cost': float(result.cost),
            'nfev': int(result.nfev), 'status': int(result.status),
            'message': str(result.message)}


def to_camera(name, size, K, dist, T_cw):
    """monet_ros.geometry.Camera of a calibrated camera (dist: (5,) k1 k2 p1 p2 k3)."""
    return Camera(name=name, K=np.asarray(K), dist=np.asarray(dist, np.float64),
                  R=T_cw[:3, :3], t=T_cw[:3, 3], width=int(size[0]), height=int(size[1]))
