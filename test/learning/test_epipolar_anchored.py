"""epipolar_loss, the anchored one-sided L_E (issue 36): descended alone on free Gaussian
centres it moves the poor views onto the truth and leaves the accurate ones where they were
(mixed confidence, one view 8 px off, a start collapsed on the body's centroid), a confident
wrong view drags no view, the anchor gets no gradient and sharpening a map at a fixed mean
does not lower it; the symmetric form (symmetric_epipolar_loss) does drag the right views,
which is why it is no longer the loss."""
from helpers.epipolar_reference import ring_rig, stack
import numpy as np
import pytest
import torch

from monet_ros.learning.losses import anchored_epipolar_terms, epipolar_loss
from monet_ros.learning.symmetric_epipolar import symmetric_epipolar_loss
from monet_ros.models import render_heatmaps

SIZE = (46, 46)
B, V, C = 8, 6, 14
ACCURATE, POOR = [0, 2, 4], [1, 3, 5]
MIXED_PEAKS = [1.0, 0.6, 0.95, 0.6, 0.9, 0.6]


@pytest.fixture(scope='module')
def scene():
    """Six heatmap cameras of a non-coplanar ring, 8 instants x 14 keypoints within +-0.45 m
    of the subject's centre: truth (B, V, C, 2) heatmap px, the centroid's projection
    (B, V, 2), K, R, t tensors."""
    cams = [ring_rig(V, SIZE, height=1.5 + (0.5 if k % 2 else -0.3))[k] for k in range(V)]
    rng = np.random.default_rng(0)
    X = rng.uniform(-0.45, 0.45, (B, C, 3))
    truth = np.stack([np.stack([c.project(x) for c in cams]) for x in X])
    centroid = np.stack([np.stack([c.project(x.mean(0)[None])[0] for c in cams]) for x in X])
    K, R, t = (a.expand(B, *a.shape).float() for a in stack(cams))
    return truth, centroid, K, R, t


def maps(centres, peaks):
    """(B, V, C, h, w) Gaussian maps (sigma 2 heatmap px) at `centres`, view v's peak
    peaks[v] (the detector's confidence)."""
    pk = torch.as_tensor(peaks, dtype=torch.float32)[None, :, None, None, None]
    flat = centres.reshape(-1, C, 2)
    return render_heatmaps(flat, SIZE, 2.0).reshape(B, V, C, *SIZE) * pk


def descend(start, peaks, K, R, t, loss=epipolar_loss, steps=300, lr=0.1):
    """Adam on the free centres of the maps, the loss alone; -> the centres (B, V, C, 2)."""
    centres = torch.tensor(start, dtype=torch.float32, requires_grad=True)
    opt = torch.optim.Adam([centres], lr=lr)
    for _ in range(steps):
        value = loss(maps(centres, peaks), K, R, t)
        opt.zero_grad()
        value.backward()
        opt.step()
    return centres.detach().numpy().astype(np.float64)


def error(points, truth, views):
    return np.linalg.norm(points - truth, axis=-1)[:, views]


def test_poor_views_move_onto_the_truth_and_accurate_ones_stay(scene):
    truth, _, K, R, t = scene
    rng = np.random.default_rng(1)
    start = truth + rng.normal(0, 0.5, truth.shape)
    start[:, POOR] = truth[:, POOR] + rng.normal(0, 3.0, truth[:, POOR].shape)
    end = descend(start, MIXED_PEAKS, K, R, t)
    assert error(start, truth, POOR).mean() > 3.0
    assert error(end, truth, POOR).mean() < 1.0
    assert np.median(error(end, truth, POOR)) < 0.8
    # the accurate views: as accurate as before, and close to where they were
    assert error(end, truth, ACCURATE).mean() < error(start, truth, ACCURATE).mean() + 0.1
    assert np.linalg.norm(end - start, axis=-1)[:, ACCURATE].mean() < 0.5
    # the symmetric form drags the accurate views towards the poor ones
    sym = descend(start, MIXED_PEAKS, K, R, t, loss=symmetric_epipolar_loss)
    assert error(sym, truth, ACCURATE).mean() > error(end, truth, ACCURATE).mean() + 0.5


