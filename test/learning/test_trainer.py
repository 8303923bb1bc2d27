"""The trainer on a tiny learnable scene: every loss term falls, checkpoints resume exactly,
bootstrapping rounds run on schedule."""
import shutil

from helpers.blobs import blob_recording
import numpy as np
import pytest
import torch

from monet_ros.config import ConfigError
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.trainer import Trainer, TrainingData
from monet_ros.models import load_checkpoint

TINY = dict(architecture='small', input_size=48, width=16, batch_labelled=4, batch_pseudo=4,
            batch_unlabeled=1, views_per_instant=3, lr=3e-3, eval_fraction=0.25,
            device='cpu', aug_rotate_deg=10.0, aug_photometric=0.5)


@pytest.fixture(scope='module')
def recording():
    torch.set_num_threads(1)          # 2 shared cores: one thread is fastest
    return blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))


def test_monet_training_reduces_every_loss_term(recording):
    config = TrainConfig(mode='monet', steps=80, epipolar_warmup=0.3, **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    trainer = Trainer(config, data)
    # the paper's L_B: spatial (2 labelled instants x 2 views x 3) + spatiotemporal tracks
    assert trainer.pseudo_label_count > 2 * 2 * 3
    before = trainer.evaluate_terms()
    trainer.run(progress=False)
    after = trainer.evaluate_terms()
    assert set(trainer.last_terms) >= {'L', 'B', 'E', 'loss', 'lr'}
    for term in ('L', 'B'):
        assert after[term] < 0.5 * before[term], (term, before, after)
    # L_E (anchored) started once the detector fitted its labelled crops and trained on;
    # whether it helps is measured by bench/accuracy.py against its exact control (a tiny
    # net on 12x12 maps tells nothing either way), here: it does not break the fit
    assert trainer.epipolar_started is not None
    assert np.isfinite(trainer.last_terms['E']) and trainer.last_terms['E'] >= 0
    assert trainer.fit_error()['median_heat'] < 1.0


def test_checkpoint_resume_continues_identically(recording, tmp_path):
    config = TrainConfig(mode='monet', steps=8, checkpoint_every=4, epipolar_warmup=0.25,
                         **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    first = Trainer(config, data, tmp_path / 'a')
    first.run(4, progress=False)
    assert (tmp_path / 'a' / 'checkpoints' / 'step_000004.pt').is_file()
    shutil.copytree(tmp_path / 'a', tmp_path / 'b')      # the state a killed run leaves
    first.run(progress=False)
    resumed = Trainer.resume(tmp_path / 'b', data)
    assert resumed.step_count == 4
    resumed.run(progress=False)
    assert resumed.step_count == 8
    for (name, a), b in zip(first.model.state_dict().items(),
                            resumed.model.state_dict().values()):
        assert torch.equal(a, b), name
    assert first.last_terms == resumed.last_terms
    model, meta = load_checkpoint(tmp_path / 'b' / 'model.pt')
    assert meta['step'] == 8 and meta['mode'] == 'monet' and meta['keypoints'] == ['k0', 'k1',
                                                                                    'k2']
    assert meta['held_out_from_stamp_ns'] == int(recording.stamps[18])
    log = (tmp_path / 'b' / 'train_log.csv').read_text().splitlines()
    assert [int(r.split(',')[0]) for r in log[1:]] == list(range(1, 9))


def test_resume_refuses_a_changed_config(recording, tmp_path):
    config = TrainConfig(mode='spatial', steps=2, checkpoint_every=2, **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    Trainer(config, data, tmp_path).run(progress=False)
    other = TrainConfig(mode='spatial', steps=4, checkpoint_every=2,
                        **{**TINY, 'lr': 1e-3})
    with pytest.raises(ValueError, match='lr'):
        Trainer.resume(tmp_path, data, config=other)
    longer = TrainConfig(mode='spatial', steps=4, checkpoint_every=2, **TINY)
    assert Trainer.resume(tmp_path, data, config=longer).step_count == 2


def test_bootstrap_rounds_run_on_schedule_and_add_labels(recording):
    # a short tracking horizon: the spatiotemporal seed leaves instants to bootstrap
    config = TrainConfig(mode='bootstrap2', steps=60, bootstrap_confidence=0.2,
                         bootstrap_threshold_px=6.0, track_horizon=1, **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    trainer = Trainer(config, data)
    assert trainer.bootstrap_steps() == [20, 40]
    start = trainer.pseudo_label_count
    trainer.run(progress=False)
    assert trainer.bootstrap_done == 2
    assert trainer.pseudo_label_count > start
    # the bootstrapped labels lie near the truth (exact projections of the moving blobs)
    boot = np.isfinite(trainer.pseudo_only[data.unlabeled_instants, ..., 0])
    truth = np.stack([np.stack([c.project(recording.gt3d[t]) for c in recording.cameras])
                      for t in data.unlabeled_instants])
    err = np.linalg.norm(trainer.pseudo_only[data.unlabeled_instants] - truth, axis=-1)[boot]
    assert np.median(err) < 3.0, np.median(err)


def test_monet_uses_the_spatiotemporal_pseudo_labels(recording):
    def pseudo(mode, **options):
        config = TrainConfig(mode=mode, steps=10, **options, **TINY)
        return Trainer(config, TrainingData(recording, config, (48, 48), (12, 12))).pseudo

    spatial = pseudo('spatial')
    tracked = pseudo('spatiotemporal')
    assert np.isfinite(tracked).sum() > np.isfinite(spatial).sum()   # tracking added labels
    np.testing.assert_array_equal(pseudo('monet'), tracked)           # the paper's L_B
    np.testing.assert_array_equal(pseudo('bootstrap1'), tracked)      # seeded from it too
    np.testing.assert_array_equal(pseudo('monet', monet_temporal=False), spatial)
    np.testing.assert_array_equal(pseudo('bootstrap2_epipolar'), spatial)


def test_pseudo_max_frames_keeps_the_first_frames_of_each_track(recording):
    """L_B trains on tracked labels at most pseudo_max_frames from their seed; the rest of
    the track is dropped from L_B only (crop boxes are the same with and without the
    gate)."""
    def data_and_pseudo(**options):
        config = TrainConfig(mode='spatiotemporal', steps=10, **options, **TINY)
        data = TrainingData(recording, config, (48, 48), (12, 12))
        return data, Trainer(config, data).pseudo

    full_data, full = data_and_pseudo(pseudo_max_frames=0)
    gated_data, gated = data_and_pseudo(pseudo_max_frames=2)
    np.testing.assert_array_equal(gated_data.boxes, full_data.boxes)
    frames = full_data.tracks().frames_from_seed                              # (T, C)
    assert np.isfinite(frames).any() and (frames[np.isfinite(frames)] > 2).any()
    near = (frames <= 2)[:, None, :] & np.ones(full.shape[1], bool)[None, :, None]
    has_full, has_gated = np.isfinite(full[..., 0]), np.isfinite(gated[..., 0])
    spatial = np.isfinite(TrainingData(recording, TrainConfig(mode='spatial', **TINY),
                                       (48, 48), (12, 12)).initial_pseudo_labels(
        TrainConfig(mode='spatial').spec, None)[..., 0])
    np.testing.assert_array_equal(has_gated, has_full & (near | spatial))
    np.testing.assert_array_equal(gated[has_gated], full[has_gated])
    assert has_gated.sum() < has_full.sum()
    # nothing dropped silently: the run summary counts what the gate took away
    assert full_data.pseudo_gate is None
    assert gated_data.pseudo_gate['dropped'] == (has_full & ~has_gated).sum()
    assert gated_data.pseudo_gate['confirmed'] == 0
    # beyond the gate, a label that another seed's track confirms is kept
    agreement = full_data.tracks().agreement
    with np.errstate(invalid='ignore'):
        confirmed = agreement <= 1.0
    verified_data, verified = data_and_pseudo(pseudo_max_frames=2, pseudo_agreement_px=1.0)
    np.testing.assert_array_equal(np.isfinite(verified[..., 0]),
                                  has_full & (near | spatial | confirmed))
    assert verified_data.pseudo_gate['confirmed'] == (has_full & ~near & confirmed).sum()
    assert (has_full & ~near & confirmed).any()         # the test sees both kinds
    with pytest.raises(ConfigError, match='pseudo_agreement_px'):
        TrainConfig(pseudo_max_frames=0, pseudo_agreement_px=4.0)


def test_every_mode_sees_the_same_number_of_images_per_step(recording):
    from monet_ros.learning.config import MODES

    counts = {}
    for mode in MODES:
        config = TrainConfig(mode=mode, steps=10, epipolar_warmup=0.5, **TINY)
        trainer = Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)))
        for step in (0, 6):                       # before and after the L_E warm-up
            trainer.step_count = step
            plan = trainer._batch_plan()
            counts[(mode, step)] = sum(len(part[1]) for part in plan)
            kinds = {part[0] for part in plan}
            # L_E alone: part 'E'; with L_T or L_R (L_E or not): part 'U'
            spec = trainer.spec
            alone = spec.epipolar and not (spec.temporal_difference or spec.reprojection)
            assert ('E' in kinds) == (alone and step == 6), (mode, step)
            assert ('U' in kinds) == (spec.unlabeled and not alone and step == 6), (mode, step)
            assert ('B' in kinds) == trainer.spec_uses_pseudo, (mode, step)
    # batch_labelled + batch_pseudo + batch_unlabeled x views_per_instant = 4 + 4 + 1 x 3
    assert set(counts.values()) == {11}, counts


def plans(trainer, steps):
    """The batch plan of each step: [[(kind, (N, 2) (instant, view)), ...], ...]."""
    out = []
    for _ in range(steps):
        trainer.step()
        out.append([(part[0], part[1].copy()) for part in trainer.last_plan])
    return out


# temporal_epsilon 0: every jump counts (12x12 heatmaps move by less than the default 1 px)
NEW_TERM = dict(batch_unlabeled=2, temporal_epsilon=0.0)
# L_E from its first step and every confident view an anchor: an untrained net neither fits
# its labels nor agrees across views
L_E_NOW = dict(epipolar_fit_heat_px=1e3, epipolar_agreement_px=1e3)


@pytest.mark.parametrize('mode, field, weight, extra', [
    ('epipolar', 'lambda_e', 5.0, L_E_NOW), ('monet', 'lambda_e', 5.0, L_E_NOW),
    ('monet', 'lambda_p', 1.0, {}), ('temporal_difference', 'lambda_t', 1.0, NEW_TERM),
    ('reprojection', 'lambda_r', 1.0, NEW_TERM),
    ('reprojection_epipolar', 'lambda_e', 5.0, dict(NEW_TERM, **L_E_NOW))])
def test_a_terms_exact_control_has_the_identical_batch_plan(recording, mode, field, weight,
                                                            extra):
    """The run with a term's weight 0 draws the same instants and views at every step (and
    the same augmentation: the RNG does not depend on the weights), while the weights do
    change the training."""
    runs = {}
    for w in (weight, 0.0):
        config = TrainConfig(mode=mode, steps=6, epipolar_warmup=0.5,
                             **dict(TINY, **extra, **{field: w}))
        trainer = Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)))
        runs[w] = (plans(trainer, 6), trainer)
    (with_term, a), (control, b) = runs[weight], runs[0.0]
    kinds = [[kind for kind, _ in step] for step in with_term]
    term = {'lambda_e': 'E', 'lambda_p': 'B', 'lambda_t': 'T', 'lambda_r': 'R'}[field]
    part = 'U' if term in 'TR' or mode == 'reprojection_epipolar' else term
    assert sum(part in k for k in kinds) >= 3, kinds        # the term is in the plan
    assert kinds == [[kind for kind, _ in step] for step in control]
    for step_a, step_b in zip(with_term, control):
        for (_, pairs_a), (_, pairs_b) in zip(step_a, step_b):
            np.testing.assert_array_equal(pairs_a, pairs_b)
    assert a.rng.bit_generator.state == b.rng.bit_generator.state
    assert a.last_terms[term] > 0 and a.last_terms['loss'] != b.last_terms['loss']


