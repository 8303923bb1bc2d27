"""Detector precision: bfloat16 inference finds the keypoints float32 finds (on hardware with
native bfloat16), and is refused, naming the cause, where it would not run well."""
from importlib.util import find_spec

from helpers.blob_net import NAMES, SIZE, blob_images, train_blob_net
from helpers.rigs import random_rig
import numpy as np
import pytest

from monet_ros.models.crop import crop_images
from monet_ros.models.detector import Detector, bfloat16_native
from monet_ros.models.heatmaps import decode_heatmaps


@pytest.fixture(scope='module')
def trained():
    """A small net trained (supervised, a few hundred steps) to find three coloured blobs."""
    return train_blob_net()


def test_unknown_precision_is_named(trained):
    with pytest.raises(ValueError, match='precision must be one of'):
        Detector(trained, {'keypoints': NAMES}, device='cpu', precision='float16')


def test_bfloat16_with_onnxruntime_is_refused(trained):
    with pytest.raises(ValueError, match='precision bfloat16 needs backend torch'):
        Detector(trained, {'keypoints': NAMES}, device='cpu', backend='onnxruntime',
                 precision='bfloat16')


@pytest.mark.skipif(bfloat16_native('cpu'), reason='this CPU runs bfloat16 natively')
def test_bfloat16_is_refused_without_native_support(trained):
    with pytest.raises(ValueError, match='AVX512-BF16 or AMX'):
        Detector(trained, {'keypoints': NAMES}, device='cpu', precision='bfloat16')


@pytest.mark.skipif(not bfloat16_native('cpu'), reason='no native bfloat16 on this CPU')
def test_bfloat16_finds_the_keypoints_float32_finds(trained):
    rng = np.random.default_rng(1)
    images, centres = blob_images(rng, 12)
    cameras = random_rig(rng, len(images), width=SIZE, height=SIZE)
    full = np.array([[0.0, 0.0, SIZE, SIZE]] * len(images))
    # the crop of a full SIZE x SIZE frame to SIZE x SIZE is the frame itself
    np.testing.assert_array_equal(crop_images(images, full, (SIZE, SIZE)), images)
    points = {}
    for precision in ('float32', 'bfloat16'):
        detector = Detector(trained, {'keypoints': NAMES}, device='cpu', precision=precision)
        heat, _ = detector.predict(images, cameras)
        # channel-interleaved memory, the heatmap message's layout (copied only into it)
        assert heat.dtype == np.float32 and heat.shape == (len(images), len(NAMES), 16, 16)
        assert np.moveaxis(heat, 1, -1).flags['C_CONTIGUOUS']
        points[precision] = decode_heatmaps(heat)[0] * 4 + 1.5   # input px
    # the float32 net has learned the blobs (else the comparison below says nothing)
    assert np.median(np.linalg.norm(points['float32'] - centres, axis=-1)) < 1.5
    shift = np.linalg.norm(points['bfloat16'] - points['float32'], axis=-1)
    # measured: median 0.012 px, largest 0.03 px (the float32 error is ~0.12 px)
    assert shift.max() < 0.1, shift.max()


@pytest.mark.parametrize('precision, native, expected', [
    ('auto', False, 'onnxruntime'),        # an AVX2-only CPU: float32, faster on ONNX Runtime
    ('float32', False, 'onnxruntime'),
    ('float32', True, 'onnxruntime'),      # float32 asked for on a bfloat16 CPU
    ('auto', True, 'torch'),               # native bfloat16 runs on torch
    ('bfloat16', True, 'torch'),
    ('int8', False, 'onnxruntime'),
])
def test_backend_auto_picks_by_precision_and_cpu(precision, native, expected):
    from monet_ros.models.detector import resolve_backend
    backend, note = resolve_backend('auto', precision, 'cpu', native_bfloat16=native)
    assert backend == expected
    assert note.startswith(f'backend auto: {expected} (')
    # given backends are kept, without a note; unknown ones are refused naming backend
    assert resolve_backend('torch', precision, 'cpu') == ('torch', '')
    assert resolve_backend('onnxruntime', precision, 'cpu') == ('onnxruntime', '')
    with pytest.raises(ValueError, match='backend must be one of'):
        resolve_backend('tensorrt', precision, 'cpu')


@pytest.mark.skipif(not find_spec('onnxruntime'),
                    reason='onnxruntime is not installed')
def test_a_detector_with_backend_auto_runs_what_it_says(trained):
    # this CPU's choice (probed): the backend run, the note ending precision_note, and the
    # heatmaps of the backend it names (torch float32 within 1e-4)
    rng = np.random.default_rng(0)
    images, _ = blob_images(rng, 4)
    cams = random_rig(rng, len(images), width=SIZE, height=SIZE)
    auto = Detector(trained, {'keypoints': NAMES}, device='cpu', backend='auto',
                    precision='float32')
    assert auto.backend == 'onnxruntime'
    assert auto.precision_note == ('precision float32; backend auto: onnxruntime (float32 on '
                                   'a CPU: faster than torch, bench/results/pipeline.md)')
    torch32 = Detector(trained, {'keypoints': NAMES}, device='cpu', precision='float32')
    np.testing.assert_allclose(auto.predict(images, cams)[0], torch32.predict(images, cams)[0],
                               atol=1e-4)
