"""precision int8 (models.quantize): ONNX Runtime static quantisation of a trained network
finds the keypoints float32 finds; it is refused, in one line naming the cause, without
calibration data, without onnxruntime, for training, and on CPUs without VNNI / AMX-INT8;
its cache beside the checkpoint follows the checkpoint's sha256 and the crops it is
calibrated on (full frame or tracked), a quant of one crop mode never used for the other."""
from helpers.blob_net import NAMES, SIZE, blob_images, train_blob_net
import numpy as np
import pytest

from monet_ros.atomic import sha256_file
from monet_ros.config import ConfigError
from monet_ros.crop_rule import TrackedRule
from monet_ros.int8_calibration import crops_key
from monet_ros.learning.trainer import check_training_precision
from monet_ros.models import save_checkpoint
from monet_ros.models.detector import Detector, resolve_precision
from monet_ros.models.heatmaps import decode_heatmaps
from monet_ros.models.quantize import (
    Int8Error,
    cached_int8,
    cpu_int8_feature,
    int8_path_for,
)

HAS_INT8 = cpu_int8_feature() is not None
needs_int8 = pytest.mark.skipif(not HAS_INT8, reason='no VNNI / AMX-INT8 on this CPU')


@pytest.fixture(scope='module')
def trained():
    return train_blob_net()


@pytest.fixture(scope='module')
def calibration():
    return blob_images(np.random.default_rng(5), 48)[0]


def full_boxes(n):
    return np.array([[0.0, 0.0, SIZE, SIZE]] * n)


def cameras(n):
    from monet_ros.geometry import Camera
    return [Camera(name=f'cam{i}', K=np.diag([100.0, 100.0, 1.0]), dist=np.zeros(5),
                   R=np.eye(3), t=np.zeros(3), width=SIZE, height=SIZE) for i in range(n)]


@needs_int8
def test_int8_finds_the_keypoints_float32_finds(trained, calibration):
    images, centres = blob_images(np.random.default_rng(7), 24)
    heat = {}
    for precision in ('float32', 'int8'):
        detector = Detector(trained, {'keypoints': NAMES}, device='cpu', backend='onnxruntime',
                            precision=precision, calibration=calibration)
        assert detector.precision == precision
        heat[precision] = detector.predict(images, cameras(len(images)),
                                           full_boxes(len(images)))[0]
    points = {p: decode_heatmaps(h)[0] * 4 + 1.5 for p, h in heat.items()}     # input px
    assert np.median(np.linalg.norm(points['float32'] - centres, axis=-1)) < 1.5
    shift = np.linalg.norm(points['int8'] - points['float32'], axis=-1)
    # measured: median 0.022, largest 0.08 input px (float32's own error vs truth ~0.1);
    # heatmap values within 0.04 of peaks ~0.9
    assert shift.max() < 0.3, shift
    assert np.abs(heat['int8'] - heat['float32']).max() < 0.1


@needs_int8
def test_no_calibration_and_no_cached_quant_is_refused_in_one_line(trained, tmp_path):
    path = tmp_path / 'model.pt'
    save_checkpoint(path, trained, {'keypoints': NAMES})
    with pytest.raises(Int8Error) as caught:
        Detector.from_checkpoint(path, device='cpu', backend='onnxruntime', precision='int8')
    text = str(caught.value)
    assert '\n' not in text and 'needs calibration data' in text and 'calibration' in text
    assert str(int8_path_for(path, sha256_file(path))) in text
    assert not list(tmp_path.glob('*.int8.onnx'))


def test_int8_is_refused_without_onnxruntime_and_for_training(trained):
    with pytest.raises(ValueError, match='precision int8 needs backend onnxruntime'):
        Detector(trained, {'keypoints': NAMES}, device='cpu', precision='int8')
    with pytest.raises(ConfigError, match='int8 is an inference precision'):
        check_training_precision('int8', 'cpu')


