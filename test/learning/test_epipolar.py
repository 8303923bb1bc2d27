"""Epipolar divergence: consistency, monotonicity, gradients, degenerate pairs, L_E."""
import math

from helpers.epipolar_reference import random_heatmap_pair, ring_rig, stack
import numpy as np
import pytest
import torch

from monet_ros.learning import (
    epipolar_divergence,
    multiview_epipolar_loss,
    rectify_pair,
    valid_view_pairs,
)
from monet_ros.models import render_heatmaps

SIZE = (46, 46)
SIGMA = 1.5


def gaussians(points, size=SIZE, dtype=torch.float64):
    """(B, C, h, w) heatmaps of Gaussians at points (B, C, 2)."""
    return render_heatmaps(torch.as_tensor(np.asarray(points), dtype=dtype), size, SIGMA)


def pair_tensors(cams, dtype=torch.float64):
    K, R, t = stack(cams, dtype)
    return K[:1], R[:1], t[:1], K[1:], R[1:], t[1:]


def divergence(h_i, h_j, cams, **kw):
    return epipolar_divergence(h_i, h_j, *pair_tensors(cams, h_i.dtype), **kw)


def epipolar_frame_in_j(cams, X):
    """Projection of X in view j and unit directions along / across its epipolar line."""
    cam_i, cam_j = cams
    x_j = cam_j.project(X[None])[0]
    farther = cam_j.project((cam_i.center + 1.2 * (X - cam_i.center))[None])[0]
    along = (farther - x_j) / np.linalg.norm(farther - x_j)
    return x_j, along, np.array([-along[1], along[0]])


@pytest.fixture(scope='module')
def pairs():
    rng = np.random.default_rng(3)
    out = []
    for _ in range(4):
        cams = random_heatmap_pair(rng)
        out.append((cams, rng.uniform(-0.3, 0.3, size=3)))
    return out


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_consistent_peaks_give_near_zero_divergence(pairs, dtype):
    for cams, X in pairs:
        x_i, x_j = (c.project(X[None])[0] for c in cams)
        off = epipolar_frame_in_j(cams, X)[2]
        h_i = gaussians([[x_i]], dtype=dtype)
        d0, valid = divergence(h_i, gaussians([[x_j]], dtype=dtype), cams, return_valid=True)
        d3 = divergence(h_i, gaussians([[x_j + 3 * off]], dtype=dtype), cams)
        assert valid.all() and d0.dtype == dtype and d0.shape == (1, 1)
        assert float(d0) < 0.05, float(d0)
        assert float(d3) > 20 * float(d0) and float(d3) > 0.5


def test_along_line_stays_small_across_grows_monotonically(pairs):
    for cams, X in pairs:
        x_i = cams[0].project(X[None])[0]
        x_j, along, across = epipolar_frame_in_j(cams, X)
        steps = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 6.0])
        h_i = gaussians([[x_i]] * len(steps))
        K_i, R_i, t_i, K_j, R_j, t_j = (a.expand(len(steps), *a.shape[1:])
                                        for a in pair_tensors(cams))
        d_along = epipolar_divergence(h_i, gaussians([[x_j + s * along] for s in steps]),
                                      K_i, R_i, t_i, K_j, R_j, t_j)[:, 0]
        d_across = epipolar_divergence(h_i, gaussians([[x_j + s * across] for s in steps]),
                                       K_i, R_i, t_i, K_j, R_j, t_j)[:, 0]
        assert float(d_along.max()) < 0.05, d_along
        assert torch.all(d_across[1:] > d_across[:-1]), d_across
        assert float(d_across[2]) > 5 * float(d_along.max())


def test_gradients_reach_both_heatmaps_and_are_finite(pairs):
    cams, X = pairs[0]
    x_i, x_j = (c.project(X[None])[0] for c in cams)
    torch.manual_seed(0)
    for dtype in (torch.float32, torch.float64):
        h_i = (gaussians([[x_i, x_i + 2]], dtype=dtype) + 0.01).requires_grad_()
        h_j = (gaussians([[x_j + 3, x_j]], dtype=dtype) + 0.01).requires_grad_()
        divergence(h_i, h_j, cams).sum().backward()
        for g in (h_i.grad, h_j.grad):
            assert torch.isfinite(g).all() and g.abs().amax(dim=(-1, -2)).min() > 0


