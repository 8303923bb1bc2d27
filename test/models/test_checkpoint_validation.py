"""Checkpoints are not trusted: metadata types, ranges and bounded sizes are checked before
any network is built, the zip archive's CRCs are verified (torch.load does not) and
non-finite weights are refused - one CheckpointError for load_checkpoint and
Detector.from_checkpoint alike (the detector node's `model` parameter and hot reload use
the same path; see test/nodes/test_bad_input_nodes.py).

Built from issue 14's examples: `input_size: 64` (an int), `model_options.width` -16 or
200000, a million context blocks, and one bit flipped inside the weights of the zip
(a weight becomes ~1e37, the member's CRC no longer matches)."""
from contextlib import contextmanager
import json
import re
import zipfile

import numpy as np
import pytest
import torch
from torch.nn.modules.module import register_module_parameter_registration_hook

from monet_ros.models import (
    CheckpointError,
    Detector,
    build_model,
    load_checkpoint,
    save_checkpoint,
)

NAMES = ['a', 'b', 'c']
# "never slow" as a count, not a wall time: the parameters any refused or odd checkpoint
# makes torch allocate stay below this (a network of a mutated width 10**12 would not)
MAX_BUILT = 50_000_000


@contextmanager
def built_parameters():
    """Counts the parameter elements of every torch module built inside (torch's global
    parameter registration hook): [total]."""
    total = [0]

    def hook(module, name, param):
        if param is not None:
            total[0] += param.numel()
    handle = register_module_parameter_registration_hook(hook)
    try:
        yield total
    finally:
        handle.remove()


@pytest.fixture
def saved(tmp_path):
    torch.manual_seed(0)
    path = tmp_path / 'model.pt'
    save_checkpoint(path, build_model('small', 3, width=16, input_size=(64, 64)),
                    {'keypoints': NAMES})
    return path


def rewrite(path, edit):
    payload = torch.load(path, weights_only=True)
    edit(payload)
    torch.save(payload, path)


def refused(path, field):
    """Both API entry points raise CheckpointError naming the file and the field before
    any network is built (no parameter allocated)."""
    pattern = re.escape(str(path)) + '.*' + re.escape(field)
    for load in (load_checkpoint, lambda p: Detector.from_checkpoint(p, device='cpu')):
        with built_parameters() as built, pytest.raises(CheckpointError, match=pattern):
            load(path)
        assert built[0] == 0, built


@pytest.mark.parametrize('field, value, named', [
    ('input_size', 64, 'metadata.input_size'),                 # the example
    ('input_size', [64, 64, 3], 'metadata.input_size'),
    ('input_size', [64.0, 64.0], 'metadata.input_size'),
    ('input_size', [True, 64], 'metadata.input_size'),
    ('input_size', [64, 10 ** 9], 'metadata.input_size'),
    ('heatmap_size', 'big', 'metadata.heatmap_size'),
    ('architecture', ['small'], 'metadata.architecture'),
    ('architecture', 'resnet', 'metadata.architecture'),
    ('keypoints', ['x'] * 100_000, 'metadata.keypoints'),
    ('step', -3, 'metadata.step'),
    ('model_options', [], 'metadata.model_options'),
])
def test_metadata_types_and_ranges(saved, field, value, named):
    rewrite(saved, lambda p: p['metadata'].update({field: value}))
    refused(saved, named)


@pytest.mark.parametrize('option, value', [
    ('width', -16), ('width', 200_000), ('width', 16.0), ('width', True),
    ('context_blocks', 1_000_000), ('depth', 3), ('input_size', [32, 32]),
])
def test_model_options_are_bounded_before_building(saved, option, value):
    rewrite(saved, lambda p: p['metadata']['model_options'].update({option: value}))
    refused(saved, f'metadata.model_options.{option}')


def _float_member(path):
    """(name, offset in the file, dtype) of the largest float tensor member of the zip."""
    with zipfile.ZipFile(path) as archive:
        infos = [i for i in archive.infolist() if '/data/' in i.filename]
        info = max(infos, key=lambda i: i.file_size)
        assert info.compress_type == zipfile.ZIP_STORED
    with open(path, 'rb') as stream:      # data starts after the local header + name + extra
        stream.seek(info.header_offset + 26)
        name_len, extra_len = np.frombuffer(stream.read(4), '<u2')
    return info, info.header_offset + 30 + int(name_len) + int(extra_len)


