"""Held-out labelled views: the online learner's accuracy criterion (issue 22 item 6).

The validation labels are never trained on (no L_L, no pseudo-label, no L_E instant, crops
not framed by them); the metric is the distance of Trainer.detect to those labels; a
checkpoint that is worse on them is not announced, however well its views agree."""
import json
import math

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import numpy as np
import pytest
import torch

from monet_ros.config import ConfigError
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.online import (
    PUBLISHED,
    LearnerConfig,
    OnlineLearner,
    publish_metric_key,
    should_publish,
)
from monet_ros.learning.trainer import (
    Trainer,
    TrainingData,
    crop_boxes,
    spread_instants,
    validation_split,
)
from monet_ros.models import build_model, save_checkpoint

TINY = dict(batch_labelled=4, batch_pseudo=4, batch_unlabeled=1, views_per_instant=3,
            lr=3e-3, eval_fraction=0.25, device='cpu', threads=1, validate_instants=4)
LABELLED = (2, 5, 9, 13)           # before the eval tail (instants 18..23 of 24)


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp('validation')
    rec = blob_recording(num_views=4, T=24, C=3, labelled=LABELLED, label_views=(0, 1))
    torch.manual_seed(0)
    save_checkpoint(root / 'init.pt', build_model('small', 3, input_size=[48, 48], width=16),
                    {'keypoints': ['k0', 'k1', 'k2']})
    return write_blob_folder(rec, root / 'data'), root / 'init.pt', rec


def test_validation_split_counts_the_tail_first_and_leaves_one_to_train():
    labelled = np.array([3, 7, 11, 15, 26])
    tail = np.arange(24, 30)
    assert validation_split(labelled, tail, 0.0).size == 0
    # 5 labelled instants x 0.2 -> 1: the tail's instant 26, nothing more
    np.testing.assert_array_equal(validation_split(labelled, tail, 0.2), [26])
    # x 0.6 -> 3: 26 + two of the four before the tail, evenly spread (runs 3 7 | 11 15)
    np.testing.assert_array_equal(validation_split(labelled, tail, 0.6), [3, 11, 26])
    # x 0.9 -> 4 wanted: three at most before the tail, one is left to train on
    np.testing.assert_array_equal(validation_split(labelled, tail, 0.9), [3, 11, 15, 26])
    np.testing.assert_array_equal(validation_split(labelled, np.arange(0), 0.9),
                                  [3, 7, 15, 26])
    assert validation_split([4], np.arange(0), 0.5).size == 0
    # the rule of `monet train --holdout-labelled`
    from monet_ros.commands.train_holdout import choose_holdout
    np.testing.assert_array_equal(choose_holdout([3, 7, 11, 15, 26], 2), [7, 15])
    np.testing.assert_array_equal(spread_instants(np.array([3, 7, 11, 15, 26]), 2), [7, 15])


def test_validation_instants_are_in_no_training_pool(scene):
    _, _, rec = scene
    config = TrainConfig(mode='monet', steps=12, epipolar_warmup=0.0, validation_labels=0.5,
                         seed=3, checkpoint_every=10 ** 6, **{k: v for k, v in TINY.items()
                                                               if k not in ('threads',
                                                                            'validate_instants')})
    data = TrainingData(rec, config, (48, 48), (12, 12))
    held = data.validation_instants
    assert held.size == 2 and set(held) <= set(LABELLED)
    np.testing.assert_array_equal(data.validation_labels, rec.labels[held])
    assert np.isnan(data.labels[held]).all()
    assert not set(held) & set(data.labelled_instants)
    assert not set(held) & set(data.unlabeled_instants)
    assert set(data.labelled_instants) == set(LABELLED) - set(held)
    # their crops are framed without their own labels: as if they had none
    masked = rec.labels.copy()
    masked[held] = np.nan
    from dataclasses import replace
    expect = crop_boxes(replace(rec, labels=masked), 'pseudo_labels', 1.0, config.box_margin,
                        data.tracked_labels())
    np.testing.assert_array_equal(data.boxes, expect)
    trainer = Trainer(config, data)
    assert np.isnan(trainer.pseudo[held]).all()
    for pool in (trainer.labelled_pool, trainer.pseudo_pool):
        assert pool.size and not set(pool[:, 0]) & set(held)
    kinds = set()
    for _ in range(config.steps):
        trainer.step()
        for kind, pairs, *_ in trainer.last_plan:
            kinds.add(kind)
            assert not set(pairs[:, 0]) & set(held), (kind, pairs[:, 0])
    assert kinds == {'L', 'B', 'E'}


