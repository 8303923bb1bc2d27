"""Rig files as users have them, and broken ones: every problem is a RigError naming the
file and the field - never a raw ValueError/OverflowError/cv2.error/MemoryError, never a
value silently taken (issue 14: `width: true`, NaN/inf sizes, a YAML alias bomb, 50 MB rig
files, OpenCV XML whose rows/cols lie or that is cut; OpenCV's own sample calibration
files are read).

"Fast" and "unread" are asserted as memory, not wall time (which a loaded machine
stretches): the peak of Python's allocations while loading (tracemalloc) stays far below
what expanding the bomb or reading the file would take."""
from contextlib import contextmanager
import tracemalloc

import cv2
import numpy as np
import pytest

from monet_ros.geometry import RigError, load_rig, read_rig, save_rig
from monet_ros.geometry.rig import MAX_RIG_BYTES


@contextmanager
def peak_allocation():
    """[peak bytes] Python allocated inside the block (tracemalloc)."""
    peak = [0]
    tracemalloc.start()
    try:
        yield peak
    finally:
        peak[0] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()


K = np.array([[658.2, 0.0, 319.4], [0.0, 657.9, 241.1], [0.0, 0.0, 1.0]])
D = np.array([-0.25, 0.11, 0.0004, -0.0007, -0.02])

PROJECT = """frame_id: world
cameras:
  - name: cam0
    width: {width}
    height: 120
    K: [[137.7, 0.0, 80.8], [0.0, 139.5, 58.8], [0.0, 0.0, 1.0]]
    D: [-0.08, 0.02, 0.0, 0.0, 0.0]
    R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    t: [0.0, 0.8, 4.1]
"""


@pytest.mark.parametrize('width', ['true', 'false', '.nan', '.inf', '-.inf', '1e400',
                                   '160.5', '"wide"', '[160]'])
def test_bad_width_names_file_camera_and_field(tmp_path, width):
    path = tmp_path / 'rig.yaml'
    path.write_text(PROJECT.format(width=width))
    with pytest.raises(RigError) as info:
        load_rig(path)
    text = str(info.value)
    assert str(path) in text and "'cam0'" in text and 'cameras[0].width' in text
    assert info.value.field == 'cameras[0].width'


def test_good_width_still_loads(tmp_path):
    path = tmp_path / 'rig.yaml'
    path.write_text(PROJECT.format(width=160))
    assert load_rig(path)[0].width == 160


def test_toml_nan_and_inf_sizes(tmp_path):
    path = tmp_path / 'calibration.toml'
    for size in ('[nan, 480]', '[inf, 480]', '[640, 1e400]'):
        path.write_text(f'[cam_1]\nname = "a"\nsize = {size}\n'
                        'matrix = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]\n'
                        'distortions = [0.0, 0.0, 0.0, 0.0]\nrotation = [0.0, 0.0, 0.0]\n'
                        'translation = [0.0, 0.0, 0.0]\n')
        with pytest.raises(RigError, match=r'calibration\.toml.*cam_1\.size'):
            load_rig(path)


def test_yaml_alias_bomb_is_refused_fast(tmp_path):
    """A ~600-byte "billion laughs": nine levels of nine aliases."""
    lines = ['a0: &a0 [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]']
    for i in range(1, 10):
        lines.append(f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 9) + ']')
    lines.append('cameras: [*a9]')
    path = tmp_path / 'bomb.yaml'
    path.write_text('\n'.join(lines) + '\n')
    assert path.stat().st_size < 700
    with peak_allocation() as peak, pytest.raises(RigError, match=r'bomb\.yaml.*alias'):
        load_rig(path)
    assert peak[0] < 16 << 20       # 9**9 expanded floats would be gigabytes


