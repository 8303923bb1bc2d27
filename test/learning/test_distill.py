"""Distillation from filtered 3D (learning.distill): a perfect teacher's pseudo-labels are
the projected ground truth (checked against OpenCV's projection), the gate and the counts
agree with a brute-force count, units do not matter, and a run at lambda_d 0 is the exact
control of a run with L_D (the same batch plan, step for step)."""
from dataclasses import replace

import cv2
from helpers.blobs import blob_recording
import numpy as np
import pytest
import torch

from monet_ros.geometry.units import with_units
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.distill import align_to_instants, distilled_labels, label_errors
from monet_ros.learning.losses import masked_heatmap_mse
from monet_ros.learning.trainer import Trainer, TrainingData

TINY = dict(architecture='small', input_size=48, width=8, batch_labelled=4, batch_pseudo=4,
            batch_unlabeled=1, views_per_instant=3, lr=3e-3, eval_fraction=0.25,
            device='cpu', aug_rotate_deg=10.0, aug_photometric=0.5, batch_distill=4)


@pytest.fixture(scope='module')
def recording():
    torch.set_num_threads(1)
    return blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))


def opencv_projection(cameras, X):
    """(T, V, C, 2) projections of X (T, C, 3) by cv2.projectPoints, camera by camera."""
    out = []
    for cam in cameras:
        rvec = cv2.Rodrigues(np.asarray(cam.R, np.float64))[0]
        p, _ = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, np.asarray(cam.t, np.float64),
                                 np.asarray(cam.K, np.float64), np.asarray(cam.dist, np.float64))
        out.append(p.reshape(X.shape[0], X.shape[1], 2))
    return np.stack(out, axis=1)


def test_a_perfect_teacher_gives_the_projected_ground_truth(recording):
    cams, X = recording.cameras, recording.gt3d
    T, C = X.shape[:2]
    V = len(cams)
    cells = np.ones((T, V, C), bool)
    d = distilled_labels(X, np.zeros((T, C)), np.full((T, C), V), cams, cells)
    truth = opencv_projection(cams, X)
    inside = np.all((truth >= -0.5) & (truth <= np.array([[c.width, c.height] for c in cams])
                                       [None, :, None] - 0.5), axis=-1)
    kept = np.isfinite(d.points[..., 0])
    assert np.array_equal(kept, inside) and inside.sum() > 0.9 * inside.size
    np.testing.assert_allclose(d.points[kept], truth[kept], atol=1e-6)
    assert np.all(d.weight[kept] == 1.0) and np.all(d.weight[~kept] == 0.0)
    assert d.counts['kept'] == inside.sum() and d.counts['outside'] == (~inside).sum()
    assert label_errors(d.points, truth)['median_px'] < 1e-6


def test_the_gate_and_its_counts_match_a_brute_force_count(recording):
    cams, X = recording.cameras, recording.gt3d.copy()
    T, C = X.shape[:2]
    V = len(cams)
    rng = np.random.default_rng(3)
    error = rng.uniform(0, 12, (T, C))
    ncams = rng.integers(0, V + 1, (T, C))
    X[rng.random((T, C)) < 0.2] = np.nan
    cells = rng.random((T, V, C)) < 0.7
    d = distilled_labels(X, error, ncams, cams, cells, gate_px=8.0, min_views=3,
                         residual_px=2.0)
    truth = opencv_projection(cams, np.nan_to_num(X))
    counts = dict(cells=0, kept=0, no_3d=0, few_views=0, high_error=0, outside=0)
    for t in range(T):
        for v in range(V):
            for c in range(C):
                if not cells[t, v, c]:
                    continue
                counts['cells'] += 1
                u, w = truth[t, v, c]
                if not np.isfinite(X[t, c]).all():
                    counts['no_3d'] += 1
                elif ncams[t, c] < 3:
                    counts['few_views'] += 1
                elif error[t, c] > 8.0:
                    counts['high_error'] += 1
                elif not (-0.5 <= u <= cams[v].width - 0.5 and -0.5 <= w <= cams[v].height - 0.5):
                    counts['outside'] += 1
                else:
                    counts['kept'] += 1
                    assert d.weight[t, v, c] == pytest.approx(1 / (1 + (error[t, c] / 2) ** 2))
                    np.testing.assert_allclose(d.points[t, v, c], truth[t, v, c], atol=1e-6)
    assert {k: d.counts[k] for k in counts} == counts
    assert d.counts['kept'] == np.isfinite(d.points[..., 0]).sum() == (d.weight > 0).sum()


