"""symmetric_epipolar_loss (L_E until issue 36, kept as a diagnostic): lowest where the
keypoints are right, a closed form that matches sampling, all view pairs; and training with
the trainer's L_E (the anchored epipolar_loss) on a detector that fits its labels keeps its
peaks sharp, its exact control drawing the same crops."""
import copy
import math

from helpers.blobs import blob_recording
from helpers.epipolar_reference import ring_rig, stack
import numpy as np
import pytest
import torch

from monet_ros.learning.config import TrainConfig
from monet_ros.learning.losses import (
    fundamental_matrices,
    heatmap_distribution,
    peak_contrast,
)
from monet_ros.learning.symmetric_epipolar import (
    symmetric_epipolar_loss as epipolar_loss,
)
from monet_ros.learning.symmetric_epipolar import (
    symmetric_epipolar_terms as epipolar_loss_terms,
)
from monet_ros.learning.trainer import Trainer, TrainingData
from monet_ros.models import render_heatmaps

SIZE = (32, 32)


def tilted_ring(num_views=6):
    """Heatmap cameras of a non-coplanar ring: centres alternately 0.4 m up and down."""
    cams = []
    for k in range(num_views):
        height = 1.5 + (0.4 if k % 2 else -0.4)
        cams.append(ring_rig(num_views, SIZE, height=height)[k])
    return cams


@pytest.fixture(scope='module')
def scene():
    cams = tilted_ring()
    rng = np.random.default_rng(7)
    X = rng.uniform(-0.4, 0.4, (3, 10, 3))                          # (B, C, 3)
    pts = np.stack([np.stack([c.project(x) for c in cams]) for x in X])   # (B, V, C, 2)
    K, R, t = (a.expand(3, *a.shape) for a in stack(cams, torch.float32))
    return cams, pts, K, R, t


def render(points, sigma):
    flat = torch.tensor(points.reshape(-1, points.shape[2], 2), dtype=torch.float32)
    return render_heatmaps(flat, SIZE, sigma).reshape(*points.shape[:3], *SIZE)


def test_ideal_gaussians_score_lower_than_floor_broadened_shifted_or_flat(scene):
    _, pts, K, R, t = scene
    ideal = render(pts, 1.0)
    shifted = pts.copy()
    shifted[:, 0] += [2.0, 0.0]                  # view 0 two heatmap px to the right
    scores = {name: float(epipolar_loss(h, K, R, t)) for name, h in (
        ('ideal', ideal), ('floor', ideal + 0.02), ('broadened', render(pts, 5.0)),
        ('shifted', render(shifted, 1.0)), ('uniform', torch.full_like(ideal, 0.5)))}
    for name in ('floor', 'broadened', 'shifted', 'uniform'):
        assert scores['ideal'] < scores[name], scores
    # the spread of a sigma-1 map above the 0.1 floor is under a pixel: the ideal score is
    # about a heatmap pixel, flat maps score about the window's spread
    assert 0.5 < scores['ideal'] < 1.5 and scores['uniform'] > 8.0, scores


def test_closed_form_matches_sampled_symmetric_epipolar_distance(scene):
    """E[d^2] from the maps' moments equals the brute-force double sum over all pixel pairs
    of p_i(a) p_j(b) d^2(a, b), d^2 with the line normals at the means (as documented)."""
    _, pts, K, R, t = scene
    heat = render(pts[:1, :2, :2], 2.0) + 0.3 * render(pts[:1, :2, :2] + 3.0, 1.5)
    terms = epipolar_loss_terms(heat, K[:1, :2], R[:1, :2], t[:1, :2])
    F, _ = fundamental_matrices(K[0, 0], R[0, 0], t[0, 0], K[0, 1], R[0, 1], t[0, 1])
    F = F.numpy()
    p = heatmap_distribution(heat).double().numpy()[0]                    # (V, C, h, w)
    h, w = SIZE
    vv, uu = np.mgrid[0:h, 0:w]
    x = np.stack([uu.ravel(), vv.ravel(), np.ones(h * w)], -1)           # (h w, 3)
    for c in range(2):
        pi, pj = p[0, c].ravel(), p[1, c].ravel()
        mi, mj = pi @ x, pj @ x
        lj, li = F @ mi, F.T @ mj
        inv = 0.5 * (1 / (lj[:2] @ lj[:2]) + 1 / (li[:2] @ li[:2]))
        e = x @ F @ x.T                        # e[b, a] = x_b^T F x_a: b in view j, a in i
        expected = pj @ (e ** 2) @ pi * inv
        assert float(terms['distance'][0, 0, c]) == pytest.approx(math.sqrt(expected),
                                                                  rel=1e-4)


