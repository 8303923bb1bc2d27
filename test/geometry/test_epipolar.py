"""Fundamental matrix and rectification vs OpenCV on random rigs."""
import cv2
from helpers.rigs import random_camera, random_points
import numpy as np
import pytest
import torch

from monet_ros.geometry import (
    apply_homography,
    epipolar_lines,
    fundamental_from_params,
    fundamental_matrix,
    rectification_homographies,
    stereo_rectify,
)


def _pair(seed, skew=0.0):
    rng = np.random.default_rng(seed)
    return (random_camera(rng, name='a', distortion=False, skew=skew),
            random_camera(rng, name='b', distortion=False, skew=skew), rng)


@pytest.mark.parametrize('seed', range(4))
def test_fundamental_vs_cv2_epilines_and_eight_point(seed):
    cam_i, cam_j, rng = _pair(seed, skew=2.0 * seed)
    X = random_points(rng, 60)
    x_i, x_j = cam_i.project(X), cam_j.project(X)
    F = fundamental_matrix(cam_i, cam_j)
    ref = cv2.computeCorrespondEpilines(x_i[:, None], 1, F)[:, 0]
    ours = epipolar_lines(F, x_i)
    np.testing.assert_allclose(ours, ref, atol=1e-9)
    # the corresponding point lies on its epipolar line (< 1e-6 px)
    dist = np.abs(np.sum(ours[:, :2] * x_j, axis=1) + ours[:, 2])
    assert dist.max() < 1e-6
    # independent estimate: OpenCV's 8-point algorithm on exact correspondences
    F_cv, _ = cv2.findFundamentalMat(x_i, x_j, cv2.FM_8POINT)
    F_cv /= np.linalg.norm(F_cv)
    sign = np.sign(np.sum(F_cv * F))
    np.testing.assert_allclose(sign * F_cv, F, atol=1e-6)
    # the epipole in view i is the image of camera j's centre
    e_i = np.append(cam_i.project(cam_j.center[None])[0], 1.0)
    assert np.linalg.norm(F @ e_i) / np.linalg.norm(F) < 1e-9 * np.linalg.norm(e_i)


def test_fundamental_batched_numpy_and_torch_agree():
    rng = np.random.default_rng(7)
    cams = [random_camera(rng, name=f'c{k}', distortion=False) for k in range(6)]
    Ks = np.stack([c.K for c in cams])
    Rs = np.stack([c.R for c in cams])
    ts = np.stack([c.t for c in cams])
    F = fundamental_from_params(Ks[:3], Rs[:3], ts[:3], Ks[3:], Rs[3:], ts[3:])
    for k in range(3):
        np.testing.assert_allclose(F[k], fundamental_matrix(cams[k], cams[k + 3]), atol=1e-12)
    Ft = fundamental_from_params(*(torch.from_numpy(a) for a in
                                   (Ks[:3], Rs[:3], ts[:3], Ks[3:], Rs[3:], ts[3:])))
    np.testing.assert_allclose(Ft.numpy(), F, atol=1e-12)


@pytest.mark.parametrize('seed', range(4))
def test_rectification_aligns_rows_like_cv2_stereo_rectify(seed):
    cam_i, cam_j, rng = _pair(100 + seed)
    X = random_points(rng, 80)
    x_i, x_j = cam_i.project(X), cam_j.project(X)
    H_i, H_j, R_rect, K_new = stereo_rectify(cam_i, cam_j)
    r_i, r_j = apply_homography(H_i, x_i), apply_homography(H_j, x_j)
    assert np.abs(r_i[:, 1] - r_j[:, 1]).max() < 1e-6
    # OpenCV's (Bouguet) rectification of the same pair is also row-aligned ...
    R_ij = cam_j.R @ cam_i.R.T
    T_ij = cam_j.t - R_ij @ cam_i.t
    R1, R2, P1, P2, *_ = cv2.stereoRectify(cam_i.K, np.zeros(5), cam_j.K, np.zeros(5),
                                          (1280, 960), R_ij, T_ij.reshape(3, 1), flags=0,
                                          alpha=-1)
    c_i = cv2.undistortPoints(x_i[:, None], cam_i.K, None, R=R1, P=P1)[:, 0]
    c_j = cv2.undistortPoints(x_j[:, None], cam_j.K, None, R=R2, P=P2)[:, 0]
    # (OpenCV picks vertical stereo, aligned columns, when the baseline is mostly along y)
    horizontal = abs(P2[0, 3]) > abs(P2[1, 3])
    aligned = 1 if horizontal else 0
    assert np.abs(c_i[:, aligned] - c_j[:, aligned]).max() < 1e-6
    # ... and its rectified baseline axis is the same direction as ours (in the world)
    cv_x_world = (R1 @ cam_i.R)[0 if horizontal else 1]
    assert abs(abs(cv_x_world @ R_rect[0]) - 1.0) < 1e-9
    # the rectified rotation is a proper rotation; H_i is K_new R_rect R_i^T K_i^-1
    np.testing.assert_allclose(R_rect @ R_rect.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R_rect) > 0
    np.testing.assert_allclose(H_i, K_new @ R_rect @ cam_i.R.T @ np.linalg.inv(cam_i.K),
                               atol=1e-12)


def test_rectification_batched_torch_matches_numpy_and_is_differentiable():
    rng = np.random.default_rng(11)
    pairs = [(random_camera(rng, distortion=False), random_camera(rng, distortion=False))
             for _ in range(3)]
    args = [np.stack([getattr(p[k], a) for p in pairs]) for k in (0, 1) for a in 'KRt']
    H_i, H_j, R_rect, K_new = rectification_homographies(*args)
    targs = [torch.tensor(a, requires_grad=True) for a in args]
    tH_i, tH_j, tR, tK = rectification_homographies(*targs)
    np.testing.assert_allclose(tH_i.detach().numpy(), H_i, atol=1e-12)
    np.testing.assert_allclose(tH_j.detach().numpy(), H_j, atol=1e-12)
    tH_i.sum().backward()
    assert targs[2].grad is not None and torch.isfinite(targs[2].grad).all()
    for k, (a, b) in enumerate(pairs):
        X = random_points(rng, 20)
        r_i = apply_homography(H_i[k], a.project(X))
        r_j = apply_homography(H_j[k], b.project(X))
        assert np.abs(r_i[:, 1] - r_j[:, 1]).max() < 1e-6