def test_cpu_rule_reads_the_vnni_and_amx_flags():
    assert cpu_int8_feature({'avx2', 'fma', 'avx512f'}) is None
    assert cpu_int8_feature({'avx2', 'avx_vnni'}) == 'AVX-VNNI'
    assert cpu_int8_feature({'amx_int8', 'avx512_vnni'}) == 'AMX-INT8 and AVX512-VNNI'
    if not HAS_INT8:
        with pytest.raises(ValueError, match='needs a CPU with AVX512-VNNI, AVX-VNNI or AMX'):
            resolve_precision('int8', 'onnxruntime', 'cpu')


@needs_int8
def test_cache_follows_the_checkpoint_sha256(trained, calibration, tmp_path):
    path = tmp_path / 'model.pt'
    save_checkpoint(path, trained, {'keypoints': NAMES})
    assert cached_int8(path) is None
    first = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime',
                                     precision='int8', calibration=calibration)
    cached = int8_path_for(path, sha256_file(path))
    assert cached.is_file() and cached.name.endswith('.int8.onnx')
    assert list(tmp_path.glob('*.int8.onnx')) == [cached]
    assert first.runner.path == cached
    # the one line a run shows: calibrated on what, wrote which quant; then the cache used
    assert first.int8_note == f'precision int8: calibrated on 48 crops (full); wrote {cached}'
    # cached: no calibration needed now; auto still runs float32 (int8 measured slower)
    again = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime',
                                     precision='int8')
    assert again.runner.path == cached
    assert again.int8_note == f'precision int8: cached quant {cached} (crops full; not ' \
        'calibrating)'
    assert cached_int8(path) == cached
    assert resolve_precision('auto', 'onnxruntime', 'cpu', path)[0] == 'float32'
    # new weights under the same name: a new sha256, the old quant is not used
    save_checkpoint(path, train_blob_net(steps=1, seed=3), {'keypoints': NAMES})
    assert cached_int8(path) is None
    with pytest.raises(Int8Error, match='needs calibration data'):
        Detector.from_checkpoint(path, device='cpu', backend='onnxruntime', precision='int8')
    with pytest.raises(Int8Error, match='a quant of other weights'):
        Detector.from_checkpoint(path, device='cpu', backend='onnxruntime', precision='int8',
                                 calibration=str(cached))
    renewed = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime',
                                       precision='int8', calibration=calibration)
    new = int8_path_for(path, sha256_file(path))
    assert new != cached and renewed.runner.path == new
    assert sorted(tmp_path.glob('*.int8.onnx')) == sorted([cached, new])



@needs_int8
def test_a_quant_renamed_onto_the_cache_name_is_not_used(trained, calibration, tmp_path):
    # the name alone proves nothing: each quant records its checkpoint's sha256 and crops
    import onnx

    first, second = tmp_path / 'a.pt', tmp_path / 'b.pt'
    save_checkpoint(first, trained, {'keypoints': NAMES})
    save_checkpoint(second, train_blob_net(steps=1, seed=3), {'keypoints': NAMES})
    made = Detector.from_checkpoint(first, device='cpu', backend='onnxruntime',
                                    precision='int8', calibration=calibration).runner.path
    record = {p.key: p.value for p in onnx.load(str(made)).metadata_props}
    assert record['monet_ros.checkpoint_sha256'] == sha256_file(first)
    assert record['monet_ros.int8_crops'] == 'full'
    # a's quant copied onto b's cache name: refused in one line without calibration data,
    # given as b's quant likewise, and calibrated again (replaced) with it
    fake = int8_path_for(second, sha256_file(second))
    fake.write_bytes(made.read_bytes())
    for calibration_of_b in (None, str(fake)):
        with pytest.raises(Int8Error, match='was made from a checkpoint of sha256 '
                           f'{sha256_file(first)[:16]}') as caught:
            Detector.from_checkpoint(second, device='cpu', backend='onnxruntime',
                                     precision='int8', calibration=calibration_of_b)
        assert '\n' not in str(caught.value) and str(fake) in str(caught.value)
    renewed = Detector.from_checkpoint(second, device='cpu', backend='onnxruntime',
                                       precision='int8', calibration=calibration)
    assert renewed.runner.path == fake and 'was not made from this checkpoint' in \
        renewed.int8_note
    assert {p.key: p.value for p in onnx.load(str(fake)).metadata_props}[
        'monet_ros.checkpoint_sha256'] == sha256_file(second)
    # a quant without a record (made before quants recorded theirs): not used either
    bare = onnx.load(str(fake))
    kept = [p for p in bare.metadata_props if not p.key.startswith('monet_ros.')]
    del bare.metadata_props[:]
    bare.metadata_props.extend(kept)
    fake.write_bytes(bare.SerializeToString())
    with pytest.raises(Int8Error, match='records no checkpoint'):
        Detector.from_checkpoint(second, device='cpu', backend='onnxruntime',
                                 precision='int8')
    # and a file that is not ONNX at all
    fake.write_bytes(b'not onnx')
    with pytest.raises(Int8Error, match='not a readable ONNX quant'):
        Detector.from_checkpoint(second, device='cpu', backend='onnxruntime',
                                 precision='int8')


