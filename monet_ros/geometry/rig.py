"""Rig files: read a list of Cameras from the project rig YAML, anipose / Pose2Sim
calibration.toml, ROS camera_info YAML, OpenCV FileStorage YAML/XML and DANNCE
label3d .mat files; write the project rig YAML (exact round trip) and anipose
calibration.toml (save_anipose_toml).

Every problem raises RigError naming the file and the field. Files are bounded before they
are parsed (MAX_RIG_BYTES), YAML aliases/anchors are refused (a 600-byte alias bomb would
expand to gigabytes), sizes must be finite positive integers (not booleans).
"""
from pathlib import Path
import tomllib
import warnings

import numpy as np
import yaml

from monet_ros.geometry.rig_fields import (  # noqa: F401 - RigError & co. are public here
    DEFAULT_FRAME_ID,
    DISTORTION_MODELS,
    MAX_MAT_BYTES,
    MAX_RIG_BYTES,
    RigError,
    _array,
    _camera,
    _check_file_size,
    _check_unique,
    _natural_key,
    _require,
    _rotation,
    _size,
    load_yaml_text,
    opencv_distortion,
)
from monet_ros.geometry.rig_opencv import _load_opencv
from monet_ros.geometry.units import (
    UNITS,
    check_units,
    infer_units,
    note_inferred,
    rig_units,
    with_units,
)

# ----------------------------------------------------------------------------- formats

