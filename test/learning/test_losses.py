"""Heatmap MSE with masks and stages, the objective's weights, soft-argmax and the
temporal-difference loss against brute-force computations."""
import numpy as np
import pytest
import torch

from monet_ros.learning.losses import (
    masked_heatmap_mse,
    objective,
    soft_argmax,
    temporal_difference_loss,
)


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
    t.update(T=torch.tensor(4.0), R=torch.tensor(5.0))
    assert objective(t, 5.0, 1.0, 0.5, 2.0).item() == 14.0 + 2.0 + 10.0
    t['R'] = torch.tensor(float('nan'))            # a weight of 0 leaves the term out
    assert objective(t, 5.0, 1.0, 0.5, 0.0).item() == 16.0


def test_soft_argmax_finds_the_centre_of_a_gaussian():
    centres = [(3.3, 4.6), (7.0, 2.25), (5.5, 5.5)]
    heat = torch.tensor(np.stack([gaussian(10, 12, u, v, 1.5) for u, v in centres]))
    # within 1% of a heatmap pixel (the floor cuts the sampled Gaussian a little unevenly)
    np.testing.assert_allclose(soft_argmax(heat * 0.3).numpy(), centres, atol=1e-2)


def test_temporal_difference_loss_is_the_mean_jump_beyond_epsilon():
    rng = np.random.default_rng(1)
    a = rng.uniform(0, 10, size=(5, 3, 2))
    b = a + rng.normal(scale=2.0, size=a.shape)
    b[0, 0] = a[0, 0]                                   # a zero jump: finite gradient
    jump = np.linalg.norm(b - a, axis=-1)
    expected = np.maximum(jump - 1.5, 0.0).mean()
    ta = torch.tensor(a, requires_grad=True)
    loss = temporal_difference_loss(ta, torch.tensor(b), 1.5)
    assert loss.item() == pytest.approx(expected, abs=1e-9)
    loss.backward()
    assert torch.isfinite(ta.grad).all()
    assert (ta.grad[torch.tensor(jump <= 1.5)] == 0).all()       # free within epsilon
    with pytest.raises(ValueError, match='temporal_difference_loss'):
        temporal_difference_loss(ta, torch.tensor(b[:2]), 1.0)
