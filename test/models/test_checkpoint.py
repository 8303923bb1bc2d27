"""Checkpoints: exact round trip, atomic writes, and a CheckpointError for every bad file."""
import re

import pytest
import torch

from monet_ros.models import CheckpointError, build_model, load_checkpoint, save_checkpoint
from monet_ros.models.checkpoint import FORMAT
from monet_ros.models.small import SmallNet

NAMES = ['a', 'b', 'c']


def small_model(seed=0, **options):
    torch.manual_seed(seed)
    model = build_model('small', len(NAMES), width=16, **options)
    for module in model.modules():  # non-trivial BatchNorm statistics
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.2, 0.2)
            module.running_var.uniform_(0.5, 1.5)
    return model.eval()


@pytest.fixture
def saved(tmp_path):
    path = tmp_path / 'model.pt'
    model = small_model()
    save_checkpoint(path, model, {'keypoints': NAMES, 'step': 7, 'metrics': {'pck': 0.5}})
    return path, model


def file_error(path, field):
    return re.escape(str(path)) + '.*' + re.escape(field)


def test_round_trip_gives_identical_outputs(saved):
    path, model = saved
    loaded, meta = load_checkpoint(path, architecture='small', num_keypoints=3)
    assert not loaded.training
    images = torch.rand(2, 3, 256, 256)
    with torch.inference_mode():
        assert torch.equal(loaded(images)[-1], model(images)[-1])
    assert meta['architecture'] == 'small' and meta['keypoints'] == NAMES
    assert meta['input_size'] == [256, 256] and meta['heatmap_size'] == [64, 64]
    assert meta['step'] == 7 and meta['metrics'] == {'pck': 0.5}
    assert meta['model_options'] == {'width': 16}
    # no temporary file stays beside the checkpoint
    assert [p.name for p in path.parent.iterdir()] == ['model.pt']


def test_overwrite_replaces_the_file(saved):
    path, _ = saved
    other = small_model(seed=3)
    save_checkpoint(path, other, {'keypoints': NAMES, 'step': 8})
    loaded, meta = load_checkpoint(path)
    assert meta['step'] == 8
    for key, value in other.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], value)


def test_save_rejects_inconsistent_metadata(tmp_path):
    model = small_model()
    with pytest.raises(ValueError, match='keypoints has 2 names'):
        save_checkpoint(tmp_path / 'x.pt', model, {'keypoints': ['a', 'b']})
    with pytest.raises(ValueError, match='metadata.architecture'):
        save_checkpoint(tmp_path / 'x.pt', model, {'keypoints': NAMES, 'architecture': 'cpm'})
    assert list(tmp_path.iterdir()) == []


def test_failed_write_leaves_old_file_and_no_partial_file(saved):
    path, _ = saved
    before = path.read_bytes()
    model = small_model(seed=5)
    # metadata that cannot be serialised
    with pytest.raises(ValueError, match='metrics'):
        save_checkpoint(path, model, {'keypoints': NAMES, 'metrics': {'x': object()}})

    # a state that fails to pickle in the middle of torch.save
    class Unpicklable(SmallNet):
        def get_extra_state(self):
            return lambda: None

    torch.manual_seed(0)
    bad = Unpicklable(3, width=16)
    with pytest.raises(Exception, match='(?i)pickle|lambda'):
        save_checkpoint(path, bad, {'keypoints': NAMES})
    assert path.read_bytes() == before
    assert [p.name for p in path.parent.iterdir()] == ['model.pt']


def test_failed_rename_leaves_no_temporary_file(tmp_path):
    target = tmp_path / 'occupied.pt'
    target.mkdir()
    (target / 'keep').write_text('x')
    with pytest.raises(OSError):
        save_checkpoint(target, small_model(), {'keypoints': NAMES})
    assert sorted(p.name for p in tmp_path.iterdir()) == ['occupied.pt']


def test_missing_file(tmp_path):
    path = tmp_path / 'nope.pt'
    with pytest.raises(CheckpointError, match=file_error(path, 'not found')):
        load_checkpoint(path)


@pytest.mark.parametrize('cut', [0.5, 0.9])
def test_truncated_file(saved, cut):
    path, _ = saved
    data = path.read_bytes()
    path.write_bytes(data[:int(len(data) * cut)])
    with pytest.raises(CheckpointError, match=file_error(path, 'corrupt or truncated')):
        load_checkpoint(path)


def test_garbage_and_foreign_files(tmp_path):
    path = tmp_path / 'garbage.pt'
    path.write_bytes(b'not a checkpoint at all' * 100)
    with pytest.raises(CheckpointError, match=file_error(path, 'corrupt or truncated')):
        load_checkpoint(path)
    path = tmp_path / 'list.pt'
    torch.save([torch.zeros(2)], path)
    with pytest.raises(CheckpointError, match=file_error(path, 'not a dict')):
        load_checkpoint(path)
    path = tmp_path / 'plain_state_dict.pt'
    torch.save(small_model().state_dict(), path)
    with pytest.raises(CheckpointError, match=file_error(path, 'field format')):
        load_checkpoint(path)


def rewrite(path, edit):
    payload = torch.load(path, weights_only=True)
    edit(payload)
    torch.save(payload, path)


@pytest.mark.parametrize('field', ['architecture', 'keypoints', 'input_size', 'heatmap_size'])
def test_missing_metadata_field(saved, field):
    path, _ = saved
    rewrite(path, lambda p: p['metadata'].pop(field))
    with pytest.raises(CheckpointError, match=file_error(path, f'metadata.{field}')):
        load_checkpoint(path)


@pytest.mark.parametrize('field', ['metadata', 'state_dict'])
def test_missing_section(saved, field):
    path, _ = saved
    rewrite(path, lambda p: p.pop(field))
    with pytest.raises(CheckpointError, match=file_error(path, f'field {field}')):
        load_checkpoint(path)


def test_architecture_mismatch(saved):
    path, _ = saved
    with pytest.raises(CheckpointError, match=file_error(path, "metadata.architecture is 'small'"
                                                               ", expected 'cpm'")):
        load_checkpoint(path, architecture='cpm')


def test_keypoint_count_mismatch(saved):
    path, _ = saved
    with pytest.raises(CheckpointError, match=file_error(path, 'metadata.keypoints has 3')):
        load_checkpoint(path, num_keypoints=14)


def test_state_dict_shape_mismatch(saved):
    path, _ = saved
    # keypoint names say 4 channels, weights have 3: the head does not fit
    rewrite(path, lambda p: p['metadata']['keypoints'].append('d'))
    with pytest.raises(CheckpointError, match=file_error(path, 'field state_dict')):
        load_checkpoint(path)


def test_state_dict_missing_key_and_wrong_sizes(saved):
    path, _ = saved
    rewrite(path, lambda p: p['state_dict'].pop('head.bias'))
    with pytest.raises(CheckpointError, match=file_error(path, 'field state_dict')):
        load_checkpoint(path)
    save_checkpoint(path, small_model(), {'keypoints': NAMES})
    rewrite(path, lambda p: p['metadata'].update(heatmap_size=[46, 46]))
    with pytest.raises(CheckpointError, match=file_error(path, 'metadata.heatmap_size')):
        load_checkpoint(path)


def test_format_constant_is_written(saved):
    path, _ = saved
    assert torch.load(path, weights_only=True)['format'] == FORMAT