TRACKED = 'tracked-m0.3-t4-k3'


def test_the_cache_name_says_which_crops_the_quant_is_calibrated_on(tmp_path):
    path = tmp_path / 'model.pt'
    sha = 'ab' * 32
    assert int8_path_for(path, sha).name == f'model.{sha[:16]}.full.int8.onnx'
    assert int8_path_for(path, sha, TRACKED).name == f'model.{sha[:16]}.{TRACKED}.int8.onnx'
    assert crops_key(True) == TRACKED and crops_key(False) == 'full'
    assert crops_key(True, TrackedRule(margin=0.5, min_points=4)) == 'tracked-m0.5-t4-k4'
    # a fixed box is the crops of an untracked run that has one (the detector node's box)
    assert crops_key(False, box=(10, 20.5, 300, 240)) == 'box-10_20.5_300_240'
    assert crops_key(True, box=(10, 20.5, 300, 240)) == TRACKED
    assert int8_path_for(path, sha, 'box-10_20.5_300_240').name.endswith(
        '.box-10_20.5_300_240.int8.onnx')
    for bad in ('tracked', 'box', 'box-1_2_3', '', None, 'full/../x'):
        with pytest.raises(ValueError, match='int8 crops key must be'):
            int8_path_for(path, sha, bad)


@needs_int8
def test_a_quant_of_other_crops_is_never_used_and_tracked_needs_the_rules_crops(
        trained, calibration, tmp_path):
    path = tmp_path / 'model.pt'
    save_checkpoint(path, trained, {'keypoints': NAMES})
    full = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime',
                                    precision='int8', calibration=calibration)
    assert full.runner.path == int8_path_for(path, sha256_file(path))
    assert cached_int8(path, crops=TRACKED) is None
    # the full-frame quant is not the tracked run's: refused by name, one line
    with pytest.raises(Int8Error, match='a quant calibrated on other crops') as caught:
        Detector.from_checkpoint(path, device='cpu', backend='onnxruntime', precision='int8',
                                 calibration=str(full.runner.path), int8_crops=TRACKED)
    assert '\n' not in str(caught.value)
    # a recording is read here only for full-frame crops; tracked crops are the crop rule's
    with pytest.raises(Int8Error, match='calibrates on the crops the run makes, not on full'):
        Detector.from_checkpoint(path, device='cpu', backend='onnxruntime', precision='int8',
                                 calibration=str(tmp_path / 'rec'), int8_crops=TRACKED)
    # a function making the crops gets a float32 detector of the network, and is called
    # only while no quant of these crops is cached
    calls = []

    def make(detector):
        calls.append((detector.precision, detector.backend, detector.input_size))
        return calibration

    for _ in range(2):
        tracked = Detector.from_checkpoint(path, device='cpu', backend='onnxruntime',
                                           precision='int8', calibration=make,
                                           int8_crops=TRACKED)
    assert calls == [('float32', 'torch', (SIZE, SIZE))]
    assert tracked.runner.path == int8_path_for(path, sha256_file(path), TRACKED)
    sha = sha256_file(path)[:16]
    assert sorted(p.name for p in tmp_path.glob('*.int8.onnx')) == \
        [f'model.{sha}.full.int8.onnx', f'model.{sha}.{TRACKED}.int8.onnx']
