"""DANNCE / Label3D .mat files (MATLAB v5 or v7.3): camnames (1, V) cell; labelData (V, 1)
cell of structs with data_2d (F, 2K) = per frame K (u, v) pairs (pixels, MATLAB 1-based
pixel centres as Label3D stores them: the same convention as the file's K, so they are
used as they are), data_3d (F, 3K), data_frame (1, F) the frame index in that camera's
video (0-based, as DANNCE indexes videos), data_sampleID (1, F).

Label3D files do not name the keypoints: they are kp0 .. kp{K-1} in column order (map
them with --keypoint-map kp0=Snout or give --skeleton with K names in that order).
NaN pairs are unlabelled.
"""
import numpy as np

from monet_ros.labels import LabelError, LabelRow
from monet_ros.labels_import import ImportResult, camera_for


def _cell_text(value):
    while isinstance(value, np.ndarray) and value.dtype == object:
        value = value.ravel()[0]
    return str(np.asarray(value).ravel()[0]) if isinstance(value, np.ndarray) else str(value)


def read_dannce(path, cameras=(), camera=None, min_score=0.0, camera_map=None):
    """(rows, keypoints, 0) of one Label3D .mat file."""
    import scipy.io as sio
    try:
        mat = sio.loadmat(path)
    except Exception as error:    # noqa: BLE001 - scipy raises many kinds for non-.mat input
        raise LabelError(f'{path}: cannot read as a Label3D .mat file ({error})') from None
    for key in ('camnames', 'labelData'):
        if key not in mat:
            raise LabelError(f'{path}: field {key}: missing; not a DANNCE Label3D file')
    names = [_cell_text(c) for c in np.asarray(mat['camnames'], dtype=object).ravel()]
    cells = np.asarray(mat['labelData'], dtype=object).ravel()
    if len(cells) != len(names):
        raise LabelError(f'{path}: field labelData: {len(cells)} cameras, camnames has '
                         f'{len(names)}')
    rows, keypoints = [], ()
    for v, (name, cell) in enumerate(zip(names, cells)):
        cell = cell.ravel()[0] if cell.dtype == object else cell
        try:
            data = np.asarray(cell['data_2d'].ravel()[0], dtype=np.float64)
            frames = np.asarray(cell['data_frame'].ravel()[0]).ravel().astype(np.int64)
        except (ValueError, KeyError, IndexError, TypeError) as error:
            raise LabelError(f'{path}: field labelData{{{v + 1}}}: no data_2d / data_frame '
                             f'({error})') from None
        if data.ndim != 2 or data.shape[1] % 2 or len(frames) != data.shape[0]:
            raise LabelError(f'{path}: field labelData{{{v + 1}}}.data_2d: shape '
                             f'{data.shape} with {len(frames)} frames, expected (F, 2K)')
        K = data.shape[1] // 2
        keypoints = tuple(f'kp{k}' for k in range(K))
        cam = camera_for(name, cameras, camera, camera_map)
        points = data.reshape(len(frames), K, 2)
        for i, k in zip(*np.nonzero(np.isfinite(points).all(-1))):
            u, v_ = points[i, k]
            rows.append(LabelRow(str(path), int(i) + 1, None, int(frames[i]), cam, keypoints[k],
                                 float(u), float(v_),
                                 f'labelData{{{v + 1}}}.data_2d row {i + 1} kp{k}'))
    return rows, keypoints, 0


def import_dannce(paths, cameras=(), camera=None, min_score=0.0, camera_map=None):
    files = []
    for p in paths:
        files += sorted(p.rglob('*.mat')) if p.is_dir() else [p]
    if not files:
        raise LabelError(f'{", ".join(map(str, paths))}: no .mat file found')
    rows, keypoints = [], {}
    for f in files:
        r, k, _ = read_dannce(f, cameras, camera, min_score, camera_map)
        rows += r
        keypoints.update(dict.fromkeys(k))
    return ImportResult(rows, tuple(keypoints))
