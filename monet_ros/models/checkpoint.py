"""Detector checkpoints: state_dict + JSON-able metadata, written atomically.

File = torch.save of {'format': FORMAT, 'metadata': dict, 'state_dict': dict}. Metadata:
    architecture  str        registry name ('cpm', 'hourglass', 'small')
    keypoints     list[str]  heatmap channel order (len = num_keypoints)
    input_size    [H, W]     network input
    heatmap_size  [h, w]     network output
    model_options dict       build_model keyword arguments (to rebuild the same network)
    step          int        training step
    metrics       dict       anything JSON-able (losses, PCK, ...)
plus any further JSON-able keys the caller adds. Loaded with torch.load(weights_only=True),
so a checkpoint can never run code.

Nothing in a checkpoint is trusted before it is checked (read_checkpoint): the zip
archive's CRCs are verified (torch.load does not: a flipped bit in the weights loads
silently), every metadata field is checked for type and range, sizes are bounded (width,
blocks, stages, input size, keypoint count: a hostile file cannot make the network
exhaust memory) BEFORE any network is built, and every weight must be finite. Every
problem is one CheckpointError naming the file and the field, for the API, the detector's
`model` parameter and its hot reload alike.
"""
import json
from pathlib import Path
import re
import zipfile

import torch

from monet_ros.atomic import atomic_write
from monet_ros.models.registry import (
    MAX_INPUT_SIDE,
    MODELS,
    OptionError,
    build_model,
    check_options,
)

FORMAT = 'monet_ros.checkpoint/1'
REQUIRED = ('architecture', 'keypoints', 'input_size', 'heatmap_size')


class CheckpointError(ValueError):
    """A checkpoint is missing, unreadable or does not match; names the file and field."""


MAX_FILE_BYTES = 4 << 30          # larger files are refused before reading
MAX_KEYPOINTS = 1000


def _is_int(value):
    return isinstance(value, int) and not isinstance(value, bool)


def _check_pair(path, field, value):
    """[H, W] of positive ints <= MAX_INPUT_SIDE (a tuple/list of two), else CheckpointError."""
    if not isinstance(value, (list, tuple)) or len(value) != 2 \
            or not all(_is_int(v) and 1 <= v <= MAX_INPUT_SIDE for v in value):
        raise CheckpointError(f'{path}: field metadata.{field} must be a pair [H, W] of ints '
                              f'in 1..{MAX_INPUT_SIDE}, got {value!r}')
    return list(value)


def validate_metadata(path, meta):
    """Check every metadata field's type and range (bounded sizes) before a network is
    built; returns the metadata with defaults filled in. Raises CheckpointError naming the
    file and field."""
    for field in REQUIRED:
        if field not in meta:
            raise CheckpointError(f'{path}: field metadata.{field} is missing')
    architecture = meta['architecture']
    if not isinstance(architecture, str) or architecture not in MODELS:
        raise CheckpointError(f'{path}: field metadata.architecture must be one of '
                              f'{sorted(MODELS)}, got {_short(architecture)}')
    keypoints = meta['keypoints']
    if not isinstance(keypoints, list) or not all(isinstance(k, str) for k in keypoints) \
            or not keypoints or len(keypoints) > MAX_KEYPOINTS:
        raise CheckpointError(f'{path}: field metadata.keypoints must be a non-empty list of '
                              f'at most {MAX_KEYPOINTS} names, got {_short(keypoints)}')
    for field in ('input_size', 'heatmap_size'):
        meta[field] = _check_pair(path, field, meta[field])
    options = meta.setdefault('model_options', {})
    if not isinstance(options, dict):
        raise CheckpointError(f'{path}: field metadata.model_options must be a dict, got '
                              f'{_short(options)}')
    try:
        check_options(architecture, options)
    except OptionError as error:
        raise CheckpointError(f'{path}: field metadata.model_options.{error.option}: '
                              f'{str(error).split(": ", 1)[1]}') from None
    if 'input_size' in options and list(options['input_size']) != meta['input_size']:
        raise CheckpointError(f'{path}: field metadata.model_options.input_size '
                              f'{options["input_size"]!r} differs from metadata.input_size '
                              f'{meta["input_size"]!r}')
    step = meta.setdefault('step', 0)
    if not _is_int(step) or step < 0:
        raise CheckpointError(f'{path}: field metadata.step must be an int >= 0, got '
                              f'{_short(step)}')
    if not isinstance(meta.setdefault('metrics', {}), dict):
        raise CheckpointError(f'{path}: field metadata.metrics must be a dict')
    return meta


