"""Rectified epipolar divergence against brute-force line max-pooling in the original heatmaps."""
from helpers.epipolar_reference import (
    kl_rows,
    line_row_max_torch,
    plane_angle,
    plane_frame,
    plane_row_max_numpy,
    random_heatmap_pair,
    rect_row_normals,
    stack,
)
import numpy as np
import pytest
import torch

from monet_ros.geometry import fundamental_matrix
from monet_ros.learning import epipolar_divergence, rectify_pair
from monet_ros.models import render_heatmaps

SIZE = (46, 46)


@pytest.fixture(scope='module')
def scenes():
    """Random camera pairs with two keypoints: on one epipolar plane in both views, and
    displaced 2.5 px across the epipolar line in view j."""
    rng = np.random.default_rng(21)
    out = []
    for _ in range(3):
        cams = random_heatmap_pair(rng)
        X = rng.uniform(-0.3, 0.3, size=3)
        x_i, x_j = (c.project(X[None])[0] for c in cams)
        farther = cams[1].project((cams[0].center + 1.2 * (X - cams[0].center))[None])[0]
        along = (farther - x_j) / np.linalg.norm(farther - x_j)
        x_off = x_j + 2.5 * np.array([-along[1], along[0]])
        h_i = render_heatmaps(torch.tensor(np.array([[x_i, x_i]])), SIZE, 1.5)
        h_j = render_heatmaps(torch.tensor(np.array([[x_j, x_off]])), SIZE, 1.5)
        out.append((cams, X, h_i, h_j))
    return out


def test_rows_are_epipolar_planes_and_agree_with_brute_force(scenes):
    for cams, X, h_i, h_j in scenes:
        K, R, t = stack(cams)
        geo = (K[:1], R[:1], t[:1], K[1:], R[1:], t[1:])
        rect = rectify_pair(h_i, h_j, *geo)
        div = epipolar_divergence(h_i, h_j, *geo)[0].numpy()
        assert rect.valid.all()
        rows = rect.theta.shape[1]
        # The brute force names planes by its own angle; convert each row's plane.
        y, z = rect.R_rect[0, 1].numpy(), rect.R_rect[0, 2].numpy()
        e1, u0, v0 = plane_frame(cams[0], cams[1], ref=z + 0.3 * y)
        assert np.allclose(rect.R_rect[0, 0].numpy(), e1)
        wdirs = np.sin(rect.theta[0].numpy())[:, None] * y + np.cos(rect.theta[0].numpy())[
            :, None] * z
        thetas = np.arctan2(wdirs @ v0, wdirs @ u0)
        q_i = plane_row_max_numpy(h_i[0].numpy(), cams[0], e1, u0, v0, thetas)
        q_j = plane_row_max_numpy(h_j[0].numpy(), cams[1], e1, u0, v0, thetas)
        q_ri = rect.heat_i[0].amax(-1).numpy()
        q_rj = rect.heat_j[0].amax(-1).numpy()
        # Same argmax plane, or for a peak between two rows one the brute force rates within
        # 5% of its maximum: rows are sampled every ~0.5 px, the brute force every 0.05 px, and
        # bilinear heatmaps have cusps at pixel centres. Same profiles, close divergences.
        for a, b in ((q_ri, q_i), (q_rj, q_j)):
            best = np.take_along_axis(b, a.argmax(-1)[:, None], -1)[:, 0]
            assert np.all((a.argmax(-1) == b.argmax(-1)) | (best >= 0.95 * b.max(-1)))
            assert np.abs(a.argmax(-1) - b.argmax(-1)).max() <= 1
            pa, pb = a / a.sum(-1, keepdims=True), b / b.sum(-1, keepdims=True)
            assert np.abs(pa - pb).max() < 0.1 * pb.max()
        brute = kl_rows(q_i, q_j)
        assert abs(div[0] - brute[0]) < 0.02 and abs(div[1] - brute[1]) < 0.1 * brute[1]
        assert brute[1] > 10 * brute[0]
        # The keypoint's own plane (from X, independent of the rectification) is the argmax.
        theta_x = plane_angle(X, cams[0], e1, u0, v0)
        step = abs(thetas[1] - thetas[0])
        assert abs(thetas[q_ri[0].argmax()] - theta_x) <= step
        assert rows >= 40


