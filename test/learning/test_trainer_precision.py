"""TrainConfig.precision: bfloat16 training (torch.autocast around the network forward) learns
like float32 where the hardware runs bfloat16 natively, keeps float32 weights and
checkpoints, and is refused, naming precision, where it would be emulated (the inference rule,
models.detector.check_precision)."""
from dataclasses import replace

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import pytest
import torch

from monet_ros.cli import main as monet_main
from monet_ros.config import ConfigError
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.online import LearnerConfig
from monet_ros.learning.trainer import Trainer, TrainingData, check_training_precision
from monet_ros.models import load_checkpoint
from monet_ros.models.detector import bfloat16_native

TINY = dict(architecture='small', input_size=48, width=16, batch_labelled=4, batch_pseudo=4,
            batch_unlabeled=1, views_per_instant=3, lr=3e-3, eval_fraction=0.25,
            device='cpu', aug_rotate_deg=10.0, aug_photometric=0.5, mode='supervised')
native = pytest.mark.skipif(not bfloat16_native('cpu'), reason='no native bfloat16 on this CPU')


@pytest.fixture(scope='module')
def recording():
    torch.set_num_threads(1)          # 2 shared cores: one thread is fastest
    return blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))


def float_weights(state):
    """The floating-point entries of a state_dict (BatchNorm's step counters are int64)."""
    return {k: v for k, v in state.items() if v.is_floating_point()}


@native
def test_bfloat16_training_lowers_the_labelled_loss_like_float32(recording, tmp_path):
    losses = {}
    for precision in ('float32', 'bfloat16'):
        config = TrainConfig(steps=30, precision=precision, **TINY)
        data = TrainingData(recording, config, (48, 48), (12, 12))
        trainer = Trainer(config, data, tmp_path / precision)
        with torch.no_grad(), trainer.autocast():      # the forward really is bfloat16
            out = trainer.model(data.cache.views([2], [0]).images)[-1]
        assert out.dtype == (torch.bfloat16 if precision == 'bfloat16' else torch.float32)
        before = trainer.evaluate_terms()['L']
        trainer.run(progress=False)
        after = trainer.evaluate_terms()['L']          # in the trainer's own precision
        # the checkpoint: float32 weights (autocast never changes them), loadable
        model, meta = load_checkpoint(tmp_path / precision / 'model.pt')
        assert meta['train_config']['precision'] == precision and meta['step'] == 30
        weights = float_weights(model.state_dict())
        assert weights and all(v.dtype == torch.float32 for v in weights.values())
        state = torch.load(tmp_path / precision / 'trainer_state.pt', weights_only=True)
        assert all(v.dtype == torch.float32 for v in float_weights(state['model']).values())
        for name, value in weights.items():
            assert torch.equal(value, trainer.model.state_dict()[name]), name
        # the same weights' labelled loss in float32: an independent evaluation
        plain = Trainer(replace(config, precision='float32'), data, model=model)
        losses[precision] = plain.evaluate_terms()['L']
        # measured: 18.8 -> 0.54 (float32) / 0.55 (bfloat16) in 30 steps
        assert after < 0.1 * before, (precision, before, after)
        # bfloat16 forward vs float32 forward of the same weights: measured 0.2% apart
        assert after == pytest.approx(losses[precision], rel=0.05), precision
    # bfloat16-trained vs float32-trained, same seed and batches: measured 2.4% apart
    # (5% with seed 1); 20% allows for another CPU's kernels
    assert losses['bfloat16'] == pytest.approx(losses['float32'], rel=0.2), losses


@native
def test_a_float32_run_resumes_in_bfloat16(recording, tmp_path):
    config = TrainConfig(steps=4, checkpoint_every=2, **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    Trainer(config, data, tmp_path).run(2, progress=False)
    resumed = Trainer.resume(tmp_path, data, config=replace(config, precision='bfloat16'))
    assert resumed.step_count == 2 and resumed.config.precision == 'bfloat16'
    resumed.run(progress=False)
    assert resumed.step_count == 4


def test_unknown_precision_is_named():
    with pytest.raises(ConfigError, match="'precision'") as error:
        TrainConfig(precision='float16')
    assert error.value.field == 'precision'


def test_bfloat16_is_refused_on_a_device_without_it(recording):
    # the inference rule's seam: bfloat16_native is False for any device but a CPU / GPU
    # that has it (here the meta device, never native), so this runs on every machine
    assert not bfloat16_native('meta')
    config = TrainConfig(steps=1, precision='bfloat16', **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    with pytest.raises(ConfigError, match='AVX512-BF16 or AMX') as error:
        Trainer(config, data, device='meta')
    assert error.value.field == 'precision'
    assert '\n' not in str(error.value)
    check_training_precision('float32', 'meta')          # float32 runs anywhere


@pytest.mark.skipif(bfloat16_native('cpu'), reason='this CPU runs bfloat16 natively')
def test_bfloat16_is_refused_on_this_cpu_without_it(recording):
    config = TrainConfig(steps=1, precision='bfloat16', **TINY)
    data = TrainingData(recording, config, (48, 48), (12, 12))
    with pytest.raises(ConfigError, match='precision'):
        Trainer(config, data)


@pytest.mark.skipif(bfloat16_native('cuda'), reason='a CUDA GPU with bfloat16 is present')
def test_bfloat16_is_refused_on_cuda_without_it():
    with pytest.raises(ConfigError, match='CUDA GPU with bfloat16'):
        check_training_precision('bfloat16', 'cuda')


def test_the_learner_mirrors_precision():
    config = LearnerConfig(bags=('a',), out='x', precision='bfloat16')
    assert config.train_config().precision == 'bfloat16'
    # the learner defaults to auto (bfloat16 where native, else float32), TrainConfig keeps
    # float32 for the Python API
    assert LearnerConfig(bags=('a',), out='x').train_config().precision == 'auto'


@native
def test_monet_train_precision_bfloat16(recording, tmp_path, capsys):
    data = write_blob_folder(recording, tmp_path / 'data')
    (tmp_path / 'blobs.yaml').write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    args = ['train', str(data), '--out', str(tmp_path / 'run'), '--steps', '3',
            '--skeleton', str(tmp_path / 'blobs.yaml'),
            '--no-progress', '--threads', '1']
    for key, value in TINY.items():
        args += ['--' + key.replace('_', '-'), str(value)]
    args += ['--precision', 'bfloat16']
    assert monet_main(args) == 0
    model, meta = load_checkpoint(tmp_path / 'run' / 'model.pt')
    assert meta['train_config']['precision'] == 'bfloat16' and meta['step'] == 3
    assert all(v.dtype == torch.float32 for v in float_weights(model.state_dict()).values())
    capsys.readouterr()
    assert monet_main([*args[:-1], 'float16']) == 2
    err = capsys.readouterr().err.strip()
    assert 'precision' in err and len(err.splitlines()) == 1, err