def _short(value, limit=60):
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + '...'


def verify_archive(path):
    """Check the CRC-32 of every member of a checkpoint's zip archive (torch.save's
    format; torch.load does not check them). Raises CheckpointError naming the member."""
    try:
        size = path.stat().st_size
    except OSError as error:
        raise CheckpointError(f'{path}: cannot read the checkpoint: {error}') from error
    if size > MAX_FILE_BYTES:
        raise CheckpointError(f'{path}: checkpoint is {size} bytes, more than the '
                              f'{MAX_FILE_BYTES} a detector checkpoint can need')
    if not zipfile.is_zipfile(path):
        raise CheckpointError(f'{path}: not a readable checkpoint (not a torch.save zip '
                              'archive; corrupt or truncated)')
    try:
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as error:
        raise CheckpointError(f'{path}: not a readable checkpoint (corrupt or truncated zip '
                              f'archive: {error})') from error
    if bad is not None:
        raise CheckpointError(f'{path}: archive member {bad!r} fails its CRC check (the file '
                              'is corrupted)')


def check_weights(path, state):
    """Every state_dict entry must be a tensor with finite values (CheckpointError naming
    the first that is not)."""
    for key, value in state.items():
        if not isinstance(key, str) or not isinstance(value, torch.Tensor):
            raise CheckpointError(f'{path}: field state_dict.{key} is not a tensor')
        if value.is_floating_point() and not bool(torch.isfinite(value).all()):
            bad = int((~torch.isfinite(value)).sum())
            raise CheckpointError(f'{path}: field state_dict.{key} holds {bad} non-finite '
                                  'value(s) (NaN/inf; corrupted or diverged weights)')


def _model_metadata(model, metadata):
    """The full metadata for `model`: caller's fields + those derived from the model."""
    meta = dict(metadata)
    derived = {
        'architecture': model.architecture,
        'input_size': list(model.input_size),
        'heatmap_size': list(model.heatmap_size),
        'model_options': dict(getattr(model, 'model_options', {})),
    }
    for key, value in derived.items():
        given = meta.get(key)
        if given is not None and (list(given) if isinstance(given, tuple) else given) != value:
            raise ValueError(f'save_checkpoint: metadata.{key} is {given!r} but the model has '
                             f'{value!r}')
        meta[key] = value
    keypoints = meta.get('keypoints')
    if keypoints is None:
        raise ValueError('save_checkpoint: metadata.keypoints (list of names) is required')
    if (not isinstance(keypoints, (list, tuple))
            or not all(isinstance(k, str) for k in keypoints)):
        raise ValueError(f'save_checkpoint: metadata.keypoints must be a list of str, '
                         f'got {keypoints!r}')
    if len(keypoints) != model.num_keypoints:
        raise ValueError(f'save_checkpoint: metadata.keypoints has {len(keypoints)} names but '
                         f'the model has {model.num_keypoints} channels')
    meta['keypoints'] = list(keypoints)
    meta.setdefault('step', 0)
    meta.setdefault('metrics', {})
    for key, value in meta.items():
        try:
            json.dumps(value, allow_nan=True)
        except (TypeError, ValueError) as error:
            raise ValueError(f'save_checkpoint: metadata.{key} is not JSON-able: {error}') \
                from error
    # Round trip through JSON: plain dicts/lists/str/numbers only (what weights_only loads).
    meta = json.loads(json.dumps(meta))
    try:   # never write a checkpoint that read_checkpoint would refuse
        validate_metadata('save_checkpoint', dict(meta))
    except CheckpointError as error:
        raise ValueError(str(error)) from None
    return meta


def save_checkpoint(path, model, metadata):
    """Write model.state_dict() + metadata to `path` atomically; returns the full metadata.

    The file is written to a temporary file in the same folder, flushed and fsynced, then
    renamed over `path` (os.replace): readers see the old file or the new one, never a
    partial one, and a failed write leaves no temporary file behind.
    """
    if getattr(model, '_fused', False):
        raise ValueError('save_checkpoint: the model was fused for inference '
                         '(fuse_for_inference); save the unfused model')
    meta = _model_metadata(model, metadata)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu() if isinstance(v, torch.Tensor) else v
             for k, v in model.state_dict().items()}
    payload = {'format': FORMAT, 'metadata': meta, 'state_dict': state}
    with atomic_write(path) as stream:
        torch.save(payload, stream)
    return meta