def test_l_e_added_to_l_r_keeps_l_r_s_plan_and_waits_for_a_fit(recording):
    """reprojection_epipolar at lambda_e 0 is `reprojection` step for step (same crops,
    same loss): L_E's exact control is the default recipe; and L_E does not start before the
    detector fits its labelled crops (here: never, to 1e-9 heatmap px)."""
    out = {}
    for mode, lam in (('reprojection', 5.0), ('reprojection_epipolar', 0.0),
                      ('reprojection_epipolar', 5.0)):
        config = TrainConfig(mode=mode, steps=6, epipolar_warmup=0.5, lambda_e=lam,
                             epipolar_fit_heat_px=1e-9, **dict(TINY, **NEW_TERM))
        trainer = Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)))
        out[mode, lam] = (plans(trainer, 6), trainer)
    (p_r, t_r), (p_c, t_c), (_, t_e) = out.values()
    for step_a, step_b in zip(p_r, p_c):
        assert [k for k, _ in step_a] == [k for k, _ in step_b]
        for (_, a), (_, b) in zip(step_a, step_b):
            np.testing.assert_array_equal(a, b)
    assert t_r.last_terms['loss'] == t_c.last_terms['loss']
    assert t_e.epipolar_started is None and 'E' not in t_e.last_terms
    assert 'once the detector fits' in t_e.objective_text()


