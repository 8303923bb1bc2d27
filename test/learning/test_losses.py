"""Heatmap MSE with masks and stages against a brute-force computation."""
import numpy as np
import pytest
import torch

from monet_ros.learning.losses import masked_heatmap_mse, objective


def gaussian(h, w, u, v, sigma):
    yy, xx = np.mgrid[0:h, 0:w]
    return np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma ** 2))


def test_masked_mse_matches_brute_force_over_stages_and_channels():
    rng = np.random.default_rng(0)
    stages = [torch.tensor(rng.normal(size=(2, 3, 8, 10)), dtype=torch.float32)
              for _ in range(2)]
    points = np.array([[[2.0, 3.0], [np.nan, np.nan], [7.5, 1.25]],
                       [[np.nan, np.nan], [4.0, 4.0], [np.nan, np.nan]]])
    loss = masked_heatmap_mse(stages, points, sigma=1.5)
    expected = 0.0
    for s in stages:
        errs = []
        for b in range(2):
            for c in range(3):
                if np.isfinite(points[b, c, 0]):
                    g = gaussian(8, 10, points[b, c, 0], points[b, c, 1], 1.5)
                    errs.append(((s[b, c].numpy() - g) ** 2).sum())
        expected += np.mean(errs)
    assert loss.item() == pytest.approx(expected, rel=1e-5)


def test_perfect_prediction_is_zero_and_unlabelled_gives_attached_zero():
    pts = torch.tensor([[[3.0, 4.0]]])
    target = torch.tensor(gaussian(9, 9, 3.0, 4.0, 2.0), dtype=torch.float32)[None, None]
    assert masked_heatmap_mse([target], pts, 2.0).item() == pytest.approx(0.0, abs=1e-10)
    pred = torch.zeros(1, 1, 9, 9, requires_grad=True)
    loss = masked_heatmap_mse([pred], torch.full((1, 1, 2), float('nan')), 2.0)
    loss.backward()
    assert loss.item() == 0.0 and pred.grad is not None


def test_objective_weights():
    t = {'L': torch.tensor(1.0), 'E': torch.tensor(2.0), 'B': torch.tensor(3.0)}
    assert objective(t, 5.0, 1.0).item() == 14.0
    assert objective({'L': torch.tensor(1.0)}, 5.0, 1.0).item() == 1.0