def test_gradcheck_float64_tiny():
    rng = np.random.default_rng(5)
    cams = random_heatmap_pair(rng, size=(9, 9))
    torch.manual_seed(1)
    h_i = (torch.rand(1, 2, 9, 9, dtype=torch.float64) + 0.05).requires_grad_()
    h_j = (torch.rand(1, 2, 9, 9, dtype=torch.float64) + 0.05).requires_grad_()
    geo = pair_tensors(cams)
    assert torch.autograd.gradcheck(
        lambda a, b: epipolar_divergence(a, b, *geo, rows=7, cols=9), (h_i, h_j))


def test_degenerate_pairs_are_flagged_not_nan():
    rng = np.random.default_rng(7)
    cam_i, cam_j = random_heatmap_pair(rng)
    # j on the ray through i's window centre (epipole inside i's window), and j == i.
    behind = cam_i.center + 0.5 * (np.zeros(3) - cam_i.center)
    on_ray = type(cam_j)('on_ray', cam_j.K, cam_j.dist, cam_j.R, -cam_j.R @ behind,
                         cam_j.width, cam_j.height)
    for j in (on_ray, cam_i):
        h_i = gaussians([[[20.0, 20.0]]]).requires_grad_()
        h_j = gaussians([[[25.0, 22.0]]]).requires_grad_()
        d, valid = divergence(h_i, h_j, [cam_i, j], return_valid=True)
        assert not valid.any() and torch.equal(d, torch.zeros(1, 1, dtype=d.dtype))
        d.sum().backward()
        assert torch.isfinite(h_i.grad).all() and torch.isfinite(h_j.grad).all()


def dense_min_angle_deg(cam_i, cam_j, size=SIZE, step=0.5):
    """Smallest angle between the baseline line and any ray of either window (dense grid)."""
    base = cam_j.center - cam_i.center
    base = base / np.linalg.norm(base)
    worst = 90.0
    for cam in (cam_i, cam_j):
        u, v = np.meshgrid(np.arange(-0.5, size[1] - 0.5 + 1e-9, step),
                           np.arange(-0.5, size[0] - 0.5 + 1e-9, step))
        rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1) @ (
            cam.R.T @ np.linalg.inv(cam.K)).T
        cos = np.abs(rays @ base) / np.linalg.norm(rays, axis=1)
        worst = min(worst, math.degrees(math.acos(min(cos.max(), 1.0))))
    return worst


def test_valid_view_pairs_skips_degenerate_pairs_of_a_ring():
    cams = ring_rig(8, height=0.3)        # opposite cameras see each other behind the subject
    K, R, t = (a[None] for a in stack(cams))
    b, i, j = valid_view_pairs(K, R, t, SIZE, min_angle_deg=10.0)
    got = {(int(a), int(c)) for a, c in zip(i, j)}
    assert set(b.tolist()) == {0}
    for a in range(8):
        for c in range(a + 1, 8):
            angle = dense_min_angle_deg(cams[a], cams[c])
            if abs(angle - 10.0) > 0.5:
                assert ((a, c) in got) == (angle > 10.0), (a, c, angle)
    opposite = {(a, a + 4) for a in range(4)}
    adjacent = {(a, a + 1) for a in range(7)} | {(0, 7)}
    assert not opposite & got and adjacent <= got
    # Missing views drop their pairs; a coincident duplicate camera is never paired.
    valid = torch.ones(1, 8, dtype=torch.bool)
    valid[0, 2] = False
    _, i2, j2 = valid_view_pairs(K, R, t, SIZE, valid)
    assert {(int(a), int(c)) for a, c in zip(i2, j2)} == {p for p in got if 2 not in p}
    K3, R3, t3 = (torch.cat([a[:, :2], a[:, :1]], 1) for a in (K, R, t))
    _, i3, j3 = valid_view_pairs(K3, R3, t3, SIZE)
    assert (0, 2) not in {(int(a), int(c)) for a, c in zip(i3, j3)}