def test_config_errors_name_the_field():
    with pytest.raises(ConfigError, match='mode'):
        TrainConfig(mode='magic')
    with pytest.raises(ConfigError, match='lambda_e'):
        TrainConfig(lambda_e=-1.0)
    with pytest.raises(ConfigError, match='input_size'):
        TrainConfig(input_size=50)


def test_validate_reports_divergence_and_reprojection(recording):
    config = TrainConfig(mode='spatial', steps=30, **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    trainer = Trainer(config, data)
    before = trainer.validate()
    trainer.run(progress=False)
    after = trainer.validate()
    assert before['instants'] == after['instants'] == 6
    assert after['reprojection_px'] < before['reprojection_px']
    assert after['epipolar_divergence'] >= 0.0


def test_temporal_difference_pairs_consecutive_instants_in_the_same_views(recording):
    config = TrainConfig(mode='temporal_difference', steps=4, epipolar_warmup=0.0,
                         **dict(TINY, batch_unlabeled=3))
    trainer = Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)))
    for _ in range(4):
        trainer.step()
        kind, pairs, k = trainer.last_plan[-1]
        assert kind == 'U' and len(pairs) == 3 * k          # the images a step always has
        inst, views = pairs[:, 0].reshape(3, k), pairs[:, 1].reshape(3, k)
        assert (inst[1] == inst[0] + 1).all() and (views[1] == views[0]).all()
        assert set(inst[:2].ravel()) <= set(trainer.data.unlabeled_instants)
        assert 'T' in trainer.last_terms


