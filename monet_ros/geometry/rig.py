"""Rig files: read a list of Cameras from the project rig YAML, anipose / Pose2Sim
calibration.toml, ROS camera_info YAML, OpenCV FileStorage YAML/XML and DANNCE
label3d .mat files; write the project rig YAML (exact round trip).

Every problem raises RigError naming the file and the field. Files are bounded before they
are parsed (MAX_RIG_BYTES), YAML aliases/anchors are refused (a 600-byte alias bomb would
expand to gigabytes), sizes must be finite positive integers (not booleans).
"""
import math
from pathlib import Path
import re
import tomllib
import warnings

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


def load_yaml_text(path, text):
    """YAML -> Python data without aliases; RigError naming the file otherwise."""
    try:
        return yaml.load(text, Loader=_NoAliasLoader)  # noqa: S506 - a SafeLoader subclass
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


# ----------------------------------------------------------------------------- formats

def _load_project_yaml(path, data):
    frame_id = data.get('frame_id', DEFAULT_FRAME_ID)
    if not isinstance(frame_id, str) or not frame_id:
        raise RigError(path, 'frame_id', f'must be a non-empty string, got {frame_id!r}')
    entries = data['cameras']
    if not isinstance(entries, list):
        raise RigError(path, 'cameras', 'must be a list of camera mappings')
    cameras = []
    for i, entry in enumerate(entries):
        prefix = f'cameras[{i}].'
        if not isinstance(entry, dict):
            raise RigError(path, f'cameras[{i}]', 'must be a mapping')
        unknown = set(entry) - {'name', 'width', 'height', 'K', 'D', 'R', 't', 'topic'}
        if unknown:
            raise RigError(path, prefix + sorted(unknown)[0], 'unknown key (expected name, '
                           'width, height, K, D, R, t, topic)')
        name = str(_require(path, entry, 'name', prefix))
        try:
            cameras.append(_project_camera(path, prefix, name, entry))
        except RigError as exc:     # name the camera too, not only its index
            raise RigError(path, exc.field, f'camera {name!r}: {exc.message}') from None
    return _check_unique(path, cameras), frame_id


def _project_camera(path, prefix, name, entry):
    return _camera(
        path, prefix, {'dist': 'D'}, name=name,
        K=_array(path, prefix + 'K', _require(path, entry, 'K', prefix), [(3, 3)]),
        dist=_array(path, prefix + 'D', entry.get('D', []) or [],
                    [(n,) for n in (0, 4, 5, 8, 12)]),
        R=_rotation(path, prefix + 'R', _require(path, entry, 'R', prefix)),
        t=_array(path, prefix + 't', _require(path, entry, 't', prefix), [(3,)]),
        width=_size(path, prefix + 'width', _require(path, entry, 'width', prefix)),
        height=_size(path, prefix + 'height', _require(path, entry, 'height', prefix)),
        topic=entry.get('topic'))


def _load_camera_info_yaml(path, data):
    """camera_calibration_parsers YAML: intrinsics; identity extrinsics unless R/t given."""
    def matrix(key, shapes):
        node = _require(path, data, key)
        return _array(path, key + '.data', _require(path, node, 'data', key + '.'), shapes)

    model = data.get('distortion_model', 'plumb_bob')
    dist = matrix('distortion_coefficients', [(n,) for n in (0, 4, 5, 8, 12, 14)])
    try:
        dist = opencv_distortion(model, dist, 'distortion_model')
    except ValueError as exc:
        raise RigError(path, 'distortion_model', str(exc).split(': ', 1)[1]) from None
    name = data.get('camera_name') or Path(path).stem
    camera = _camera(
        path, '', {'K': 'camera_matrix.data', 'dist': 'distortion_coefficients.data',
                   'width': 'image_width', 'height': 'image_height', 'name': 'camera_name'},
        name=str(name), K=matrix('camera_matrix', [(3, 3)]), dist=dist,
        R=_rotation(path, 'R', data['R']) if 'R' in data else np.eye(3),
        t=_array(path, 't', data['t'], [(3,)]) if 't' in data else np.zeros(3),
        width=_size(path, 'image_width', _require(path, data, 'image_width')),
        height=_size(path, 'image_height', _require(path, data, 'image_height')),
        topic=data.get('topic'))
    return [camera], DEFAULT_FRAME_ID


