"""The training recipe speaks up: a semi-supervised term without data and a detector that does
not fit its own labels are warned about loudly (stderr and the run summary); bootstrapping's
cut-off follows the detector's own peak values; the learning-rate schedule is the documented
one."""
import math

from helpers.blobs import blob_recording
import numpy as np
import pytest
import torch

from monet_ros.learning.config import TrainConfig
from monet_ros.learning.trainer import Trainer, TrainingData

TINY = dict(architecture='small', input_size=48, width=16, batch_labelled=4, batch_pseudo=4,
            batch_unlabeled=1, views_per_instant=3, lr=3e-3, device='cpu',
            aug_rotate_deg=10.0, aug_photometric=0.5, lr_warmup_steps=5)


@pytest.fixture(scope='module')
def recording():
    torch.set_num_threads(1)
    return blob_recording(num_views=4, T=20, C=3, labelled=(2, 9), label_views=(0, 1))


def trainer_for(recording, **options):
    config = TrainConfig(**{**TINY, **options})
    return Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)))


def test_bootstrapping_round_without_pseudo_labels_warns_on_stderr_and_in_summary(
        recording, capfd):
    trainer = trainer_for(recording, mode='bootstrap1', steps=6, bootstrap_confidence=1e6)
    summary = trainer.run(progress=False)
    assert trainer.bootstrap_done == 1
    assert summary['bootstrap'][0]['pseudo_labels'] == 0
    messages = [m for m in summary['warnings'] if 'kept no pseudo-label' in m]
    assert len(messages) == 1 and 'L_B gets no bootstrapped data' in messages[0]
    assert 'WARNING: bootstrapping round 1' in capfd.readouterr().err


def test_spatial_mode_without_two_labelled_views_warns_at_start():
    single = blob_recording(num_views=3, T=8, C=2, labelled=(2,), label_views=(0,))
    said = []
    config = TrainConfig(**{**TINY, 'mode': 'spatial', 'steps': 2})
    trainer = Trainer(config, TrainingData(single, config, (48, 48), (12, 12)), warn=said.append)
    assert trainer.pseudo_label_count == 0
    assert len(said) == 1 and 'no pseudo-labels' in said[0] and 'L_B gets no data' in said[0]
    assert trainer.warnings == said


@pytest.mark.parametrize('options, expected', [
    (dict(mode='reprojection', batch_unlabeled=0), 'batch_unlabeled 0: the reprojection'),
    (dict(mode='monet', batch_unlabeled=0), 'batch_unlabeled 0: the anchored epipolar term L_E'),
    (dict(mode='reprojection', views_per_instant=2), 'gets 2 views of each unlabeled instant'),
    (dict(mode='reprojection', views_per_instant=0, bootstrap_min_views=5),
     'bootstrap_min_views 5 inlier views but gets 4 views'),
    (dict(mode='temporal_difference', batch_unlabeled=1), 'L_T needs pairs'),
    (dict(mode='temporal_difference', batch_unlabeled=0), 'batch_unlabeled 0: the temporal')])
def test_a_term_on_unlabeled_instants_without_data_warns_at_start(recording, options,
                                                                   expected):
    """L_E / L_T / L_R configured but unable to get data (no unlabeled instant per step, fewer
    views than RANSAC's inliers): said once at the start, never trained on silently."""
    said = []
    config = TrainConfig(**{**TINY, 'steps': 2, **options})
    Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)), warn=said.append)
    assert len(said) == 1 and expected in said[0], said
    said.clear()                    # the same settings with that term's weight 0: no warning
    weight = {'reprojection': 'lambda_r', 'monet': 'lambda_e',
              'temporal_difference': 'lambda_t'}[options['mode']]
    config = TrainConfig(**{**TINY, 'steps': 2, **options, weight: 0.0})
    Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)), warn=said.append)
    assert said == []


def test_the_objective_in_words_names_each_weighted_term(recording):
    assert trainer_for(recording, mode='reprojection', steps=10, epipolar_warmup=0.3,
                       lambda_r=2.0).objective_text() == 'L_L + 1 L_B + 2 L_R from step 3'
    assert trainer_for(recording, mode='supervised', steps=10).objective_text() == 'L_L'
    assert trainer_for(recording, mode='monet', steps=10, epipolar_warmup=0.0,
                       lambda_p=0.0).objective_text() == (
        'L_L + 5 L_E once the detector fits its labelled crops (median <= 1 heatmap px)')