def test_bit_flip_in_weights_is_refused(saved):
    """One exponent bit of one float32 weight flipped in the file: torch.load alone gives
    a ~1e37 weight (checked here); the archive check refuses the file."""
    info, start = _float_member(saved)
    data = bytearray(saved.read_bytes())
    data[start + 3] ^= 0x40                  # exponent MSB of the first float32 (little end)
    saved.write_bytes(bytes(data))
    payload = torch.load(saved, weights_only=True)        # torch does not notice
    assert max(float(t.abs().max()) for t in payload['state_dict'].values()
               if t.is_floating_point()) > 1e30
    refused(saved, 'CRC')


@pytest.mark.parametrize('bad', [float('nan'), float('inf')])
def test_non_finite_weights_are_refused(saved, bad):
    """A valid archive (CRCs right) whose weights hold NaN / inf (e.g. a diverged run)."""
    def poison(payload):
        payload['state_dict']['head.weight'][0, 0, 0, 0] = bad
    rewrite(saved, poison)
    with zipfile.ZipFile(saved) as archive:
        assert archive.testzip() is None
    refused(saved, 'state_dict.head.weight')


def test_valid_checkpoint_still_loads(saved):
    model, meta = load_checkpoint(saved)
    assert meta['input_size'] == [64, 64] and meta['keypoints'] == NAMES
    assert Detector.from_checkpoint(saved, device='cpu').input_size == (64, 64)


VALUES = [0, 1, -1, 3, 64, 2 ** 31, 10 ** 12, 0.5, float('nan'), float('inf'), True, None,
          '', 'x', [], [64], [64, 64], [64, 64, 3], ['a'], {}, {'width': 8}, [[64, 64]]]
FIELDS = ['architecture', 'keypoints', 'input_size', 'heatmap_size', 'model_options',
          'step', 'metrics', 'model_options.width', 'model_options.context_blocks',
          'model_options.input_size', 'model_options.num_stages']


def test_seeded_metadata_mutations_only_ever_give_checkpoint_error(saved):
    """200 seeded mutations (1-3 fields set to odd values): each load either succeeds with
    a working detector or raises CheckpointError - never another exception, never slow."""
    original = torch.load(saved, weights_only=True)
    rng = np.random.default_rng(14)
    outcomes = {'loaded': 0, 'refused': 0}
    for case in range(200):
        payload = {k: v for k, v in original.items()}
        meta = json_copy(original['metadata'])
        for _ in range(int(rng.integers(1, 4))):
            field = FIELDS[int(rng.integers(len(FIELDS)))]
            value = VALUES[int(rng.integers(len(VALUES)))]
            if field.startswith('model_options.'):
                if isinstance(meta.get('model_options'), dict):
                    meta['model_options'][field.split('.', 1)[1]] = value
            else:
                meta[field] = value
        payload['metadata'] = meta
        torch.save(payload, saved)
        with built_parameters() as built:
            try:
                model, _ = load_checkpoint(saved)
            except CheckpointError as error:
                assert str(saved) in str(error), error
                outcomes['refused'] += 1
            else:
                with torch.inference_mode():
                    out = model(torch.zeros(1, 3, *model.input_size))[-1]
                assert out.shape[-2:] == tuple(model.heatmap_size), case
                outcomes['loaded'] += 1
        assert built[0] <= MAX_BUILT, f'case {case}: {meta}: {built[0]} parameters'
    assert outcomes['refused'] > 100


def json_copy(value):
    return json.loads(json.dumps(value))


@pytest.mark.parametrize('name, options, option', [
    ('small', {'width': 10 ** 6}, 'width'), ('small', {'context_blocks': 10 ** 6},
                                             'context_blocks'),
    ('cpm', {'num_stages': 0}, 'num_stages'), ('hourglass', {'width': 64}, 'width'),
    ('small', {'input_size': (64, 10 ** 6)}, 'input_size'), ('cpm', {'width': 2.5}, 'width'),
])
def test_build_model_checks_options_before_allocating(name, options, option):
    """The same bounds for a fresh model (CLI / node options) as for checkpoints."""
    from monet_ros.models.registry import OptionError
    with built_parameters() as built, \
            pytest.raises(OptionError, match=f'model option {option}') as info:
        build_model(name, 3, **options)
    assert info.value.option == option
    assert built[0] == 0, built