def test_units_do_not_change_the_pseudo_labels(recording):
    cams, X = recording.cameras, recording.gt3d
    T, C = X.shape[:2]
    cells = np.ones((T, len(cams), C), bool)
    args = (np.ones((T, C)), np.full((T, C), 4))
    metres = distilled_labels(X, *args, cams, cells)
    # the teacher's 3D in mm (a rig file in mm), labels for the metre rig: converted
    from_mm = distilled_labels(X * 1000.0, *args, cams, cells, units='mm')
    np.testing.assert_allclose(from_mm.points, metres.points, atol=1e-9, equal_nan=True)
    mm_cams = [c.replace(t=np.asarray(c.t) * 1000.0) for c in with_units(cams, 'mm')]
    in_mm = distilled_labels(X * 1000.0, *args, mm_cams, cells)
    np.testing.assert_allclose(in_mm.points, metres.points, atol=1e-6, equal_nan=True)
    assert in_mm.counts == metres.counts


def test_align_to_instants_places_rows_by_stamp():
    stamps = np.array([10, 20, 30, 40, 50])
    frames = np.array([40, 10, 30])                       # out of order, 20 and 50 missing
    values = np.array([[4.0], [1.0], [3.0]])
    out, found = align_to_instants(stamps, frames, values)
    assert found.tolist() == [True, False, True, True, False]
    assert out[found, 0].tolist() == [1.0, 3.0, 4.0] and np.isnan(out[~found]).all()


def test_weights_scale_the_heatmap_loss():
    torch.manual_seed(0)
    stages = [torch.rand(2, 3, 8, 8)]
    points = torch.tensor([[[2.0, 3.0], [4.0, 4.0], [5.0, 1.0]]] * 2)
    plain = masked_heatmap_mse(stages, points, 1.0)
    half = masked_heatmap_mse(stages, points, 1.0, torch.full((2, 3), 0.5))
    assert half.item() == pytest.approx(0.5 * plain.item(), rel=1e-6)
    # a weight of 0 on one keypoint removes its error but still counts it (L_D's average)
    w = torch.ones(2, 3)
    w[:, 2] = 0
    masked = points.clone()
    masked[:, 2] = float('nan')
    only = masked_heatmap_mse(stages, masked, 1.0)
    assert masked_heatmap_mse(stages, points, 1.0, w).item() == pytest.approx(
        only.item() * 2 / 3, rel=1e-6)


def _distilled_from_truth(trainer, recording):
    T, V, C, _ = trainer.data.labels.shape
    cells = np.ones((T, V, C), bool)
    return distilled_labels(recording.gt3d, np.full((T, C), 1.0), np.full((T, C), V),
                            recording.cameras, cells)


def test_lambda_d_zero_is_the_exact_control(recording):
    config = TrainConfig(mode='reprojection', steps=6, epipolar_warmup=0.0, **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    runs = []
    for weight in (1.0, 0.0):
        trainer = Trainer(replace(config, lambda_d=weight), data)
        d = _distilled_from_truth(trainer, recording)
        trainer.set_distilled(d.points, d.weight, 1)
        # labelled cells, the held-out tail and validation instants get none
        assert not np.isfinite(trainer.distilled[data.held_out]).any()
        assert not (np.isfinite(trainer.distilled[..., 0]) &
                    np.isfinite(data.labels[..., 0])).any()
        plans, terms = [], []
        for _ in range(config.steps):
            out = trainer.step()
            plans.append([(kind, p.tolist()) for kind, p, *_ in trainer.last_plan])
            terms.append(out)
        runs.append((plans, terms))
    (plans_d, terms_d), (plans_0, terms_0) = runs
    assert plans_d == plans_0
    assert all(any(kind == 'D' and len(p) == 4 for kind, p in plan) for plan in plans_d)
    # both compute L_D; only the run with lambda_d > 0 adds it to the loss
    first_d, first_0 = terms_d[0], terms_0[0]
    assert first_d['D'] == pytest.approx(first_0['D'], rel=1e-5) and first_d['D'] > 0
    assert first_d['loss'] == pytest.approx(first_0['loss'] + first_d['D'], rel=1e-4)
