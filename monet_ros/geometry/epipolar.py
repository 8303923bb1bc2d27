"""Epipolar geometry of camera pairs: fundamental matrices, epipolar lines, rectification.

The batched functions take K (..., 3, 3), R (..., 3, 3), t (..., 3) as numpy arrays or
torch tensors (same type out; torch stays differentiable), convention x ~ K (R X + t).
All pixels here are ideal (undistorted) pixels.
"""
import numpy as np


def _torch(x):
    """The torch module when x is a torch tensor, else None (torch is imported only by
    callers that already use it: importing the geometry layer stays fast)."""
    if type(x).__module__.split('.')[0] == 'torch':
        import torch
        return torch
    return None


def _cross(a, b):
    torch = _torch(a)
    return torch.linalg.cross(a, b, dim=-1) if torch else np.cross(a, b)


def _normalize(v):
    torch = _torch(v)
    if torch:
        return v / torch.linalg.norm(v, dim=-1, keepdim=True)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _stack(items, axis):
    torch = _torch(items[0])
    return torch.stack(items, dim=axis) if torch else np.stack(items, axis=axis)


def _mT(m):
    return m.swapaxes(-1, -2)


def _inv(m):
    torch = _torch(m)
    return torch.linalg.inv(m) if torch else np.linalg.inv(m)


def skew_matrix(v):
    """(..., 3) -> (..., 3, 3) cross-product matrix [v]_x."""
    zero = v[..., 0] * 0
    return _stack([_stack([zero, -v[..., 2], v[..., 1]], -1),
                   _stack([v[..., 2], zero, -v[..., 0]], -1),
                   _stack([-v[..., 1], v[..., 0], zero], -1)], -2)


def relative_pose(R_i, t_i, R_j, t_j):
    """Pose of camera j relative to camera i: x_j = R_ij x_i + t_ij (batched)."""
    R_ij = R_j @ _mT(R_i)
    t_ij = t_j - (R_ij @ t_i[..., None])[..., 0]
    return R_ij, t_ij


def fundamental_from_params(K_i, R_i, t_i, K_j, R_j, t_j):
    """Batched fundamental matrices (..., 3, 3) with x_j^T F x_i = 0, scaled to unit
    Frobenius norm. Inputs numpy or torch (..., 3, 3) / (..., 3)."""
    R_ij, t_ij = relative_pose(R_i, t_i, R_j, t_j)
    E = skew_matrix(t_ij) @ R_ij
    F = _mT(_inv(K_j)) @ E @ _inv(K_i)
    torch = _torch(F)
    if torch:
        return F / torch.linalg.norm(F, dim=(-2, -1), keepdim=True)
    return F / np.linalg.norm(F, axis=(-2, -1), keepdims=True)


def fundamental_matrix(cam_i, cam_j):
    """F (3, 3) between two Cameras: x_j^T F x_i = 0 for ideal (undistorted) pixels."""
    return fundamental_from_params(cam_i.K, cam_i.R, cam_i.t, cam_j.K, cam_j.R, cam_j.t)


def epipolar_lines(F, uv_i):
    """Lines (N, 3) = (a, b, c) in view j, a u + b v + c = 0 with a^2 + b^2 = 1, of the
    points uv_i (N, 2) of view i (same normalisation as cv2.computeCorrespondEpilines)."""
    uv_i = np.asarray(uv_i, dtype=np.float64)
    lines = np.concatenate([uv_i, np.ones_like(uv_i[:, :1])], axis=1) @ np.asarray(F).T
    return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


def rectifying_rotation(R_i, t_i, R_j, t_j):
    """World -> rectified-frame rotation (..., 3, 3) shared by a camera pair.

    Rows: x = baseline direction (centre i -> centre j), y = (mean optical axis) x x,
    z = x x y; so both rectified cameras differ by a pure x translation and corresponding
    points share a row. Degenerate (NaN) when the baseline is parallel to the mean optical
    axis (or the centres coincide)."""
    c_i = -(_mT(R_i) @ t_i[..., None])[..., 0]
    c_j = -(_mT(R_j) @ t_j[..., None])[..., 0]
    x = _normalize(c_j - c_i)
    z_mean = R_i[..., 2, :] + R_j[..., 2, :]
    y = _normalize(_cross(z_mean, x))
    z = _cross(x, y)
    return _stack([x, y, z], -2)


def rectification_homographies(K_i, R_i, t_i, K_j, R_j, t_j, K_new=None):
    """Batched stereo rectification of a camera pair.

    Returns (H_i, H_j, R_rect, K_new): H_* (..., 3, 3) map ideal pixels of each view to
    rectified pixels (u_r ~ H x); R_rect (..., 3, 3) world -> rectified rotation (the
    rectified cameras are K_new [R_rect | -R_rect c]); K_new (..., 3, 3) shared intrinsics,
    by default the mean of K_i and K_j without skew and with fx = fy = mean focal length.
    Corresponding points land on the same row v of the rectified views.
    The rotation of camera k's frame into the rectified frame is R_rect R_k^T.
    """
    R_rect = rectifying_rotation(R_i, t_i, R_j, t_j)
    if K_new is None:
        f = (K_i[..., 0, 0] + K_i[..., 1, 1] + K_j[..., 0, 0] + K_j[..., 1, 1]) / 4
        cx = (K_i[..., 0, 2] + K_j[..., 0, 2]) / 2
        cy = (K_i[..., 1, 2] + K_j[..., 1, 2]) / 2
        zero, one = f * 0, f * 0 + 1
        K_new = _stack([_stack([f, zero, cx], -1), _stack([zero, f, cy], -1),
                        _stack([zero, zero, one], -1)], -2)
    H_i = K_new @ R_rect @ _mT(R_i) @ _inv(K_i)
    H_j = K_new @ R_rect @ _mT(R_j) @ _inv(K_j)
    return H_i, H_j, R_rect, K_new


def stereo_rectify(cam_i, cam_j, K_new=None):
    """Rectifying rotations and homographies for two Cameras.

    Returns (H_i, H_j, R_rect, K_new) as in rectification_homographies, numpy (3, 3) each.
    Apply H to *undistorted* pixels (Camera.undistort_points) with apply_homography."""
    return rectification_homographies(cam_i.K, cam_i.R, cam_i.t, cam_j.K, cam_j.R, cam_j.t,
                                      K_new)


def apply_homography(H, uv):
    """Points uv (N, 2) through H (3, 3) -> (N, 2)."""
    uv = np.asarray(uv, dtype=np.float64)
    h = np.concatenate([uv, np.ones_like(uv[:, :1])], axis=1) @ np.asarray(H).T
    return h[:, :2] / h[:, 2:]
