"""Rig file building blocks shared by the format readers (monet_ros.geometry.rig,
rig_opencv): RigError, bounded reads, alias-free YAML, checked numbers, arrays and sizes,
and the one distortion-model rule used for rig files and CameraInfo messages alike."""
import math
from pathlib import Path
import re

import cv2
import numpy as np
import yaml

from monet_ros.geometry.camera import Camera, CameraError

DEFAULT_FRAME_ID = 'world'
MAX_RIG_BYTES = 8 << 20       # text rig files (a 1000-camera rig is ~1 MB)
MAX_MAT_BYTES = 512 << 20     # DANNCE .mat files (may hold labels too)
# Distortion coefficient counts accepted per ROS distortion_model (OpenCV order k1 k2 p1 p2
# k3 k4 k5 k6 s1..s4 tx ty): the SAME rule for rig files, camera_info YAML and recordings.
DISTORTION_MODELS = {'plumb_bob': (0, 4, 5), 'rational_polynomial': (0, 4, 5, 8, 12, 14),
                     '': (0,), 'none': (0,)}


def opencv_distortion(model, coefficients, where):
    """Coefficients of a ROS CameraInfo distortion_model as a Camera.dist array.

    plumb_bob: 0, 4 or 5 coefficients; rational_polynomial: 0, 4, 5, 8, 12 or 14 (fewer
    than 8 = the higher terms are 0; 14 = tilt terms, accepted only when 0); '' / 'none':
    no coefficients (or all 0). Anything else (equidistant, fisheye...) is refused.
    Raises ValueError starting with `where` (the file/field or topic)."""
    model = str(model)
    d = np.asarray(coefficients, np.float64).reshape(-1)
    if model not in DISTORTION_MODELS:
        raise ValueError(f'{where}: unsupported distortion_model {model!r} (OpenCV '
                         'plumb_bob / rational_polynomial only)')
    if model in ('', 'none'):
        if np.any(d != 0):
            raise ValueError(f'{where}: distortion_model {model!r} with non-zero '
                             'coefficients')
        return np.zeros(0)
    if d.size not in DISTORTION_MODELS[model]:
        raise ValueError(f'{where}: distortion_model {model!r} with {d.size} coefficients '
                         f'(expected {" or ".join(map(str, DISTORTION_MODELS[model]))})')
    if not np.all(np.isfinite(d)):
        raise ValueError(f'{where}: distortion coefficients contain NaN or infinity')
    if d.size == 14:
        if np.any(d[12:] != 0):
            raise ValueError(f'{where}: tilted-sensor terms (coefficients 13-14) are not '
                             'supported')
        d = d[:12]
    return d


class _NoAliasLoader(yaml.SafeLoader):
    """SafeLoader that refuses aliases: rig files never need them, and nested aliases
    (a "billion laughs" file) expand exponentially."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, f'YAML alias *{event.anchor} is not allowed in a rig file',
                event.start_mark)
        return super().compose_node(parent, index)


def safe_yaml(text):
    """yaml.safe_load that refuses aliases (yaml.YAMLError) - for every file a user gives."""
    return yaml.load(text, Loader=_NoAliasLoader)  # noqa: S506 - a SafeLoader subclass


def load_yaml_text(path, text):
    """YAML -> Python data without aliases; RigError naming the file otherwise."""
    try:
        return safe_yaml(text)
    except yaml.YAMLError as exc:
        raise RigError(path, None, f'not valid YAML ({exc})') from None


class RigError(ValueError):
    """A rig file cannot be used; `.path` and `.field` say where."""

    def __init__(self, path, field, message):
        self.path = str(path)
        self.field = field
        self.message = message
        where = f'{self.path}: field {field!r}: ' if field else f'{self.path}: '
        super().__init__(where + message)

    def __reduce__(self):
        # raised in a worker process: it must unpickle in the parent
        return type(self), (self.path, self.field, self.message)


# ----------------------------------------------------------------------------- helpers

def _natural_key(text):
    return [int(part) if part.isdigit() else part for part in re.split(r'(\d+)', text)]


def _has_bool(value, depth=0):
    """True when a (nested list of) value(s) holds a bool (YAML true/false)."""
    if isinstance(value, (bool, np.bool_)):
        return True
    if isinstance(value, (list, tuple)) and depth < 4:
        return any(_has_bool(v, depth + 1) for v in value)
    return False


def _array(path, field, value, shapes):
    """value -> float64 array reshaped to the first matching shape in `shapes`."""
    if value is None:
        raise RigError(path, field, 'missing')
    if _has_bool(value):
        raise RigError(path, field, f'holds a boolean, not a number: {str(value)[:60]!r}')
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise RigError(path, field, f'not a numeric array: {str(value)[:60]!r}') from None
    for shape in shapes:
        if array.shape == shape:
            return array
        vector_like = sum(d > 1 for d in array.shape) <= 1
        if array.size == int(np.prod(shape)) and (vector_like or len(shape) == 1 and
                                                   array.ndim == 1):
            return array.reshape(shape)
    raise RigError(path, field, f'expected shape {" or ".join(map(str, shapes))}, '
                   f'got {array.shape}')


def _require(path, mapping, key, prefix=''):
    if not isinstance(mapping, dict) or key not in mapping or mapping[key] is None:
        raise RigError(path, prefix + key, 'missing')
    return mapping[key]


def _size(path, field, value):
    """A positive integer size (an int, or a float/string with an integer value); booleans,
    NaN, infinity and sizes above 1e6 pixels are refused."""
    if isinstance(value, (bool, np.bool_)):
        raise RigError(path, field, f'must be a positive integer, got the boolean {value!r}')
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise RigError(path, field, f'not a number: {str(value)[:40]!r}') from None
    if not math.isfinite(number) or number != int(number) or not 0 < number <= 1e6:
        raise RigError(path, field, f'must be a positive integer (<= 1000000), got '
                       f'{str(value)[:40]!r}')
    return int(number)


def _camera(path, prefix, fields=None, **kwargs):
    """Camera(**kwargs), turning CameraError into RigError naming file and field
    (`fields` maps Camera field names to the file's names)."""
    try:
        return Camera(**kwargs)
    except CameraError as exc:
        name = (fields or {}).get(exc.field, exc.field)
        raise RigError(path, prefix + name, str(exc).split(': ', 2)[-1]) from None


def _rotation(path, field, value):
    """3x3 matrix, or a 3-vector Rodrigues rotation."""
    array = _array(path, field, value, [(3, 3), (3,)])
    if array.shape == (3,):
        array = cv2.Rodrigues(array)[0]
    return array


def _check_unique(path, cameras):
    names = [c.name for c in cameras]
    for name in names:
        if names.count(name) > 1:
            raise RigError(path, 'name', f'duplicate camera name {name!r}')
    if not cameras:
        raise RigError(path, 'cameras', 'no cameras in the file')
    return cameras


def _check_file_size(path, limit):
    try:
        size = Path(path).stat().st_size
    except OSError as exc:
        raise RigError(path, None, f'cannot read the file ({exc})') from None
    if size > limit:
        raise RigError(path, None, f'file is {size} bytes, more than the {limit} a rig file '
                       'may have')