def test_every_pair_of_present_views_is_used(scene):
    _, pts, K, R, t = scene
    heat = render(pts, 1.0)
    terms = epipolar_loss_terms(heat, K, R, t)
    assert terms['pairs'].shape == (15, 2) and bool(terms['pair_used'].all())
    valid = torch.ones(3, 6, dtype=torch.bool)
    valid[0, 2] = False
    terms = epipolar_loss_terms(heat, K, R, t, valid)
    assert int(terms['pair_used'].sum()) == 3 * 15 - 5 == terms['pairs_possible']
    none = torch.zeros(3, 6, dtype=torch.bool)
    loss = epipolar_loss(heat.requires_grad_(), K, R, t, none)
    assert float(loss.detach()) == 0.0 and loss.requires_grad


def test_gradient_moves_a_shifted_peak_back_onto_the_epipolar_lines(scene):
    _, pts, K, R, t = scene
    shifted = pts.copy()
    shifted[:, 0] += [0.0, 2.0]
    target = render(pts, 1.0)
    heat = render(shifted, 1.0).requires_grad_()
    opt = torch.optim.SGD([heat], lr=0.5)
    before = float(epipolar_loss(heat, K, R, t))
    for _ in range(20):
        opt.zero_grad()
        epipolar_loss(heat, K, R, t).backward()
        opt.step()
    assert float(epipolar_loss(heat, K, R, t)) < before
    # the view the others agree on is moved towards its true peak
    err_before = float((render(shifted, 1.0)[:, 0] - target[:, 0]).square().sum())
    assert float((heat.detach()[:, 0] - target[:, 0]).square().sum()) < err_before


def test_bad_shapes_name_the_argument(scene):
    _, pts, K, R, t = scene
    heat = render(pts, 1.0)
    with pytest.raises(ValueError, match='outputs'):
        epipolar_loss(heat[0], K, R, t)
    with pytest.raises(ValueError, match='K must be'):
        epipolar_loss(heat, K[:, :2], R, t)
    with pytest.raises(ValueError, match='valid'):
        epipolar_loss(heat, K, R, t, torch.ones(3, 5, dtype=torch.bool))


TINY = dict(architecture='small', input_size=48, width=16, batch_labelled=6, batch_pseudo=0,
            batch_unlabeled=2, views_per_instant=0, lr=3e-3, device='cpu',
            aug_rotate_deg=5.0, aug_photometric=0.3, sigma=1.0)


def unlabeled_contrast(trainer):
    """Mean detached peak contrast of the detector's maps on every view of the unlabeled
    training instants (no augmentation)."""
    data = trainer.data
    inst = data.unlabeled_instants
    V = data.recording.num_views
    pairs = np.stack(np.meshgrid(inst, np.arange(V), indexing='ij'), -1).reshape(-1, 2)
    trainer.model.eval()
    with torch.no_grad():
        heat = trainer.model(data.cache.views(pairs[:, 0], pairs[:, 1]).images)[-1]
    trainer.model.train()
    return float(peak_contrast(heat).mean())


@pytest.mark.slow
def test_training_with_it_keeps_a_fitted_detector_sharp():
    torch.set_num_threads(1)
    recording = blob_recording(num_views=4, T=20, C=3, labelled=(2, 9, 15))
    fit_config = TrainConfig(mode='supervised', steps=150, **TINY)
    data = TrainingData(recording, fit_config, (48, 48), (12, 12))
    fitted = Trainer(fit_config, data)
    fitted.run(progress=False)
    assert fitted.fit_error()['median_heat'] < 1.0            # it fits its labels
    before = unlabeled_contrast(fitted)
    after, plans = {}, {}
    for lambda_e in (0.0, 5.0):
        config = TrainConfig(mode='epipolar', steps=20, epipolar_warmup=0.0,
                             lambda_e=lambda_e, **TINY)
        trainer = Trainer(config, data, model=copy.deepcopy(fitted.model))
        plans[lambda_e] = []
        while trainer.step_count < config.steps:
            trainer.step()
            plans[lambda_e].append(trainer.last_plan)
        assert trainer.epipolar_started == 0          # it fits its labels from the start
        assert 'E' in trainer.last_terms         # reported by the control too (not trained)
        after[lambda_e] = unlabeled_contrast(trainer)
    assert after[5.0] >= 0.97 * before, (before, after)
    assert after[5.0] >= 0.97 * after[0.0], (before, after)
    # the exact control: the same crops at every step
    for a, b in zip(plans[0.0], plans[5.0]):
        assert [p[0] for p in a] == [p[0] for p in b]
        assert all(np.array_equal(p[1], q[1]) for p, q in zip(a, b))
