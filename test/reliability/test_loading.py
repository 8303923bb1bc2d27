"""The loading entry points under generated damage: rig files (load_rig, every node's `rig`
parameter), checkpoints (Detector.from_checkpoint: `monet process/eval/pipeline`, the
detector's `model` parameter) and bags (open_bag + messages: every command and the player).
Each ends in a loaded object that makes sense or a ValueError subclass naming the file -
never another exception type, a hang or an object with nonsense values."""
import math

from helpers.recordings import small_checkpoint
from helpers.reliability import RELIABILITY, record
from helpers.scenes import ring_rig
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
import torch
import yaml

from monet_ros.geometry import load_rig, save_rig
from monet_ros.io import BagError, BagWriter, open_bag
from monet_ros.models import CheckpointError, Detector

SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=6),
                    st.sampled_from([1e300, -1, 0, 640, '640', 'nan', '.inf']))
VALUES = st.recursive(SCALARS, lambda c: st.lists(c, max_size=4) |
                      st.dictionaries(st.text(max_size=4), c, max_size=3), max_leaves=10)
RIG_FIELDS = ['name', 'width', 'height', 'K', 'D', 'R', 't', 'topic']


@pytest.fixture(scope='module')
def rig_text(tmp_path_factory):
    path = tmp_path_factory.mktemp('rig') / 'rig.yaml'
    save_rig(path, ring_rig(2))
    return path.read_text()


def assert_camera_sane(cam):
    assert isinstance(cam.width, int) and isinstance(cam.height, int)
    assert 0 < cam.width and 0 < cam.height
    for value in (cam.K, cam.R, cam.t, cam.dist):
        assert np.all(np.isfinite(value))
    assert np.allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-3)


@settings(RELIABILITY, max_examples=60)
@given(camera=st.integers(0, 1), field=st.sampled_from(RIG_FIELDS + ['(delete)', 'frame_id']),
       value=VALUES, which=st.integers(0, 5))
def test_rig_yaml_with_damaged_fields(rig_text, tmp_path_factory, camera, field, value, which):
    data = yaml.safe_load(rig_text)
    if field == 'frame_id':
        data['frame_id'] = value
    elif field == '(delete)':
        del data['cameras'][camera][RIG_FIELDS[which % len(RIG_FIELDS)]]
    else:
        data['cameras'][camera][field] = value
    path = tmp_path_factory.mktemp('rig') / 'rig.yaml'
    path.write_text(yaml.safe_dump(data))
    check_rig_file(path)


def check_rig_file(path):
    """load_rig of `path`: an error naming the file, or cameras that pass assert_camera_sane
    (recorded as the one or the other)."""
    try:
        cameras = load_rig(path)
    except ValueError as error:
        assert str(path) in str(error), error
        record('load_rig', 'clear error')
        return
    for cam in cameras:
        assert_camera_sane(cam)
    record('load_rig', 'right result')


@settings(RELIABILITY, max_examples=30)
@given(text=st.one_of(st.text(max_size=200), st.binary(max_size=200).map(
    lambda b: b.decode('latin-1'))), suffix=st.sampled_from(['.yaml', '.toml', '.xml', '.yml']))
def test_rig_files_of_garbage(tmp_path_factory, text, suffix):
    path = tmp_path_factory.mktemp('rig') / f'calibration{suffix}'
    path.write_text(text, encoding='utf-8', errors='replace')
    check_rig_file(path)


# ------------------------------------------------------------------ checkpoints
@pytest.fixture(scope='module')
def checkpoint_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp('ckpt') / 'model.pt'
    small_checkpoint(path, input_size=(64, 64))
    return path.read_bytes()


def load_checkpoint_outcome(path):
    try:
        detector = Detector.from_checkpoint(path, device='cpu')
    except CheckpointError as error:
        assert str(path) in str(error) or path.name in str(error), error
        record('Detector.from_checkpoint', 'clear error')
        return None
    record('Detector.from_checkpoint', 'right result')
    return detector


@settings(RELIABILITY, max_examples=20)
@given(cut=st.floats(0.0, 0.999))
def test_truncated_checkpoints(checkpoint_bytes, tmp_path_factory, cut):
    path = tmp_path_factory.mktemp('ckpt') / 'model.pt'
    path.write_bytes(checkpoint_bytes[:int(cut * len(checkpoint_bytes))])
    assert load_checkpoint_outcome(path) is None


@settings(RELIABILITY, max_examples=25)
@given(field=st.sampled_from(['keypoints', 'architecture', '(delete keypoints)',
                              '(delete architecture)']),
       value=VALUES)
def test_checkpoint_metadata_of_the_wrong_shape(checkpoint_bytes, tmp_path_factory, field,
                                                value):
    """Metadata fields replaced by generated values: refused naming the file, or a detector
    whose keypoints are names. (Sizes and model options - kind 2 - have their own tests.)"""
    import io
    root = tmp_path_factory.mktemp('ckpt')
    payload = torch.load(io.BytesIO(checkpoint_bytes), weights_only=True)
    meta = payload['metadata'] if 'metadata' in payload else payload
    if field.startswith('(delete'):
        meta.pop(field[8:-1], None)
    else:
        meta[field] = value
    path = root / 'model.pt'
    torch.save(payload, path)
    detector = load_checkpoint_outcome(path)
    if detector is not None:
        assert all(isinstance(k, str) for k in detector.keypoints)
        assert len(detector.keypoints) == detector.model.num_keypoints


# ------------------------------------------------------------------ bags
@pytest.fixture(scope='module')
def bag_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp('bag') / 'rec.mcap'
    rng = np.random.default_rng(0)
    with BagWriter(tmp_path_factory.mktemp('bag') / 'rec') as writer:
        for k in range(6):
            for cam in ('cam0', 'cam1'):
                writer.write_image(f'/{cam}/image_raw', 10**18 + k * 33_000_000,
                                   rng.integers(0, 255, (8, 8, 3), dtype=np.uint8), cam)
        folder = writer.path
    files = sorted(folder.glob('*.mcap'))
    path.write_bytes(files[0].read_bytes())
    return path.read_bytes()


@settings(RELIABILITY, max_examples=40)
@given(damage=st.sampled_from(['truncate', 'flip', 'zero run']), where=st.floats(0, 0.999),
       bit=st.integers(0, 7), length=st.integers(1, 64))
def test_damaged_bags_read_or_refuse(bag_bytes, tmp_path_factory, damage, where, bit, length):
    """A damaged .mcap: open_bag refuses it naming the file (BagError), or reading gives
    whole messages and a report; never another exception."""
    data = bytearray(bag_bytes)
    at = int(where * len(data))
    if damage == 'truncate':
        data = data[:at]
    elif damage == 'flip':
        data[at] ^= 1 << bit
    else:
        data[at:at + length] = bytes(len(data[at:at + length]))
    path = tmp_path_factory.mktemp('bag') / 'rec.mcap'
    path.write_bytes(bytes(data))
    try:
        reader = open_bag(path)
        messages = list(reader.messages())
    except BagError as error:
        assert str(path) in str(error) or path.name in str(error), error
        record('open_bag + messages', 'clear error')
        return
    for m in messages:
        assert m.msg.height == 8 and len(m.msg.data) == 8 * 8 * 3
    given_count = len(messages)
    assert given_count <= 12
    if given_count < 12:                  # nothing lost silently (kind 3)
        assert not reader.report.ok, reader.report.summary()
    record('open_bag + messages', 'right result' if given_count == 12 and reader.report.ok
           else 'skipped and counted')
    assert math.isfinite(float(reader.report.total_skipped))