@pytest.mark.parametrize('outlier_peak', [0.6, 1.0])
def test_one_view_8px_off(scene, outlier_peak):
    """A less confident view 8 px off is pulled back; a view 8 px off that is the most
    confident of all anchors nothing (no other view agrees with it) and drags no view."""
    truth, _, K, R, t = scene
    rng = np.random.default_rng(2)
    start = truth + rng.normal(0, 0.5, truth.shape)
    d = rng.normal(size=(B, C, 2))
    start[:, 3] = truth[:, 3] + 8.0 * d / np.linalg.norm(d, axis=-1, keepdims=True)
    peaks = [1.0, 0.95, 0.9, outlier_peak, 0.85, 0.8]
    others = [0, 1, 2, 4, 5]
    end = descend(start, peaks, K, R, t)
    assert error(end, truth, others).mean() < error(start, truth, others).mean() + 0.3
    if outlier_peak < 0.8:
        assert error(end, truth, [3]).mean() < 1.0
    terms = anchored_epipolar_terms(maps(torch.tensor(start, dtype=torch.float32), peaks),
                                    K, R, t)
    assert terms['anchors'][:, 3].float().mean() < 0.2       # it rarely agrees with anyone
    assert terms['anchors'][:, 0].float().mean() > 0.8


def test_a_start_collapsed_on_the_centroid_is_pulled_back(scene):
    """The poor views start with every keypoint on the projection of the body's centroid (a
    configuration consistent across those views, which the symmetric forms score as well as
    the truth); the confident views pull them back to the truth."""
    truth, centroid, K, R, t = scene
    rng = np.random.default_rng(3)
    start = truth + rng.normal(0, 0.5, truth.shape)
    start[:, POOR] = np.repeat(centroid[:, POOR, None], C, 2)
    end = descend(start, MIXED_PEAKS, K, R, t)
    before = error(start, truth, POOR)
    after = error(end, truth, POOR)
    assert before.mean() > 6.0
    assert np.median(after) < 1.0
    assert after.mean() < 0.3 * before.mean()
    assert error(end, truth, ACCURATE).mean() < error(start, truth, ACCURATE).mean() + 0.1


def test_anchor_gets_no_gradient_and_a_shift_is_penalised(scene):
    truth, _, K, R, t = scene
    start = truth.copy()
    start[:, 1] += [2.0, -1.5]
    centres = torch.tensor(start, dtype=torch.float32)
    heat = maps(centres, MIXED_PEAKS).requires_grad_()
    loss = epipolar_loss(heat, K, R, t)
    loss.backward()
    loss = loss.detach()
    grad = heat.grad.abs().sum(dim=(0, 2, 3, 4))                          # per view
    assert grad[0] == 0                     # the most confident view: an anchor only
    assert grad[1] > 0
    assert float(loss) > float(epipolar_loss(maps(torch.tensor(truth, dtype=torch.float32),
                                                  MIXED_PEAKS), K, R, t)) + 0.1


def test_sharpening_at_a_fixed_mean_does_not_lower_the_loss(scene):
    """Pixel-centred Gaussians of one peak height at sigma 2 and 1 (same means): the same
    loss, to rounding; only moving the mean changes it."""
    truth, _, K, R, t = scene
    centres = torch.tensor(np.round(truth) + [[1.0, 0.0]] * np.isin(
        np.arange(V), POOR)[None, :, None, None], dtype=torch.float32)
    pk = torch.tensor(MIXED_PEAKS)[None, :, None, None, None]
    values = []
    for sigma in (2.0, 1.0, 0.7):
        heat = render_heatmaps(centres.reshape(-1, C, 2), SIZE, sigma).reshape(
            B, V, C, *SIZE) * pk
        values.append(float(epipolar_loss(heat, K, R, t)))
    assert values[0] > 0.05
    # the same to 1% (the floor and the window's edge cut the Gaussians' tails a little)
    assert max(values) - min(values) < 1e-2 * values[0], values


def test_nothing_to_anchor_is_zero_attached_and_bad_inputs_are_named(scene):
    truth, _, K, R, t = scene
    heat = maps(torch.tensor(truth, dtype=torch.float32), [0.3] * V).requires_grad_()
    loss = epipolar_loss(heat, K, R, t)             # every peak below anchor_confidence
    assert float(loss) == 0.0 and loss.requires_grad
    with pytest.raises(ValueError, match='outputs'):
        epipolar_loss(heat[0], K, R, t)
    with pytest.raises(ValueError, match='K must be'):
        epipolar_loss(heat, K[:, :2], R, t)
    with pytest.raises(ValueError, match='valid must be'):
        epipolar_loss(heat, K, R, t, torch.ones(B, V + 1, dtype=torch.bool))
    with pytest.raises(ValueError, match='kernel_px'):
        epipolar_loss(heat, K, R, t, kernel_px=0.0)
    # views marked missing take no part: only one confident view left, nothing anchors
    valid = torch.zeros(B, V, dtype=torch.bool)
    valid[:, 0] = valid[:, 1] = True
    one = maps(torch.tensor(truth, dtype=torch.float32), [1.0, 0.4, 1.0, 1.0, 1.0, 1.0])
    assert float(epipolar_loss(one, K, R, t, valid)) == 0.0