def test_multiview_loss_matches_per_pair_divergences():
    cams = ring_rig(5)
    K, R, t = (a[None].expand(2, *a.shape) for a in stack(cams))
    rng = np.random.default_rng(11)
    X = rng.uniform(-0.4, 0.4, size=(2, 3, 3))                     # (B, C, 3)
    pts = np.stack([np.stack([c.project(X[b]) for c in cams]) for b in range(2)])
    pts[1, 3] += 2.5                                                # one inconsistent view
    heat = gaussians(pts.reshape(10, 3, 2)).reshape(2, 5, 3, *SIZE).requires_grad_()
    valid = torch.ones(2, 5, dtype=torch.bool)
    valid[0, 4] = False
    loss = multiview_epipolar_loss(heat, K, R, t, valid)
    b, i, j = valid_view_pairs(K, R, t, SIZE, valid)
    rows, cols = 60, 60
    terms = []
    for bb, a, c in zip(b.tolist(), i.tolist(), j.tolist()):     # reference: one pair at a time
        for x, y in ((a, c), (c, a)):
            terms.append(epipolar_divergence(
                heat[bb, x][None], heat[bb, y][None], K[bb, x][None], R[bb, x][None],
                t[bb, x][None], K[bb, y][None], R[bb, y][None], t[bb, y][None],
                rows=rows, cols=cols))
    ref = torch.cat(terms).mean()
    fixed = multiview_epipolar_loss(heat, K, R, t, valid, rows=rows, cols=cols)
    assert torch.allclose(fixed, ref, rtol=1e-9, atol=1e-12)
    assert abs(float(loss.detach()) - float(ref)) < 0.1 * float(ref)
    assert 0 < float(multiview_epipolar_loss(heat[:1], K[:1], R[:1], t[:1])) < 0.05
    assert float(multiview_epipolar_loss(heat[1:], K[1:], R[1:], t[1:])) > 0.2
    loss.backward()
    assert torch.isfinite(heat.grad).all() and heat.grad[0, 4].abs().max() == 0
    assert heat.grad[1, 3].abs().max() > 0
    none = multiview_epipolar_loss(heat, K, R, t, torch.zeros(2, 5, dtype=torch.bool))
    assert float(none) == 0.0 and none.requires_grad


def test_bad_inputs_name_the_argument():
    cams = ring_rig(2)
    h = gaussians([[[20.0, 20.0]]])
    geo = pair_tensors(cams)
    with pytest.raises(ValueError, match='heat_i'):
        epipolar_divergence(h[0], h, *geo)
    with pytest.raises(ValueError, match='camera j'):
        epipolar_divergence(h, h, *geo[:3], geo[3][0], geo[4], geo[5])
    with pytest.raises(ValueError, match='min_angle_deg'):
        epipolar_divergence(h, h, *geo, min_angle_deg=95)
    with pytest.raises(ValueError, match='heat'):
        multiview_epipolar_loss(h, *geo[:3])


def test_divergence_equals_kl_of_rectified_row_maxima_with_same_gradients():
    """epipolar_divergence re-samples only each row's argmax with autograd; it must equal
    KL of the fully rectified heatmaps' row maxima (rectify_pair + amax), gradients too."""
    cams = random_heatmap_pair(np.random.default_rng(4))
    torch.manual_seed(2)
    h_i = torch.rand(2, 3, *SIZE, dtype=torch.float64, requires_grad=True)
    h_j = torch.rand(2, 3, *SIZE, dtype=torch.float64, requires_grad=True)
    geo = [a.expand(2, *a.shape[1:]) for a in pair_tensors(cams)]
    ours = epipolar_divergence(h_i, h_j, *geo, eps=1e-6)
    rect = rectify_pair(h_i, h_j, *geo, overlap=True)     # the rows both windows see
    q_i, q_j = rect.heat_i.amax(-1), rect.heat_j.amax(-1)
    q_i, q_j = q_i / q_i.sum(-1, keepdim=True), q_j / q_j.sum(-1, keepdim=True)
    ref = (q_i * (torch.log(q_i + 1e-6) - torch.log(q_j + 1e-6))).sum(-1)
    assert torch.allclose(ours, ref, rtol=1e-12, atol=1e-15)
    weights = torch.rand_like(ref)
    g_ours = torch.autograd.grad((ours * weights).sum(), (h_i, h_j))
    g_ref = torch.autograd.grad((ref * weights).sum(), (h_i, h_j))
    for a, b in zip(g_ours, g_ref):
        assert torch.allclose(a, b, rtol=1e-10, atol=1e-14)