_UNSAFE = re.compile(r'Unsupported global: GLOBAL ([\w.]+)')


def torch_load_problem(error, what='monet checkpoint'):
    """One line for an error of torch.load(..., weights_only=True): a file holding pickled
    Python objects is 'not a <what>', named as unsafe and refused (torch's advice to load it
    with weights_only=False, which would run its code, is never relayed); anything else is
    a corrupt or truncated file."""
    text = str(error)
    if 'Weights only load failed' in text or 'WeightsUnpickler' in text:
        found = _UNSAFE.search(text)
        objects = f' ({found.group(1)})' if found else ''
        return (f'not a {what}: it holds pickled Python objects{objects}, which are unsafe '
                'to load (they can run code); refused')
    return f'not a readable checkpoint (corrupt or truncated): {type(error).__name__}: {text}'


def read_checkpoint(path):
    """(metadata, state_dict) of a checkpoint file, validated (archive CRCs, metadata types,
    ranges and bounded sizes, finite weights); CheckpointError otherwise."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f'{path}: checkpoint file not found')
    verify_archive(path)
    try:
        payload = torch.load(path, map_location='cpu', weights_only=True)
    except Exception as error:  # noqa: BLE001 - zip, pickle and EOF errors all mean "corrupt"
        raise CheckpointError(f'{path}: {torch_load_problem(error)}') from error
    if not isinstance(payload, dict):
        raise CheckpointError(f'{path}: not a monet_ros checkpoint (top level is '
                              f'{type(payload).__name__}, not a dict)')
    if payload.get('format') != FORMAT:
        raise CheckpointError(f'{path}: field format is {_short(payload.get("format"))}, '
                              f'expected {FORMAT!r}')
    for field in ('metadata', 'state_dict'):
        if not isinstance(payload.get(field), dict):
            raise CheckpointError(f'{path}: field {field} is missing or not a dict')
    meta = validate_metadata(path, payload['metadata'])
    check_weights(path, payload['state_dict'])
    return meta, payload['state_dict']


def load_checkpoint(path, architecture=None, num_keypoints=None, device='cpu'):
    """Rebuild the model of a checkpoint and load its weights -> (model in eval mode, metadata).

    architecture / num_keypoints: when given, the checkpoint must match them. Every problem
    (missing file, corrupt or truncated file or archive CRC, metadata of the wrong type or
    range, non-finite weights, architecture or keypoint-count mismatch, state_dict that does
    not fit the architecture) raises CheckpointError naming the file and the field; the
    metadata is validated before any network is built.
    """
    path = Path(path)
    meta, state = read_checkpoint(path)
    if architecture is not None and meta['architecture'] != architecture:
        raise CheckpointError(f'{path}: field metadata.architecture is '
                              f'{meta["architecture"]!r}, expected {architecture!r}')
    count = len(meta['keypoints'])
    if num_keypoints is not None and count != num_keypoints:
        raise CheckpointError(f'{path}: field metadata.keypoints has {count} keypoints, '
                              f'expected {num_keypoints}')
    try:
        model = build_model(meta['architecture'], count, **meta['model_options'])
    except (TypeError, ValueError, RuntimeError) as error:
        raise CheckpointError(f'{path}: field metadata.architecture/model_options cannot build '
                              f'a model: {error}') from error
    for field in ('input_size', 'heatmap_size'):
        if list(getattr(model, field)) != list(meta[field]):
            raise CheckpointError(f'{path}: field metadata.{field} is {meta[field]!r} but '
                                  f'{meta["architecture"]!r} has {list(getattr(model, field))}')
    try:
        model.load_state_dict(state, strict=True)
    except (RuntimeError, TypeError, ValueError) as error:
        raise CheckpointError(f'{path}: field state_dict does not fit architecture '
                              f'{meta["architecture"]!r} with {count} keypoints: {error}') \
            from error
    return model.to(device).eval(), meta
