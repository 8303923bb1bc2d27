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
"""
import json
from pathlib import Path

import torch

from monet_ros.atomic import atomic_write
from monet_ros.models.registry import build_model

FORMAT = 'monet_ros.checkpoint/1'
REQUIRED = ('architecture', 'keypoints', 'input_size', 'heatmap_size')


class CheckpointError(ValueError):
    """A checkpoint is missing, unreadable or does not match; names the file and field."""


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
    return json.loads(json.dumps(meta))


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


def read_checkpoint(path):
    """(metadata, state_dict) of a checkpoint file, validated; CheckpointError otherwise."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f'{path}: checkpoint file not found')
    try:
        payload = torch.load(path, map_location='cpu', weights_only=True)
    except Exception as error:  # noqa: BLE001 - zip, pickle and EOF errors all mean "corrupt"
        raise CheckpointError(f'{path}: not a readable checkpoint (corrupt or truncated): '
                              f'{type(error).__name__}: {error}') from error
    if not isinstance(payload, dict):
        raise CheckpointError(f'{path}: not a monet_ros checkpoint (top level is '
                              f'{type(payload).__name__}, not a dict)')
    if payload.get('format') != FORMAT:
        raise CheckpointError(f'{path}: field format is {payload.get("format")!r}, '
                              f'expected {FORMAT!r}')
    for field in ('metadata', 'state_dict'):
        if not isinstance(payload.get(field), dict):
            raise CheckpointError(f'{path}: field {field} is missing or not a dict')
    meta = payload['metadata']
    for field in REQUIRED:
        if field not in meta:
            raise CheckpointError(f'{path}: field metadata.{field} is missing')
    keypoints = meta['keypoints']
    if not isinstance(keypoints, list) or not all(isinstance(k, str) for k in keypoints) \
            or not keypoints:
        raise CheckpointError(f'{path}: field metadata.keypoints must be a non-empty list of '
                              f'names, got {keypoints!r}')
    if not isinstance(meta.get('model_options', {}), dict):
        raise CheckpointError(f'{path}: field metadata.model_options must be a dict')
    meta.setdefault('model_options', {})
    meta.setdefault('step', 0)
    meta.setdefault('metrics', {})
    return meta, payload['state_dict']


def load_checkpoint(path, architecture=None, num_keypoints=None, device='cpu'):
    """Rebuild the model of a checkpoint and load its weights -> (model in eval mode, metadata).

    architecture / num_keypoints: when given, the checkpoint must match them. Every problem
    (missing file, corrupt or truncated file, missing metadata, architecture or keypoint-count
    mismatch, state_dict that does not fit the architecture) raises CheckpointError naming
    the file and the field.
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
    except (TypeError, ValueError) as error:
        raise CheckpointError(f'{path}: field metadata.architecture/model_options cannot build '
                              f'a model: {error}') from error
    for field in ('input_size', 'heatmap_size'):
        if list(getattr(model, field)) != list(meta[field]):
            raise CheckpointError(f'{path}: field metadata.{field} is {meta[field]!r} but '
                                  f'{meta["architecture"]!r} has {list(getattr(model, field))}')
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as error:
        raise CheckpointError(f'{path}: field state_dict does not fit architecture '
                              f'{meta["architecture"]!r} with {count} keypoints: {error}') \
            from error
    return model.to(device).eval(), meta