def test_underfit_detector_warns_and_a_fitted_one_does_not(recording):
    said = []
    config = TrainConfig(**{**TINY, 'mode': 'supervised', 'steps': 2, 'lr': 1e-6})
    data = TrainingData(recording, config, (48, 48), (12, 12))
    summary = Trainer(config, data, warn=said.append).run(progress=False)
    assert summary['fit']['median_heat'] > config.fit_warning_heat_px
    assert len(said) == 1 and 'does not fit its own labels' in said[0]
    # independent check of the reported fit: the labelled views' detections vs the labels
    fitted = Trainer(TrainConfig(**{**TINY, 'mode': 'supervised', 'steps': 150}), data,
                     warn=said.append)
    summary = fitted.run(progress=False)
    points, _ = fitted.detect(data.labelled_instants)
    labels = recording.labels[data.labelled_instants]
    ok = np.isfinite(labels[..., 0])
    err = np.linalg.norm(points[ok] - labels[ok], axis=-1)
    assert summary['fit']['count'] == ok.sum() == 2 * 2 * 3
    assert summary['fit']['median_px'] == pytest.approx(np.median(err))
    # heatmap pixels: the crop's scale (input 48 -> heatmap 12 over each view's crop box)
    side = data.boxes[data.labelled_instants][..., 2] - data.boxes[data.labelled_instants][..., 0]
    heat_err = err * np.broadcast_to((12.0 / side)[..., None], ok.shape)[ok]
    assert summary['fit']['median_heat'] == pytest.approx(np.median(heat_err))
    assert summary['fit']['median_heat'] < config.fit_warning_heat_px
    assert len(said) == 1 and summary['warnings'] == []


def test_bootstrap_cutoff_is_relative_to_the_labelled_peaks(recording):
    trainer = trainer_for(recording, mode='bootstrap1', steps=60,
                          bootstrap_relative_confidence=0.5)
    trainer.run(steps=30, progress=False)          # the round is due at step 30
    peaks = trainer.labelled_peaks()
    cutoff, median = trainer.bootstrap_cutoff()
    assert median == pytest.approx(np.median(peaks))
    assert cutoff == pytest.approx(0.5 * median)
    stats = trainer.bootstrap_stats[0]
    assert stats['cutoff'] == pytest.approx(cutoff, rel=1e-6)
    assert stats['pseudo_labels'] > 0


def test_learning_rate_schedule_warmup_then_cosine(recording):
    config = TrainConfig(steps=50, lr=1e-3, lr_schedule='cosine', lr_warmup_steps=10,
                         lr_final=0.1)
    factors = np.array([config.lr_factor(k) for k in range(50)])
    np.testing.assert_allclose(factors[:10], np.arange(1, 11) / 11)
    assert factors[10] == pytest.approx(1.0)
    assert factors[49] == pytest.approx(0.1)
    mid = 10 + (49 - 10) / 2
    assert config.lr_factor(mid) == pytest.approx(0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi / 2)))
    assert np.all(np.diff(factors[10:]) <= 1e-12)
    step = TrainConfig(lr_schedule='step', lr_warmup_steps=0, lr_decay=0.5, lr_decay_every=4)
    assert [step.lr_factor(k) for k in (0, 3, 4, 9)] == [1.0, 1.0, 0.5, 0.25]
    trainer = trainer_for(recording, mode='supervised', steps=12, lr_warmup_steps=4)
    seen = [trainer.step()['lr'] for _ in range(12)]
    np.testing.assert_allclose(seen, [3e-3 * trainer.config.lr_factor(k) for k in range(12)])


def test_l_e_that_never_starts_is_said(recording, capfd):
    """A detector that never fits its labelled crops to epipolar_fit_heat_px never gets L_E
    (its anchors would be guesses): the run says so instead of reporting a mode it did not
    train."""
    trainer = trainer_for(recording, mode='epipolar', steps=6, epipolar_warmup=0.0,
                          epipolar_fit_heat_px=1e-9)
    summary = trainer.run(progress=False)
    assert trainer.epipolar_started is None and 'E' not in trainer.last_terms
    said = [w for w in summary['warnings'] if 'L_E never started' in w]
    assert len(said) == 1 and 'epipolar_fit_heat_px' in said[0], summary['warnings']
    assert 'L_E never started' in capfd.readouterr().err