def _load_toml(path):
    """anipose / Pose2Sim calibration.toml: [cam_N] sections in numeric order; name, size
    [w, h], matrix (3x3), distortions (OpenCV), rotation (Rodrigues 3-vector), translation."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except tomllib.TOMLDecodeError as exc:
        raise RigError(path, None, f'not valid TOML ({exc})') from None
    sections = sorted((k for k, v in data.items() if isinstance(v, dict) and k != 'metadata'),
                      key=_natural_key)
    cameras = []
    for key in sections:
        section = data[key]
        prefix = f'{key}.'
        if section.get('fisheye', False):
            raise RigError(path, prefix + 'fisheye', 'fisheye cameras are not supported')
        size = _array(path, prefix + 'size', _require(path, section, 'size', prefix), [(2,)])
        cameras.append(_camera(
            path, prefix, {'K': 'matrix', 'dist': 'distortions', 'R': 'rotation',
                           't': 'translation', 'width': 'size[0]', 'height': 'size[1]'},
            name=str(section.get('name', key)),
            K=_array(path, prefix + 'matrix', _require(path, section, 'matrix', prefix),
                     [(3, 3)]),
            dist=_array(path, prefix + 'distortions', section.get('distortions', []),
                        [(n,) for n in (0, 4, 5, 8, 12)]),
            R=_rotation(path, prefix + 'rotation',
                        _require(path, section, 'rotation', prefix)),
            t=_array(path, prefix + 'translation',
                     _require(path, section, 'translation', prefix), [(3,)]),
            width=_size(path, prefix + 'size[0]', size[0]),
            height=_size(path, prefix + 'size[1]', size[1])))
    return _check_unique(path, cameras), DEFAULT_FRAME_ID


# Field names accepted in OpenCV FileStorage files, matched without regard to case (OpenCV's
# camera_calibration sample writes Camera_Matrix, Distortion_Coefficients, image_Width).
_OPENCV_KEYS = {
    'K': ('camera_matrix', 'cameraMatrix', 'K', 'M', 'intrinsic_matrix', 'intrinsics'),
    'D': ('distortion_coefficients', 'dist_coeffs', 'distCoeffs', 'D', 'distortion'),
    'R': ('R', 'rotation_matrix', 'rotation', 'rvec'),
    't': ('T', 't', 'translation', 'tvec'),
    'width': ('image_width', 'width'),
    'height': ('image_height', 'height'),
    'size': ('image_size', 'imageSize'),
    'name': ('camera_name', 'name'),
}
_STEREO_EXTRINSICS = ('extrinsics.yml', 'extrinsics.yaml', 'extrinsics.xml')


def _accepted(field):
    return '/'.join(_OPENCV_KEYS[field])


def _open_storage(path):
    """(cv2.FileStorage opened for reading, {lower-case key: key}); RigError otherwise."""
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        raise RigError(path, None, f'not a readable OpenCV FileStorage file '
                       f'({str(exc).strip()[:200]})') from None
    if not fs.isOpened():
        raise RigError(path, None, 'not a readable OpenCV FileStorage file')
    try:
        keys = {key.lower(): key for key in fs.root().keys()}
    except (cv2.error, SystemError) as exc:
        fs.release()
        raise RigError(path, None, f'not a readable OpenCV FileStorage file '
                       f'({str(exc).strip()[:200]})') from None
    return fs, keys


def _read_node(path, fs, key):
    """A FileStorage entry as an array / str / float; RigError naming the key when its
    rows/cols do not match its data, or it is truncated."""
    try:
        node = fs.getNode(key)
        if node.isMap() or node.isSeq() or node.type() == cv2.FILE_NODE_NONE:
            mat = node.mat()
            if mat is None and node.isSeq():
                mat = np.array([node.at(i).real() for i in range(node.size())])
            return mat
        if node.isString():
            return node.string()
        return node.real()
    except (cv2.error, SystemError) as exc:
        raise RigError(path, key, 'unreadable matrix (rows/cols do not match the data, or '
                       f'the file is truncated): {str(exc).strip()[:200]}') from None


def _load_opencv(path, image_size=None):
    """OpenCV FileStorage (YAML/XML) with one camera (camera_matrix, distortion_coefficients,
    image_width, image_height[, R, T]; OpenCV's camera_calibration sample names too:
    Camera_Matrix, Distortion_Coefficients, image_Width, image_Height) or a stereo pair
    (stereo_calib: M1, D1, M2, D2 in intrinsics.yml, R, T in extrinsics.yml, read from
    beside it when the file itself has no R/T). Files without an image size need
    image_size=(w, h)."""
    fs, keys = _open_storage(path)
    try:
        def first(field, keys=keys, fs=fs):
            for key in _OPENCV_KEYS[field]:
                if key.lower() in keys:
                    real = keys[key.lower()]
                    return real, _read_node(path, fs, real)
            return _OPENCV_KEYS[field][0], None

        def size():
            wkey, w = first('width')
            hkey, h = first('height')
            if w is not None and h is not None:
                return _size(path, wkey, w), _size(path, hkey, h)
            skey, s = first('size')
            if s is not None:
                s = _array(path, skey, s, [(2,)])
                return _size(path, skey + '[0]', s[0]), _size(path, skey + '[1]', s[1])
            if image_size is not None:
                return (_size(path, 'image_size[0]', image_size[0]),
                        _size(path, 'image_size[1]', image_size[1]))
            raise RigError(path, 'image_width', f'missing: the file stores no image size '
                           f'(accepted: {_accepted("width")} with {_accepted("height")}, or '
                           f'{_accepted("size")}); give the size (image_size=(w, h))')

        dist_shapes = [(n,) for n in (0, 4, 5, 8, 12)]
        if 'm1' in keys and 'm2' in keys:  # stereo calibration output
            width, height = size()
            R, t = _stereo_extrinsics(path, fs, keys)
            cams = []
            for k, (R_k, t_k) in enumerate([(np.eye(3), np.zeros(3)), (R, t)], start=1):
                M, D = keys[f'm{k}'], keys.get(f'd{k}')
                cams.append(_camera(
                    path, '', {'K': M, 'dist': D or f'D{k}', 't': 'T'}, name=f'cam{k}',
                    K=_array(path, M, _read_node(path, fs, M), [(3, 3)]),
                    dist=_array(path, D or f'D{k}', _read_node(path, fs, D) if D else [],
                                dist_shapes),
                    R=_rotation(path, 'R', R_k), t=_array(path, 'T', t_k, [(3,)]),
                    width=width, height=height))
            return cams, DEFAULT_FRAME_ID
        kkey, K = first('K')
        if K is None:
            raise RigError(path, 'camera_matrix', f'missing (accepted names: {_accepted("K")},'
                           ' or M1/M2 for a stereo pair)')
        dkey, D = first('D')
        rkey, R = first('R')
        tkey, t = first('t')
        _, name = first('name')
        width, height = size()
        camera = _camera(
            path, '', {'K': kkey, 'dist': dkey, 'R': rkey, 't': tkey},
            name=str(name) if isinstance(name, str) and name else Path(path).stem,
            K=_array(path, kkey, K, [(3, 3)]),
            dist=_array(path, dkey, [] if D is None else D, dist_shapes),
            R=np.eye(3) if R is None else _rotation(path, rkey, R),
            t=np.zeros(3) if t is None else _array(path, tkey, t, [(3,)]),
            width=width, height=height)
        return [camera], DEFAULT_FRAME_ID
    finally:
        fs.release()


def _stereo_extrinsics(path, fs, keys):
    """(R, T) of a stereo pair: from the file, else from stereo_calib's extrinsics.yml
    beside it; RigError naming both when neither has them."""
    if 'r' in keys and 't' in keys:
        return _read_node(path, fs, keys['r']), _read_node(path, fs, keys['t'])
    for name in _STEREO_EXTRINSICS:
        other = Path(path).with_name(name)
        if other.is_file() and other != Path(path):
            _check_file_size(other, MAX_RIG_BYTES)
            ofs, okeys = _open_storage(other)
            try:
                if 'r' in okeys and 't' in okeys:
                    return (_read_node(other, ofs, okeys['r']),
                            _read_node(other, ofs, okeys['t']))
            finally:
                ofs.release()
    raise RigError(path, 'R', 'missing: a stereo pair (M1, M2) needs R and T, in the file or '
                   f'in {" / ".join(_STEREO_EXTRINSICS)} beside it (as stereo_calib writes '
                   'them)')


def _check_file_size(path, limit):
    try:
        size = Path(path).stat().st_size
    except OSError as exc:
        raise RigError(path, None, f'cannot read the file ({exc})') from None
    if size > limit:
        raise RigError(path, None, f'file is {size} bytes, more than the {limit} a rig file '
                       'may have')


def _load_dannce_mat(path, image_size=None):
    """DANNCE / Label3D .mat: camnames, params{K (MATLAB: transposed, skew in K[1, 0]),
    RDistort [k1 k2 k3], TDistort [p1 p2], r (row-vector convention x_cam = X r + t), t}.
    The image size is not stored: pass image_size=(w, h), else 2x the principal point is
    used (with a warning)."""
    import scipy.io

    try:
        mat = scipy.io.loadmat(str(path))
    except Exception as exc:  # scipy raises several types for non-.mat input
        raise RigError(path, None, f'not a readable MATLAB .mat file ({exc})') from None
    params = _require(path, mat, 'params')
    names = mat.get('camnames')
    params = np.asarray(params).ravel()
    names = [str(np.asarray(n).ravel()[0]) for n in np.asarray(names).ravel()] \
        if names is not None else [f'Camera{i + 1}' for i in range(params.size)]
    if len(names) != params.size:
        raise RigError(path, 'camnames', f'{len(names)} names for {params.size} cameras')
    cameras = []
    for i, (name, p) in enumerate(zip(names, params)):
        prefix = f'params[{i}].'

        def field(key, p=p, prefix=prefix):
            if p.dtype.names is None or key not in p.dtype.names:
                raise RigError(path, prefix + key, 'missing')
            return np.asarray(p[key].ravel()[0] if p[key].dtype == object else p[key])

        K_mat = _array(path, prefix + 'K', field('K'), [(3, 3)])
        rd = _array(path, prefix + 'RDistort', field('RDistort'), [(3,), (2,)])
        td = _array(path, prefix + 'TDistort', field('TDistort'), [(2,)])
        k3 = rd[2] if rd.size == 3 else 0.0
        K = K_mat.T
        if image_size is None:
            w, h = int(np.ceil(2 * K[0, 2])), int(np.ceil(2 * K[1, 2]))
            if i == 0:
                warnings.warn(f'{path}: a DANNCE file stores no image size; using twice the '
                              'principal point (pass image_size=(w, h))', stacklevel=4)
        else:
            w, h = image_size
        cameras.append(_camera(
            path, prefix, {'R': 'r', 'dist': 'RDistort'}, name=name, K=K,
            dist=np.array([rd[0], rd[1], td[0], td[1], k3]),
            R=_array(path, prefix + 'r', field('r'), [(3, 3)]).T,
            t=_array(path, prefix + 't', field('t'), [(3,)]), width=w, height=h))
    return _check_unique(path, cameras), DEFAULT_FRAME_ID


# ----------------------------------------------------------------------------- public API

def read_rig(path, image_size=None):
    """Load a rig file of any supported format -> (cameras list[Camera], frame_id str).

    Formats: project rig YAML (frame_id + cameras), anipose / Pose2Sim calibration.toml,
    ROS camera_info YAML (one camera, identity extrinsics unless R/t are given), OpenCV
    FileStorage YAML/XML (OpenCV's sample names too), DANNCE label3d .mat. image_size=(w, h):
    the size for files that store none (DANNCE, stereo_calib's intrinsics.yml).
    Files larger than MAX_RIG_BYTES (MAX_MAT_BYTES for .mat) are refused unread."""
    path = Path(path)
    if not path.is_file():
        raise RigError(path, None, 'no such file' if not path.exists() else 'not a file')
    suffix = path.suffix.lower()
    _check_file_size(path, MAX_MAT_BYTES if suffix == '.mat' else MAX_RIG_BYTES)
    if suffix == '.mat':
        return _load_dannce_mat(path, image_size)
    try:
        head = path.read_bytes()[:4096]
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise RigError(path, None, f'cannot read the file ({exc})') from None
    if suffix == '.toml':
        return _load_toml(path)
    if head.lstrip().startswith((b'%YAML:', b'<?xml', b'<opencv_storage')) \
            or b'!!opencv-matrix' in head or suffix == '.xml':
        return _load_opencv(path, image_size)
    if suffix in ('.yaml', '.yml', ''):
        data = load_yaml_text(path, text)
        if isinstance(data, dict) and 'cameras' in data:
            return _load_project_yaml(path, data)
        if isinstance(data, dict) and 'camera_matrix' in data:
            return _load_camera_info_yaml(path, data)
        raise RigError(path, 'cameras', 'unknown rig format: a YAML rig needs `cameras` '
                       '(project rig) or `camera_matrix` (ROS camera_info)')
    raise RigError(path, None, f'unknown rig format {suffix!r} (expected .yaml/.yml rig or '
                   'camera_info, .toml anipose/Pose2Sim, OpenCV .yaml/.xml, DANNCE .mat)')


def load_rig(path, image_size=None):
    """Load a rig file (any supported format) -> list[Camera] (see read_rig)."""
    return read_rig(path, image_size=image_size)[0]


def _num(x):
    """Float text that YAML 1.1 (PyYAML) reads back as exactly the same float."""
    text = repr(float(x))
    if 'e' in text and '.' not in text.split('e')[0]:
        mantissa, exponent = text.split('e')
        text = f'{mantissa}.0e{exponent}'
    return text


def _vec(values):
    return '[' + ', '.join(_num(v) for v in np.ravel(values)) + ']'


def _mat(m):
    return '[' + ', '.join(_vec(row) for row in np.asarray(m)) + ']'


def save_rig(path, cameras, frame_id=DEFAULT_FRAME_ID):
    """Write cameras as a project rig YAML; load_rig(path) returns equal cameras (exact)."""
    if not cameras:
        raise ValueError('save_rig needs at least one camera')
    lines = ['# monet_ros rig file: x_pixel ~ K (R X + t), world (frame_id) -> camera.',
             f'frame_id: {yaml.safe_dump(str(frame_id), default_style=chr(39)).strip()}',
             'cameras:']
    for cam in cameras:
        lines += [f'  - name: {yaml.safe_dump(cam.name, default_style=chr(39)).strip()}',
                  f'    width: {cam.width}', f'    height: {cam.height}',
                  f'    K: {_mat(cam.K)}', f'    D: {_vec(cam.dist)}',
                  f'    R: {_mat(cam.R)}', f'    t: {_vec(cam.t)}']
        if cam.topic is not None:
            lines.append(f'    topic: {yaml.safe_dump(cam.topic, default_style=chr(39)).strip()}')
    path = Path(path)
    tmp = path.with_name(path.name + '.tmp')
    tmp.write_text('\n'.join(lines) + '\n')
    tmp.replace(path)
