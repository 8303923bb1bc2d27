"""ONNX Runtime backend: the exported network gives torch's heatmaps (every architecture),
the export is cached beside the checkpoint keyed by its sha256, raw layouts crop alike."""
from helpers.rigs import random_rig
import numpy as np
import pytest
import torch

from monet_ros.atomic import sha256_file
from monet_ros.models import build_model, save_checkpoint
from monet_ros.models.detector import Detector
from monet_ros.models.onnx_backend import OnnxBackendError, OnnxRunner, onnx_path_for

pytest.importorskip('onnxruntime')

# small widths and inputs so every architecture exports and runs in a second or two
ARCHITECTURES = {'small': {'width': 16, 'input_size': (96, 128)},
                 'cpm': {'num_stages': 2, 'width': 16, 'input_size': (96, 128)},
                 'hourglass': {'features': 32, 'num_stacks': 2, 'depth': 3,
                               'input_size': (96, 128)}}


def _model(name, seed=0):
    torch.manual_seed(seed)
    model = build_model(name, 5, **ARCHITECTURES[name]).eval()
    generator = torch.Generator().manual_seed(seed)
    for module in model.modules():  # non-trivial BatchNorm, so its folding is exported too
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.copy_(torch.randn(module.num_features, generator=generator) / 10)
            module.running_var.uniform_(0.5, 1.5, generator=generator)
    return model


@pytest.fixture(scope='module')
def scene():
    rng = np.random.default_rng(0)
    cameras = random_rig(rng, 3, width=320, height=240)
    images = rng.integers(0, 256, size=(3, 240, 320, 3), dtype=np.uint8)
    return cameras, images


@pytest.mark.parametrize('name', sorted(ARCHITECTURES))
def test_onnxruntime_equals_torch(name, scene):
    cameras, images = scene
    model = _model(name)
    meta = {'keypoints': [f'k{i}' for i in range(5)]}
    reference, ref_cams = Detector(model, meta, device='cpu').predict(images, cameras)
    onnx = Detector(model, meta, device='cpu', backend='onnxruntime', threads=1)
    heat, heat_cams = onnx.predict(images, cameras)
    assert heat.shape == reference.shape and heat.dtype == np.float32
    assert np.abs(reference).max() > 0.01  # a real output, not all zeros
    np.testing.assert_allclose(heat, reference, atol=1e-4, rtol=0)
    for a, b in zip(heat_cams, ref_cams):
        np.testing.assert_array_equal(a.K, b.K)


def test_export_cached_beside_checkpoint_by_sha256(scene, tmp_path):
    cameras, images = scene
    meta = {'keypoints': [f'k{i}' for i in range(5)]}
    path = tmp_path / 'net.pt'
    save_checkpoint(path, _model('small', 0), meta)
    first = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime')
    export = onnx_path_for(path, sha256_file(path))
    assert export.parent == tmp_path and sha256_file(path)[:16] in export.name
    assert first.runner.path == export and export.is_file()
    stamp = export.stat().st_mtime_ns
    again = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime')
    assert export.stat().st_mtime_ns == stamp  # reused, not exported again
    np.testing.assert_array_equal(again.predict(images, cameras)[0],
                                  first.predict(images, cameras)[0])
    assert not list(tmp_path.glob('.*.tmp'))  # atomic write left nothing behind
    # new weights in the same file: a new export, with the new weights' output
    save_checkpoint(path, _model('small', 1), meta)
    changed = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime')
    assert changed.runner.path != export and changed.runner.path.is_file()
    torch_out = Detector.from_checkpoint(path, device='cpu').predict(images, cameras)[0]
    np.testing.assert_allclose(changed.predict(images, cameras)[0], torch_out, atol=1e-4,
                               rtol=0)


def test_bad_backend_and_bad_file_are_named(tmp_path):
    model = _model('small')
    with pytest.raises(ValueError, match='backend must be one of'):
        Detector(model, {'keypoints': [f'k{i}' for i in range(5)]}, backend='tensorrt')
    bad = tmp_path / 'broken.onnx'
    bad.write_bytes(b'not a model')
    with pytest.raises(OnnxBackendError, match='broken.onnx'):
        OnnxRunner(bad)


@pytest.mark.parametrize('layout', ['bgr8', 'rgba8', 'bgra8', 'mono8'])
def test_raw_layouts_crop_like_rgb(layout, scene):
    """An image kept in its message layout (only the crop is converted) gives the heatmaps
    of the same image converted to rgb first."""
    cameras, images = scene
    detector = Detector(_model('small'), {'keypoints': [f'k{i}' for i in range(5)]},
                        device='cpu')
    if layout == 'mono8':
        rgb = np.repeat(images[..., :1], 3, axis=3)
        raw = images[..., :1]
    else:
        alpha = np.full(images.shape[:3] + (1,), 255, np.uint8)
        raw = {'bgr8': images[..., ::-1],
               'rgba8': np.concatenate([images, alpha], axis=3),
               'bgra8': np.concatenate([images[..., ::-1], alpha], axis=3)}[layout]
        rgb = images
    boxes = np.array([[40, 20, 200, 140], [0, 0, 320, 240], [100, 60, 300, 230]], float)
    expected = detector.predict(rgb, cameras, boxes)[0]
    got = detector.predict(list(np.ascontiguousarray(raw)), cameras, boxes,
                           encodings=[layout] * 3)[0]
    np.testing.assert_array_equal(got, expected)


def test_unwritable_export_path_runs_from_memory(scene, tmp_path):
    """When the export cannot be written beside the checkpoint (here a folder is in the
    way, which fails for root too), the export runs from memory."""
    cameras, images = scene
    path = tmp_path / 'net.pt'
    save_checkpoint(path, _model('small', 2), {'keypoints': [f'k{i}' for i in range(5)]})
    onnx_path_for(path, sha256_file(path)).mkdir()
    detector = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime')
    assert detector.runner.path is None
    assert not [p for p in tmp_path.iterdir() if p.is_file() and p.suffix != '.pt']
    expected = Detector.from_checkpoint(path, device='cpu').predict(images, cameras)[0]
    np.testing.assert_allclose(detector.predict(images, cameras)[0], expected, atol=1e-4,
                               rtol=0)


@pytest.mark.parametrize('policy, spins', [('PASSIVE', False), ('passive', False),
                                           ('ACTIVE', True), (None, True)])
def test_intra_op_threads_wait_as_openmp_does(monkeypatch, policy, spins):
    """Where OpenMP waits passively (the nodes set OMP_WAIT_POLICY=PASSIVE), ONNX Runtime's
    threads do not spin either; elsewhere its default (spinning) stays."""
    from monet_ros.models.onnx_backend import export_onnx
    if policy is None:
        monkeypatch.delenv('OMP_WAIT_POLICY', raising=False)
    else:
        monkeypatch.setenv('OMP_WAIT_POLICY', policy)
    runner = OnnxRunner(export_onnx(build_model('small', 2, input_size=(32, 32)).eval()),
                        threads=1)
    options = runner.session.get_session_options()
    if spins:
        with pytest.raises(RuntimeError, match='allow_spinning'):   # ONNX Runtime's default
            options.get_session_config_entry('session.intra_op.allow_spinning')
    else:
        assert options.get_session_config_entry('session.intra_op.allow_spinning') == '0'
    x = np.random.default_rng(0).random((1, 3, 32, 32), dtype=np.float32)
    assert runner(x).shape == (1, 2, 8, 8)