def _load_project_yaml(path, data):
    """(cameras, frame_id, stated units or None) of a project rig YAML mapping."""
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
    return _check_unique(path, cameras), frame_id, data.get('units')


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
    [w, h], matrix (3x3), distortions (OpenCV), rotation (Rodrigues 3-vector), translation;
    [metadata] units (written by monet; anipose's own files have none) -> stated units."""
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
    metadata = data.get('metadata')
    units = metadata.get('units') if isinstance(metadata, dict) else None
    return _check_unique(path, cameras), DEFAULT_FRAME_ID, units


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

def read_rig(path, image_size=None, units=None):
    """Load a rig file of any supported format -> (cameras list[Camera], frame_id str).

    Formats: project rig YAML (frame_id + units + cameras), anipose / Pose2Sim
    calibration.toml, ROS camera_info YAML (one camera, identity extrinsics unless R/t are
    given), OpenCV FileStorage YAML/XML (OpenCV's sample names too), DANNCE label3d .mat.
    image_size=(w, h): the size for files that store none (DANNCE, stereo_calib's
    intrinsics.yml). Files larger than MAX_RIG_BYTES (MAX_MAT_BYTES for .mat) are refused
    unread.

    Length unit (every Camera's `units`, geometry.units): the one the file states (rig
    YAML `units`, [metadata] units of a TOML written by monet), else `units` ('m', 'cm',
    'mm': --rig-units), else the rule of geometry.units.infer_units (noted in one line on
    stderr). RigError (field 'units') for a bad unit, or when `units` differs from the
    file's."""
    cameras, frame_id, stated = _read_rig(Path(path), image_size)
    if units is not None:
        try:
            check_units(units, 'rig units')
        except ValueError as error:
            raise RigError(path, 'units', str(error).split(': ', 1)[1]) from None
    if stated is not None:
        if not isinstance(stated, str) or stated not in UNITS:
            raise RigError(path, 'units', f'must be one of {", ".join(UNITS)}, got {stated!r}')
        if units is not None and units != stated:
            raise RigError(path, 'units', f'the file states {stated!r} but {units!r} was given '
                           '(--rig-units / rig_units): leave the option out or fix the file')
        units = stated
    elif units is None:
        units, reason = infer_units(cameras)
        if reason is not None:
            note_inferred(path, units, reason)
    return with_units(cameras, units), frame_id


def _read_rig(path, image_size):
    """(cameras, frame_id, units the file states or None) of any supported format."""
    if not path.is_file():
        raise RigError(path, None, 'no such file' if not path.exists() else 'not a file')
    suffix = path.suffix.lower()
    _check_file_size(path, MAX_MAT_BYTES if suffix == '.mat' else MAX_RIG_BYTES)
    if suffix == '.mat':
        return (*_load_dannce_mat(path, image_size), None)
    try:
        head = path.read_bytes()[:4096]
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise RigError(path, None, f'cannot read the file ({exc})') from None
    if suffix == '.toml':
        return _load_toml(path)
    if head.lstrip().startswith((b'%YAML:', b'<?xml', b'<opencv_storage')) \
            or b'!!opencv-matrix' in head or suffix == '.xml':
        return (*_load_opencv(path, image_size), None)
    if suffix in ('.yaml', '.yml', ''):
        data = load_yaml_text(path, text)
        if isinstance(data, dict) and 'cameras' in data:
            return _load_project_yaml(path, data)
        if isinstance(data, dict) and 'camera_matrix' in data:
            return (*_load_camera_info_yaml(path, data), None)
        raise RigError(path, 'cameras', 'unknown rig format: a YAML rig needs `cameras` '
                       '(project rig) or `camera_matrix` (ROS camera_info)')
    raise RigError(path, None, f'unknown rig format {suffix!r} (expected .yaml/.yml rig or '
                   'camera_info, .toml anipose/Pose2Sim, OpenCV .yaml/.xml, DANNCE .mat)')


def load_rig(path, image_size=None, units=None):
    """Load a rig file (any supported format) -> list[Camera] (see read_rig; units: the
    rig's length unit when the file states none)."""
    return read_rig(path, image_size=image_size, units=units)[0]


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
    """Write cameras as a project rig YAML (with their length unit, `units`); load_rig(path)
    returns equal cameras (exact). ValueError for no cameras or mixed units."""
    if not cameras:
        raise ValueError('save_rig needs at least one camera')
    units = rig_units(cameras)
    lines = ['# monet_ros rig file: x_pixel ~ K (R X + t), world (frame_id) -> camera.',
             f'frame_id: {yaml.safe_dump(str(frame_id), default_style=chr(39)).strip()}',
             f"units: '{units}'   # length unit of t and of the 3D points (m, cm or mm)",
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


def _toml_value(value):
    """A TOML value of a str, bool, int, float or nested list/array of numbers."""
    if isinstance(value, str):
        return '"' + value.replace('\\', '\\\\').replace('"', '\\"') + '"'
    if isinstance(value, (bool, np.bool_)):
        return 'true' if value else 'false'
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if np.isfinite(value) else ('nan' if np.isnan(value) else
                                                               ('inf' if value > 0 else '-inf'))
    return '[' + ', '.join(_toml_value(v) for v in (value.tolist() if isinstance(
        value, np.ndarray) else value)) + ']'


def save_anipose_toml(path, cameras, metadata=None):
    """Write cameras as an anipose / aniposelib calibration.toml: [cam_N] name, size
    [w, h], matrix (3x3), distortions (OpenCV order, at least 5 values), rotation
    (Rodrigues vector, world -> camera), translation; then [metadata] (str / number
    values) with `units`, the cameras' length unit (anipose ignores it; load_rig reads it).
    load_rig(path) gives the same cameras back (rotation to ~1e-15). Written atomically (a
    .tmp file renamed)."""
    import cv2

    if not cameras:
        raise ValueError('save_anipose_toml needs at least one camera')
    lines = []
    for i, cam in enumerate(cameras):
        dist = np.zeros(max(5, cam.dist.size))
        dist[:cam.dist.size] = cam.dist
        lines += [f'[cam_{i}]', f'name = {_toml_value(cam.name)}',
                  f'size = {_toml_value([int(cam.width), int(cam.height)])}',
                  f'matrix = {_toml_value(np.asarray(cam.K))}',
                  f'distortions = {_toml_value(dist)}',
                  f'rotation = {_toml_value(cv2.Rodrigues(np.asarray(cam.R))[0].ravel())}',
                  f'translation = {_toml_value(np.asarray(cam.t))}', '']
    lines.append('[metadata]')
    metadata = {**(metadata or {}), 'units': rig_units(cameras)}
    lines += [f'{key} = {_toml_value(value)}' for key, value in metadata.items()]
    path = Path(path)
    tmp = path.with_name(path.name + '.tmp')
    tmp.write_text('\n'.join(lines) + '\n')
    tmp.replace(path)