def test_batched_torch_brute_force_matches_numpy_reference(scenes):
    """The bench's baseline (line sampling, torch) computes the same row maxima."""
    cams, _, h_i, h_j = scenes[0]
    K, R, t = stack(cams)
    rect = rectify_pair(h_i, h_j, K[:1], R[:1], t[:1], K[1:], R[1:], t[1:])
    normals = rect_row_normals(rect.R_rect, rect.theta)
    y, z = rect.R_rect[0, 1].numpy(), rect.R_rect[0, 2].numpy()
    e1, u0, v0 = plane_frame(cams[0], cams[1], ref=z)
    wdirs = np.sin(rect.theta[0].numpy())[:, None] * y + np.cos(rect.theta[0].numpy())[
        :, None] * z
    thetas = np.arctan2(wdirs @ v0, wdirs @ u0)
    for k, (cam, h) in enumerate(((cams[0], h_i), (cams[1], h_j))):
        fast = line_row_max_torch(h, K[k:k + 1], R[k:k + 1], normals, spacing=0.25)[0].numpy()
        ref = plane_row_max_numpy(h[0].numpy(), cam, e1, u0, v0, thetas)
        assert np.abs(fast - ref).max() < 0.01


def test_rectified_rows_are_corresponding_epipolar_lines_covering_the_window():
    """Rectify coordinate maps: each rectified sample reads back its source pixel. Rows of
    i and j must satisfy x_j^T F x_i = 0 (geometry.fundamental_matrix), cover every pixel of
    both windows, and sample them about as densely as the input grid."""
    cams = random_heatmap_pair(np.random.default_rng(8))
    h, w = SIZE
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64),
                          torch.arange(w, dtype=torch.float64), indexing='ij')
    maps = torch.stack([u, v, torch.ones_like(u)])[None]           # (1, 3, h, w)
    K, R, t = stack(cams)
    rect = rectify_pair(maps, maps, K[:1], R[:1], t[:1], K[1:], R[1:], t[1:])
    F = fundamental_matrix(*cams)
    src = []
    for r in (rect.heat_i[0], rect.heat_j[0]):
        inside = (r[2] > 1 - 1e-9).numpy()                          # all 4 neighbours inside
        src.append((r[0].numpy(), r[1].numpy(), inside))
    (ui, vi, ini), (uj, vj, inj) = src
    rows = rect.theta.shape[1]
    checked = 0
    for k in range(rows):
        if ini[k].sum() < 2 or inj[k].sum() < 2:
            continue
        xi = np.c_[ui[k][ini[k]], vi[k][ini[k]], np.ones(ini[k].sum())]
        xj = np.c_[uj[k][inj[k]], vj[k][inj[k]], np.ones(inj[k].sum())]
        lines = xi @ F.T                                             # lines in view j
        lines /= np.linalg.norm(lines[:, :2], axis=1, keepdims=True)
        assert np.abs(xj @ lines.T).max() < 1e-6
        checked += 1
    assert checked > 0.5 * rows
    for uu, vv, ok in src:
        pts = np.c_[uu[ok], vv[ok]]
        centres = np.c_[u.numpy().ravel(), v.numpy().ravel()]
        nearest = np.min(np.linalg.norm(centres[:, None] - pts[None], axis=-1), axis=1)
        # Covers the window: a sample near every pixel centre (the border pixels' samples
        # that read the zero padding are not counted as "inside").
        border = (centres == 0).any(1) | (centres[:, 0] == w - 1) | (centres[:, 1] == h - 1)
        assert nearest[~border].max() < 0.75 and nearest[border].max() < 1.5
        col_step = np.hypot(np.diff(uu, axis=1), np.diff(vv, axis=1))[ok[:, 1:] & ok[:, :-1]]
        row_step = np.hypot(np.diff(uu, axis=0), np.diff(vv, axis=0))[ok[1:] & ok[:-1]]
        assert 0.3 < np.median(col_step) < 0.7 and col_step.max() < 1.0
        assert 0.6 < np.median(row_step) < 1.2 and row_step.max() < 2.0