def ground_truth_part(trainer, recording):
    """The 'U' part of a step (not augmented) and its projected ground truth: (batch, pairs,
    k, truth (N, C, 2) image px, points (N, C, 2) heatmap px)."""
    from monet_ros.learning.pseudo_labels import project_to_views

    kind, pairs, k = trainer._batch_plan()[-1]
    batch = trainer.data.cache.views(pairs[:, 0], pairs[:, 1])
    T, V = recording.num_instants, recording.num_views
    truth = project_to_views(recording.gt3d.reshape(-1, 3), recording.cameras).reshape(
        V, T, -1, 2).transpose(1, 0, 2, 3)[pairs[:, 0], pairs[:, 1]]
    return batch, pairs, k, truth, batch.to_heatmap(truth)


def perfect_maps(points, shift=None):
    """(N, C, 12, 12) Gaussians (sigma 1) at heatmap points (N, C, 2), optionally one
    (row, keypoint, offset) moved: the maps of a perfect (or once wrong) detector."""
    from monet_ros.models import render_heatmaps

    moved = points.copy()
    if shift is not None:
        row, c, offset = shift
        moved[row, c] += offset
    return render_heatmaps(torch.as_tensor(moved, dtype=torch.float32), (12, 12), 1.0)


def test_reprojection_targets_are_the_views_consensus(recording):
    """L_R's targets: a perfect detector's maps give back the ground truth; one view moved by
    6 heatmap px (about 14 image px, beyond bootstrap_threshold_px) is outvoted by the other
    three and gets the truth as its target."""
    config = TrainConfig(mode='reprojection', steps=4, epipolar_warmup=0.0,
                         **dict(TINY, batch_unlabeled=2, views_per_instant=0))
    trainer = Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)))
    batch, pairs, k, truth, points = ground_truth_part(trainer, recording)
    assert k == recording.num_views == 4
    target = trainer._reprojection_targets(perfect_maps(points), batch, slice(None), pairs, k,
                                           1.0)
    np.testing.assert_allclose(target, points, atol=1e-3)
    heat = perfect_maps(points, shift=(1, 2, (6.0, 0.0)))
    moved = trainer._reprojection_targets(heat, batch, slice(None), pairs, k, 1.0)
    np.testing.assert_allclose(moved, points, atol=1e-3)          # the moved view included
    # below the confidence cut-off (a share of the labelled peak) nothing is a target
    low = trainer._reprojection_targets(heat * 0.2, batch, slice(None), pairs, k, 1.0)
    assert np.isnan(low).all()


def test_temporal_difference_term_is_the_ground_truth_motion_beyond_epsilon(recording):
    """On a perfect detector's maps L_T is the frame-to-frame motion of the ground truth in
    the first frame's heatmap px (an independent computation from the projected 3D truth)."""
    config = TrainConfig(mode='temporal_difference', steps=4, epipolar_warmup=0.0,
                         **dict(TINY, batch_unlabeled=4, temporal_epsilon=0.25))
    trainer = Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)))
    batch, pairs, k, truth, points = ground_truth_part(trainer, recording)
    terms = trainer._unlabeled_terms([perfect_maps(points)], batch, slice(None), pairs, k, 1.0)
    rows = np.arange(len(pairs)).reshape(4, k)
    now, nxt = rows[0::2].ravel(), rows[1::2].ravel()
    motion = np.linalg.norm(batch.to_heatmap(truth[nxt], now) - points[now], axis=-1)
    expected = np.maximum(motion - 0.25, 0.0).mean()
    assert expected > 0.01                                   # the blobs move
    assert terms['T'].item() == pytest.approx(expected, abs=0.02)