def test_labelled_metric_is_the_distance_of_the_detections_to_the_held_out_labels(scene):
    _, _, rec = scene
    config = TrainConfig(mode='supervised', steps=20, validation_labels=0.5, seed=1,
                         checkpoint_every=10 ** 6, **{k: v for k, v in TINY.items()
                                                      if k not in ('threads',
                                                                   'validate_instants')})
    trainer = Trainer(config, TrainingData(rec, config, (48, 48), (12, 12)))
    for _ in range(config.steps):
        trainer.step()
    held = trainer.data.validation_instants
    metrics = trainer.validate(max_instants=4)
    points, _ = trainer.detect(held)                              # (K, V, C, 2)
    truth = rec.labels[held]
    distances = []
    for k in range(len(held)):
        for v in range(rec.num_views):
            for c in range(rec.num_keypoints):
                if np.isfinite(truth[k, v, c, 0]):
                    du, dv = points[k, v, c] - truth[k, v, c]
                    distances.append(math.hypot(du, dv))
    assert metrics['labelled_keypoints'] == len(distances) == 2 * 2 * 3
    assert metrics['labelled_mean_px'] == pytest.approx(sum(distances) / len(distances),
                                                        rel=1e-12)
    assert metrics['labelled_median_px'] == pytest.approx(float(np.median(distances)),
                                                          rel=1e-12)
    assert {'reprojection_px', 'epipolar_divergence'} <= set(metrics)


def test_should_publish_compares_the_chosen_metric():
    worse_labels = {'labelled_mean_px': 6.0, 'reprojection_px': 2.0}
    reference = {'labelled_mean_px': 4.0, 'reprojection_px': 3.0}
    ok, reason = should_publish(worse_labels, reference['labelled_mean_px'],
                                metric='labelled_mean_px')
    assert not ok and 'labelled' in reason and 'worse' in reason
    assert should_publish(worse_labels, reference['reprojection_px'],
                          metric='reprojection_px')[0]        # agreement alone would take it
    assert should_publish(worse_labels, 4.0, tolerance_px=2.0, metric='labelled_mean_px')[0]
    assert should_publish({'labelled_mean_px': 4.0}, 4.0, metric='labelled_mean_px')[0]
    assert not should_publish({'labelled_mean_px': None}, math.inf,
                              metric='labelled_mean_px')[0]
    said = []
    assert publish_metric_key('auto', 2, said.append) == 'labelled_mean_px' and not said
    assert publish_metric_key('auto', 0, said.append) == 'reprojection_px'
    assert len(said) == 1 and 'reprojection' in said[0] and '\n' not in said[0]
    assert publish_metric_key('reprojection', 2) == 'reprojection_px'
    with pytest.raises(ConfigError, match="'validation_labels'"):
        publish_metric_key('labelled', 0)


def test_config_errors_name_the_field(scene, tmp_path):
    with pytest.raises(ConfigError, match="'publish_metric'"):
        LearnerConfig(bags=('a',), out='x', publish_metric='agreement')
    with pytest.raises(ConfigError, match="'validation_labels'"):
        LearnerConfig(bags=('a',), out='x', validation_labels=1.5)
    with pytest.raises(ConfigError, match="'publish_metric'"):
        LearnerConfig(bags=('a',), out='x', publish_metric='labelled', validation_labels=0.0)
    with pytest.raises(ConfigError, match="'validation_labels'"):
        TrainConfig(validation_labels=-0.1)
    # one labelled instant: none can be held out; labelled refuses, auto falls back loudly
    single = blob_recording(num_views=4, T=24, C=3, labelled=(4,), label_views=(0, 1))
    folder = write_blob_folder(single, tmp_path / 'single')
    _, init, _ = scene
    base = dict(bags=(str(folder),), model=str(init), **TINY)
    with pytest.raises(ConfigError, match="'validation_labels'"):
        OnlineLearner(LearnerConfig(out=str(tmp_path / 'a'), publish_metric='labelled', **base),
                      log=lambda *a: None)
    learner = OnlineLearner(LearnerConfig(out=str(tmp_path / 'b'), **base), log=lambda *a: None)
    assert learner.metric == 'reprojection_px'
    assert any('publish_metric auto' in w for w in learner.trainer.warnings)


