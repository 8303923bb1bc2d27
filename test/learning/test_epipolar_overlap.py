"""L_E compares only the epipolar planes both windows see, and its gradient does not leak
into each map's minimum through the non-negative shift."""
import numpy as np
import torch

from monet_ros.learning import epipolar_divergence, multiview_epipolar_loss
from monet_ros.learning.trainer import nonnegative
from monet_ros.models import render_heatmaps

SIZE = (46, 46)


def parallel_pair(shift_rows):
    """Two cameras side by side (baseline along x, same orientation): epipolar planes are
    image rows v = cy + f tan(theta). View j's heatmap window is shifted by `shift_rows`, so
    its row v_j sees the plane of view i's row v_j - shift_rows."""
    f = 40.0
    K_i = np.array([[f, 0, 22.5], [0, f, 22.5], [0, 0, 1.0]])
    K_j = K_i.copy()
    K_j[1, 2] += shift_rows
    t_j = np.array([-0.5, 0.0, 0.0])                  # centre of j at x = +0.5
    return [torch.as_tensor(a[None], dtype=torch.float64)
            for a in (K_i, np.eye(3), np.zeros(3), K_j, np.eye(3), t_j)]


def gaussians(points, sigma=1.5):
    return render_heatmaps(torch.as_tensor(np.asarray(points, np.float64)), SIZE, sigma)


def test_rows_outside_the_partner_window_contribute_nothing():
    # j sees the planes of i's rows -23 .. 22: the top half of i's window
    K_i, R_i, t_i, K_j, R_j, t_j = parallel_pair(23.0)
    x = 20.0
    h_j = gaussians([[[x - 8, 10.0 + 23.0]]])            # i's row 10 in j's window
    inside = gaussians([[[x, 10.0]]])
    outside = gaussians([[[x + 5, 38.0]]])                # a row j cannot see
    h_i = (inside + outside).requires_grad_(True)
    div = epipolar_divergence(h_i, h_j, K_i, R_i, t_i, K_j, R_j, t_j)
    alone = epipolar_divergence(inside, h_j, K_i, R_i, t_i, K_j, R_j, t_j)
    # the same plane in both views: ~0 divergence, with or without the blob outside
    assert float(alone) < 1e-3
    assert abs(float(div.detach()) - float(alone)) < 1e-9
    grad, = torch.autograd.grad(div.sum(), h_i)
    assert grad[0, 0, 26:].abs().max() == 0          # rows j cannot see: no gradient
    # a keypoint moved off the shared plane (inside the overlap) still counts
    moved = epipolar_divergence(gaussians([[[x, 16.0]]]), h_j, K_i, R_i, t_i, K_j, R_j, t_j)
    assert float(moved) > 100 * float(alone) + 0.1


def test_partner_windows_without_shared_planes_are_invalid_not_nan():
    geo = parallel_pair(60.0)                             # j sees only planes below i's window
    h = gaussians([[[20.0, 20.0]]]).requires_grad_(True)
    div, valid = epipolar_divergence(h, h, *geo, return_valid=True)
    assert not bool(valid[0]) and float(div) == 0.0


def test_the_minimum_shift_passes_no_gradient_to_the_minimum_pixel():
    K_i, R_i, t_i, K_j, R_j, t_j = parallel_pair(0.0)
    K = torch.stack([K_i, K_j], 1)
    R = torch.stack([R_i, R_j], 1)
    t = torch.stack([t_i, t_j], 1)
    heat = torch.cat([gaussians([[[20.0, 12.0]]]), gaussians([[[14.0, 30.0]]])])
    heat = heat - 0.2                                     # raw outputs may be negative
    heat[:, :, 45, 45] = -1.0                             # each map's unique minimum
    heat = heat[None].requires_grad_(True)               # (B=1, V=2, C=1, h, w)
    loss = multiview_epipolar_loss(nonnegative(heat), K, R, t)
    assert float(loss.detach()) > 0.01
    grad, = torch.autograd.grad(loss, heat)
    assert grad[0, :, 0, 45, 45].abs().max() == 0
    assert grad.abs().max() > 0
    # (through a non-detached shift, the minimum pixel would take minus the map's total)
    shifted = heat - heat.amin(dim=(-2, -1), keepdim=True)
    grad_attached, = torch.autograd.grad(multiview_epipolar_loss(shifted, K, R, t), heat)
    assert grad_attached[0, :, 0, 45, 45].abs().min() > 0


def test_partners_drawing_parallel_lines_through_a_keypoint_share_one_weight():
    from monet_ros.learning.epipolar import line_weights
    from monet_ros.synth.rig import look_at

    X = np.array([0.0, 0.0, 1.0])                    # a keypoint
    Y = np.array([-0.4, -0.5, 1.6])                  # another, off the plane below
    C_i, C_1 = np.array([3.0, 0.0, 0.0]), np.array([0.0, 3.0, 1.0])
    # C_2 lies in the epipolar plane (X, C_i, C_1): in view i, the lines that partners 1 and 2
    # draw through X coincide; C_3 is off that plane
    C_2 = C_i + 1.5 * (C_1 - C_i) - 0.5 * (X - C_i)
    C_3 = np.array([0.0, -3.0, 3.0])
    assert abs(np.dot(np.cross(C_1 - C_i, X - C_i), C_2 - C_i)) < 1e-12
    # view i looks at X, which lands on a pixel centre: its peak is exactly X's projection
    K = np.array([[40.0, 0, 22.0], [0, 40.0, 22.0], [0, 0, 1]])
    Rs = [look_at(C_i, X)] + [look_at(c, (0.0, 0.0, 1.1)) for c in (C_1, C_2, C_3)]
    ts = [-R @ c for R, c in zip(Rs, (C_i, C_1, C_2, C_3))]
    peaks = [[(K @ (R @ P + t))[:2] / (K @ (R @ P + t))[2] for P in (X, Y)]
             for R, t in zip(Rs, ts)]
    heat = gaussians(peaks)[None]                                  # (1, V=4, C=2, 46, 46)
    as_t = [torch.as_tensor(np.stack(a)[None]) for a in ([K] * 4, Rs, ts)]
    pair_valid = ~torch.eye(4, dtype=torch.bool)[None]
    # (far epipoles: lines through Y from partners 1 and 2 differ by ~1.9 degrees)
    w = line_weights(heat, *as_t, pair_valid, parallel_deg=1.0)[0]    # (i, j, C)
    np.testing.assert_allclose(w[0, 1:, 0].numpy(), [0.5, 0.5, 1.0])   # keypoint X
    np.testing.assert_allclose(w[0, 1:, 1].numpy(), [1.0, 1.0, 1.0])   # keypoint Y
    assert (w[torch.arange(4), torch.arange(4)] == 0).all()
