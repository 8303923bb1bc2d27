"""OnlineLearner on a tiny recording folder: validated checkpoints, the announcement
criterion, pruning, resume after a restart, several bags."""
import hashlib
import json
import math

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import numpy as np
import pytest
import torch

from monet_ros.config import ConfigError
from monet_ros.learning.online import (
    FOREVER,
    LearnerConfig,
    OnlineLearner,
    concatenate_recordings,
    should_publish,
)
from monet_ros.learning.recording import RecordingError
from monet_ros.models import build_model, load_checkpoint, save_checkpoint
from monet_ros.models.onnx_backend import onnx_path_for

TINY = dict(batch_labelled=4, batch_pseudo=4, batch_unlabeled=1, views_per_instant=3,
            lr=3e-3, eval_fraction=0.25, device='cpu', threads=1)


@pytest.fixture(scope='module')
def folder(tmp_path_factory):
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp('online')
    rec = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    torch.manual_seed(0)
    model = build_model('small', 3, input_size=[48, 48], width=16)
    save_checkpoint(root / 'init.pt', model, {'keypoints': ['k0', 'k1', 'k2']})
    return write_blob_folder(rec, root / 'data'), root / 'init.pt', rec


def test_should_publish_criterion():
    assert should_publish({'reprojection_px': 3.0}, math.inf)[0]
    assert should_publish({'reprojection_px': 3.0}, None)[0]
    assert should_publish({'reprojection_px': 3.0}, 3.0)[0]            # not worse: announced
    assert not should_publish({'reprojection_px': 3.01}, 3.0)[0]
    assert should_publish({'reprojection_px': 3.4}, 3.0, tolerance_px=0.5)[0]
    ok, reason = should_publish({'reprojection_px': float('nan')}, 3.0)
    assert not ok and 'no finite' in reason
    assert not should_publish({}, math.inf)[0]


def test_config_is_validated_and_maps_to_a_train_config(folder):
    data, init, _ = folder
    with pytest.raises(ConfigError, match="'out'"):
        LearnerConfig(bags=(str(data),))
    with pytest.raises(ConfigError, match="'bags'"):
        LearnerConfig(out='x')
    with pytest.raises(ConfigError, match="'epipolar_warmup'"):
        LearnerConfig(bags=('a',), out='x', epipolar_warmup=0.2)
    config = LearnerConfig(bags=('a',), out='x', lambda_e=2.5, lr=1e-3)
    train = config.train_config()
    assert train.steps == FOREVER and train.lambda_e == 2.5 and train.lr == 1e-3
    assert LearnerConfig(bags=('a',), out='x', steps=50).train_config().steps == 50


def test_learner_announces_only_checkpoints_not_worse_and_resumes(folder, tmp_path):
    data, init, rec = folder
    out = tmp_path / 'run'
    config = LearnerConfig(bags=(str(data),), out=str(out), model=str(init),
                           checkpoint_every=5, keep_checkpoints=2, **TINY)
    learner = OnlineLearner(config, log=lambda *a: None)
    assert learner.recording.num_instants == 24
    start = learner.reference_px
    assert math.isfinite(start)
    results = []
    for _ in range(30):
        terms = learner.step()
        assert {'L', 'B', 'loss'} <= set(terms)
        result = learner.checkpoint_due()
        if result is not None:       # pruned later: check the file while it is there
            assert result.sha256 == hashlib.sha256(open(result.path, 'rb').read()).hexdigest()
            results.append(result)
    assert [r.step for r in results] == [5, 10, 15, 20, 25, 30]
    # labels at instants 2 and 9: one of them is held out, the criterion is the error on it
    assert learner.data.validation_instants.size == 1 and learner.metric == 'labelled_mean_px'
    reference = start
    for r in results:      # the criterion, recomputed here from the reported numbers
        err = r.metrics['labelled_mean_px']
        assert r.published == (err is not None and err <= reference)
        if r.published:
            reference = err
        assert set(r.metrics) >= {'epipolar_divergence', 'reprojection_px', 'loss_L',
                                  'labelled_mean_px', 'labelled_median_px'}
    assert learner.reference_px == reference
    published = [r for r in results if r.published]
    assert published, 'training from a random net improved nothing in 30 steps'
    last = published[-1]
    assert json.loads((out / 'published.json').read_text())['sha256'] == last.sha256
    message = json.loads(last.announcement())
    assert message == {'path': last.path, 'step': last.step, 'sha256': last.sha256,
                       'metrics': last.metrics}
    model, meta = load_checkpoint(last.path)
    assert meta['step'] == last.step and meta['keypoints'] == ['k0', 'k1', 'k2']
    kept = sorted(p.name for p in (out / 'checkpoints').glob('*.pt'))
    announced = f'step_{last.step:06d}.pt'
    written = [f'step_{r.step:06d}.pt' for r in results]
    assert kept == sorted({announced, *[w for w in written if w != announced][-2:]})
    # the announced checkpoint's ONNX export is ready for the detectors (their cache name),
    # the deleted checkpoints' exports are gone with them
    exports = sorted(p.name for p in (out / 'checkpoints').glob('*.onnx'))
    assert onnx_path_for(last.path, last.sha256).name in exports
    assert all(e.split('.')[0] + '.pt' in kept for e in exports), (exports, kept)

    # a restarted learner continues at step 30 with the last announcement as reference
    again = OnlineLearner(config, log=lambda *a: None)
    assert again.step_count == 30 and again.published.sha256 == last.sha256
    assert again.reference_px == last.metrics['labelled_mean_px']
    for name, value in learner.trainer.model.state_dict().items():
        assert torch.equal(value, again.trainer.model.state_dict()[name]), name

    # wrecked weights (a huge learning rate) are validated, written and NOT announced
    wreck = LearnerConfig(bags=(str(data),), out=str(tmp_path / 'wreck'), model=last.path,
                          checkpoint_every=3, **{**TINY, 'lr': 5.0})
    bad = OnlineLearner(wreck, log=lambda *a: None)
    good_px = bad.reference_px
    for _ in range(3):
        bad.step()
    result = bad.checkpoint_due()
    assert result is not None and not result.published, result
    assert 'worse' in result.reason or 'no finite' in result.reason
    assert bad.reference_px == good_px and bad.published is None
    assert not (tmp_path / 'wreck' / 'published.json').exists()
    load_checkpoint(result.path)          # written and whole, just not announced


def test_concatenated_recordings_and_mismatched_cameras(folder):
    _, _, rec = folder
    other = blob_recording(num_views=4, T=5, C=3, labelled=(1,), seed=1)
    both = concatenate_recordings([rec, other])
    assert both.num_instants == 29 and both.frames[2].shape[0] == 29
    np.testing.assert_array_equal(both.labels[24:], other.labels)
    np.testing.assert_array_equal(both.frames[1][24:], other.frames[1])
    three = blob_recording(num_views=3, T=5, C=3, labelled=(1,))
    with pytest.raises(RecordingError, match='cameras'):
        concatenate_recordings([rec, three])
