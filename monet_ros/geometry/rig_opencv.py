"""OpenCV FileStorage (YAML/XML) calibration files as rigs: one camera (the names OpenCV's
own samples write too) or a stereo pair (stereo_calib's intrinsics.yml + extrinsics.yml)."""
from pathlib import Path

import cv2
import numpy as np

from monet_ros.geometry.rig_fields import (
    DEFAULT_FRAME_ID,
    MAX_RIG_BYTES,
    RigError,
    _array,
    _camera,
    _check_file_size,
    _rotation,
    _size,
)

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