def test_huge_rig_file_is_refused_unread(tmp_path):
    path = tmp_path / 'big.yaml'
    with open(path, 'w') as stream:
        stream.write(PROJECT.format(width=160))
        stream.write(('#' * 1023 + '\n') * (MAX_RIG_BYTES // 1024 + 1))
    with peak_allocation() as peak, pytest.raises(RigError, match=r'big\.yaml.*bytes'):
        load_rig(path)
    assert peak[0] < MAX_RIG_BYTES // 8     # the file is never read into memory


def _write_opencv(path, entries):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in entries.items():
        fs.write(key, value)
    fs.release()


def test_opencv_camera_calibration_sample_names(tmp_path):
    """out_camera_data.xml as OpenCV's camera_calibration sample writes it."""
    path = tmp_path / 'out_camera_data.xml'
    _write_opencv(path, {'calibration_Time': 'Mon Nov  3 10:00:00 2025', 'nrOfFrames': 25,
                         'image_Width': 640, 'image_Height': 480, 'board_Width': 9,
                         'board_Height': 6, 'Camera_Matrix': K,
                         'Distortion_Coefficients': D.reshape(5, 1),
                         'Avg_Reprojection_Error': 0.31})
    cam = load_rig(path)[0]
    np.testing.assert_array_equal(cam.K, K)
    np.testing.assert_array_equal(cam.dist, D)
    assert (cam.width, cam.height) == (640, 480)
    np.testing.assert_array_equal(cam.R, np.eye(3))


def test_opencv_stereo_calib_intrinsics_without_size(tmp_path):
    """stereo_calib's intrinsics.yml (M1 D1 M2 D2, no size) + extrinsics.yml (R T ...)."""
    folder = tmp_path / 'calib'
    folder.mkdir()
    intrinsics = folder / 'intrinsics.yml'
    _write_opencv(intrinsics, {'M1': K, 'D1': D.reshape(1, 5), 'M2': K * [[1.01], [1.0],
                                                                          [1.0]],
                               'D2': D.reshape(1, 5)})
    with pytest.raises(RigError) as info:                    # no size, no extrinsics
        load_rig(intrinsics)
    assert 'image_width' in str(info.value) and 'image_size' in str(info.value)
    with pytest.raises(RigError, match=r'intrinsics\.yml.*extrinsics\.yml'):
        load_rig(intrinsics, image_size=(640, 480))
    R = cv2.Rodrigues(np.array([0.0, 0.1, 0.0]))[0]
    T = np.array([[-0.12], [0.0], [0.001]])
    _write_opencv(folder / 'extrinsics.yml', {'R': R, 'T': T, 'R1': np.eye(3)})
    left, right = load_rig(intrinsics, image_size=(640, 480))
    assert (left.width, left.height) == (right.width, right.height) == (640, 480)
    np.testing.assert_array_equal(left.R, np.eye(3))
    np.testing.assert_allclose(right.R, R)
    np.testing.assert_allclose(right.t, T.ravel())
    np.testing.assert_allclose(right.K, K * [[1.01], [1.0], [1.0]])


def test_unknown_opencv_names_list_the_accepted_ones(tmp_path):
    path = tmp_path / 'cam.xml'
    _write_opencv(path, {'intrinsic': K, 'image_Width': 640, 'image_Height': 480})
    with pytest.raises(RigError) as info:
        load_rig(path)
    assert 'camera_matrix' in str(info.value) and 'cameraMatrix' in str(info.value)


XML_MATRIX = """<?xml version="1.0"?>
<opencv_storage>
<image_width>640</image_width>
<image_height>480</image_height>
<camera_matrix type_id="opencv-matrix">
  <rows>{rows}</rows>
  <cols>{cols}</cols>
  <dt>d</dt>
  <data>
    658.2 0. 319.4 0. 657.9 241.1 0. 0. 1.</data></camera_matrix>
</opencv_storage>
"""


@pytest.mark.parametrize('rows, cols', [(4, 4), (3, 2), (100000, 100000), (-1, 3)])
def test_opencv_xml_whose_rows_cols_lie(tmp_path, rows, cols):
    path = tmp_path / 'cam.xml'
    path.write_text(XML_MATRIX.format(rows=rows, cols=cols))
    with pytest.raises(RigError, match=r'cam\.xml'):
        load_rig(path)


@pytest.mark.parametrize('fraction', [0.3, 0.6, 0.9])
def test_truncated_opencv_xml(tmp_path, fraction):
    text = XML_MATRIX.format(rows=3, cols=3)
    path = tmp_path / 'cam.xml'
    path.write_text(text[:int(len(text) * fraction)])
    with pytest.raises(RigError, match=r'cam\.xml'):
        load_rig(path)


def test_round_trip_unchanged(tmp_path):
    cams = load_rig(_sample(tmp_path))
    save_rig(tmp_path / 'again.yaml', cams)
    assert read_rig(tmp_path / 'again.yaml')[0] == cams


def _sample(tmp_path):
    path = tmp_path / 'sample.yaml'
    path.write_text(PROJECT.format(width=160))
    return path


TOKENS = ['true', 'null', '.nan', '.inf', '-1', '0', '1e400', '"x"', '[]', '{}', '[1, 2]',
          '[[1, 0, 0], [0, 1, 0]]', '&a 3', '*a', '160', '1e-300', "'", '[', '-', '~']


def test_seeded_project_yaml_mutations_are_rig_errors_or_rigs(tmp_path):
    """300 seeded edits of a rig file (a value replaced by an odd token, or the text cut):
    load_rig gives cameras or RigError naming the file - nothing else, never slow."""
    text = PROJECT.format(width=160)
    lines = text.splitlines()
    rng = np.random.default_rng(14)
    path = tmp_path / 'rig.yaml'
    refused = 0
    for _ in range(300):
        if rng.random() < 0.2:
            mutated = text[:int(rng.integers(len(text)))]
        else:
            i = int(rng.integers(1, len(lines)))
            key = lines[i].split(':')[0]
            mutated = '\n'.join(lines[:i] + [f'{key}: {TOKENS[int(rng.integers(len(TOKENS)))]}']
                                + lines[i + 1:])
        path.write_text(mutated)
        with peak_allocation() as peak:
            try:
                cams = load_rig(path)
            except RigError as error:
                assert str(path) in str(error), error
                refused += 1
            else:
                assert all(c.width > 0 and np.isfinite(c.K).all() for c in cams)
        assert peak[0] < 16 << 20, mutated
    assert refused > 150


def test_seeded_opencv_xml_damage_is_rig_error_or_rig(tmp_path):
    text = XML_MATRIX.format(rows=3, cols=3)
    rng = np.random.default_rng(15)
    path = tmp_path / 'cam.xml'
    for _ in range(200):
        data = bytearray(text.encode())
        for _ in range(int(rng.integers(1, 4))):
            data[int(rng.integers(len(data)))] = int(rng.integers(32, 127))
        if rng.random() < 0.3:
            del data[int(rng.integers(len(data))):]
        path.write_bytes(bytes(data))
        try:
            cams = load_rig(path)
        except RigError as error:
            assert str(path) in str(error)
        else:
            assert cams[0].K.shape == (3, 3)


def test_booleans_in_matrices_are_refused(tmp_path):
    path = tmp_path / 'rig.yaml'
    path.write_text(PROJECT.format(width=160).replace('[1, 0, 0]', '[true, 0, 0]'))
    with pytest.raises(RigError, match=r'cameras\[0\]\.R.*cam0.*boolean'):
        load_rig(path)


def test_skeleton_yaml_alias_bomb_is_refused(tmp_path):
    """The same alias-free YAML loader for skeleton files."""
    from monet_ros.skeleton import SkeletonError, load_skeleton
    lines = ['a0: &a0 [x, x, x, x, x, x, x, x, x]']
    lines += [f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 9) + ']' for i in range(1, 10)]
    lines += ['name: bomb', 'keypoints: *a9']
    path = tmp_path / 'bomb.yaml'
    path.write_text('\n'.join(lines) + '\n')
    with pytest.raises(SkeletonError, match=r'bomb\.yaml.*alias'):
        load_skeleton(path)
