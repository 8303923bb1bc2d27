"""bench/real.py scores a model through `monet process`: its real-data path gives the 3D
that `monet process` writes (read back from the output bag here, independently)."""
import importlib.util

import numpy as np
import pytest
import torch

from monet_ros.cli import main as monet
from monet_ros.io import cloud_to_keypoints3d, open_bag
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.recording import load_recording
from monet_ros.learning.trainer import Trainer, TrainingData
from monet_ros.models import save_checkpoint


def bench_real(repo_root):
    spec = importlib.util.spec_from_file_location('bench_real', repo_root / 'bench' / 'real.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_the_benchs_real_data_path_equals_monet_process(tmp_path, repo_root):
    torch.set_num_threads(1)
    data = tmp_path / 'synth'
    assert monet(['synth', '--out', str(data), '--frames', '8', '--cameras', '3', '--width',
                  '160', '--height', '120', '--label-fraction', '0.3', '--seed', '1',
                  '--quiet']) == 0
    recording = load_recording(data)
    config = TrainConfig(mode='supervised', architecture='small', input_size=64, width=8,
                         steps=30, batch_labelled=6, batch_pseudo=0, lr=3e-3, device='cpu')
    trainer = Trainer(config, TrainingData(recording, config, (64, 64), (16, 16)),
                      warn=lambda m: None)
    trainer.run(progress=False)
    checkpoint = tmp_path / 'model.pt'
    save_checkpoint(checkpoint, trainer.model, trainer.metadata())

    real = bench_real(repo_root)
    X, points, unmatched = real.process_path(data / 'recording', checkpoint, tmp_path / 'a',
                                             recording.stamps, recording.cameras)
    assert unmatched == 0 and X.shape == (recording.num_instants, 14, 3)
    assert points.shape == (recording.num_instants, 3, 14, 2)

    assert monet(['process', str(data / 'recording'), '--model', str(checkpoint), '--out',
                  str(tmp_path / 'b'), '--quiet']) == 0
    written = {m.msg.header.stamp.sec * 10 ** 9 + m.msg.header.stamp.nanosec:
               cloud_to_keypoints3d(m.msg, units='m')['X']
               for m in open_bag(tmp_path / 'b').messages('/monet/keypoints3d')}
    assert len(written) == recording.num_instants
    expected = np.stack([written[int(s)] for s in recording.stamps])
    finite = np.isfinite(expected)
    assert finite.any()                                   # something was triangulated
    np.testing.assert_array_equal(np.isfinite(X), finite)
    np.testing.assert_allclose(X[finite], expected[finite], atol=1e-6, rtol=0)