def _swap_k0_k1(model):
    """The same network with output channels k0 and k1 exchanged: the same points, so the
    same agreement between views, under each other's names."""
    with torch.no_grad():
        for p in (model.head.weight, model.head.bias):
            p[[0, 1]] = p[[1, 0]].clone()


def test_a_checkpoint_worse_on_held_out_labels_is_not_announced(scene, tmp_path):
    folder, init, rec = scene
    # a detector that has learnt the blobs: the start of both learners
    fit = TrainConfig(mode='supervised', steps=150, validation_labels=0.2, seed=0,
                      checkpoint_every=10 ** 6, **{k: v for k, v in TINY.items()
                                                   if k not in ('threads', 'validate_instants')})
    trainer = Trainer(fit, TrainingData(rec, fit, (48, 48), (12, 12)), tmp_path / 'fit')
    for _ in range(fit.steps):
        trainer.step()
    start = trainer.save()

    def learner(name, **more):
        config = LearnerConfig(bags=(str(folder),), out=str(tmp_path / name), model=str(start),
                               validation_labels=0.2, seed=0, publish_tolerance_px=1e-9,
                               **{**TINY, **more})
        return OnlineLearner(config, log=lambda *a: None)

    by_labels = learner('labelled')
    assert by_labels.metric == 'labelled_mean_px'
    assert by_labels.data.validation_instants.size == 1
    before = by_labels.start_metrics
    _swap_k0_k1(by_labels.trainer.model)
    result = by_labels.evaluate(by_labels.trainer.save())
    after = result.metrics
    # the swapped views agree as well (the same points; 1e-9 px: summation order) ...
    assert after['reprojection_px'] == pytest.approx(before['reprojection_px'], abs=1e-9)
    # ... but the names are wrong: far from the held-out labels
    assert after['labelled_mean_px'] > before['labelled_mean_px'] + 3.0, (before, after)
    assert not result.published and 'worse' in result.reason
    assert by_labels.published is None and not (tmp_path / 'labelled' / PUBLISHED).exists()
    assert by_labels.reference_px == before['labelled_mean_px']

    # the old criterion (agreement) announces the same weights
    by_agreement = learner('reprojection', publish_metric='reprojection')
    _swap_k0_k1(by_agreement.trainer.model)
    result = by_agreement.evaluate(by_agreement.trainer.save())
    assert result.published, result.reason
    published = json.loads((tmp_path / 'reprojection' / PUBLISHED).read_text())
    assert published['publish_metric'] == 'reprojection_px'
    assert published['metrics']['labelled_mean_px'] == pytest.approx(after['labelled_mean_px'])

    # resumed with the labelled criterion from an announcement written before the metric
    # existed: the announced checkpoint is validated again for the reference
    legacy = dict(published)
    del legacy['publish_metric']
    legacy['metrics'] = {k: v for k, v in legacy['metrics'].items()
                         if not k.startswith('labelled_')}
    (tmp_path / 'reprojection' / PUBLISHED).write_text(json.dumps(legacy))
    again = learner('reprojection', publish_metric='labelled')
    assert again.published.sha256 == published['sha256']
    assert again.reference_px == pytest.approx(after['labelled_mean_px'], rel=1e-9)


def test_monet_train_holds_out_the_same_validation_labels(scene, tmp_path, capsys):
    from monet_ros.cli import main as monet_main
    folder, _, rec = scene
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    code = monet_main(['train', str(folder), '--out', str(tmp_path / 'run'), '--skeleton',
                       str(skeleton), '--mode', 'supervised', '--steps', '5',
                       '--validation-labels', '0.5', '--architecture', 'small',
                       '--input-size', '48', '--width', '16', '--eval-fraction', '0.25',
                       '--device', 'cpu', '--threads', '1', '--no-progress'])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    summary = json.loads(captured.out)
    # 4 labelled instants x 0.5 -> 2 held out, 2 labelled views x 3 keypoints each
    assert summary['validation']['count'] == 2 * 2 * 3
    assert 'held-out validation labels' in captured.err
    meta = torch.load(tmp_path / 'run' / 'model.pt', weights_only=True)['metadata']
    assert meta['train_config']['validation_labels'] == 0.5
