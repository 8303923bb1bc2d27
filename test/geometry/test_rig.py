"""Rig files: every supported format loads, save/load is exact, bad files name file+field."""
import re
import tomllib

import cv2
from helpers.rigs import random_camera
import numpy as np
import pytest

from monet_ros.geometry import Camera, RigError, load_rig, read_rig, save_rig

CAMERA_INFO_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [414.2, 0, 319.5, 0, 413.9, 239.5, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.0531, 0.0981, 0.0012, -0.0021, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [414.2, 0, 319.5, 0, 0, 413.9, 239.5, 0, 0, 0, 1, 0]
"""


def test_example_rig_loads(repo_root):
    cameras, frame_id = read_rig(repo_root / 'config' / 'rigs' / 'example.yaml')
    assert frame_id == 'world'
    assert [c.name for c in cameras] == ['cam0', 'cam1']
    assert cameras[0].topic == '/cam0/image_raw'
    assert (cameras[0].width, cameras[0].height) == (1280, 960)
    # both cameras look at the origin from 3.67 m
    for cam in cameras:
        np.testing.assert_allclose(np.linalg.norm(cam.center), 3.6742346142, atol=1e-9)
        np.testing.assert_allclose(cam.project(np.zeros((1, 3)))[0], cam.K[:2, 2], atol=1e-6)


def test_save_load_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    cams = [random_camera(rng, name='left cam', dist_len=12, skew=0.123456789),
            random_camera(rng, name='c1', dist_len=0),
            random_camera(rng, name='c2', dist_len=4)]
    # awkward floats: tiny, huge, negative zero-ish
    cams[1] = cams[1].replace(t=np.array([1e-300, -2.5e-17, 123456789.123456789]),
                              topic='/c1/image_raw')
    path = tmp_path / 'rig.yaml'
    save_rig(path, cams, frame_id='mocap')
    loaded, frame_id = read_rig(path)
    assert frame_id == 'mocap'
    assert loaded == cams
    for a, b in zip(loaded, cams):
        for key in ('K', 'dist', 'R', 't'):
            assert np.array_equal(getattr(a, key), getattr(b, key)), key
    # and saving again gives the same bytes
    path2 = tmp_path / 'rig2.yaml'
    save_rig(path2, loaded, frame_id='mocap')
    assert path.read_bytes() == path2.read_bytes()


def _toml_reference(path):
    """Independent reading: sections sorted by their integer suffix."""
    data = tomllib.loads(path.read_text())
    keys = sorted((k for k in data if k != 'metadata'), key=lambda k: int(k.split('_')[1]))
    return [data[k] for k in keys], [k for k in data if k != 'metadata']


@pytest.mark.parametrize('rel, count', [
    ('aniposelib_testdata/7cam-allen-mouse/calibration.toml', 7),
    ('aniposelib_testdata/12cam-allen-mouse/calibration.toml', 12),
    ('aniposelib_testdata/calib_motobs_7cam.toml', 7),
    ('aniposelib_testdata/mouse-outdoor/calibration_right_4_10_2026_adjusted.toml', 12)])
def test_anipose_toml_numeric_order(shared_data, rel, count):
    path = shared_data / rel
    cams = load_rig(path)
    sections, _ = _toml_reference(path)
    assert len(cams) == count
    assert [c.name for c in cams] == [s['name'] for s in sections]
    for cam, s in zip(cams, sections):
        np.testing.assert_array_equal(cam.K, np.array(s['matrix'], float))
        np.testing.assert_array_equal(cam.dist, np.array(s['distortions'], float))
        np.testing.assert_allclose(cam.R, cv2.Rodrigues(np.array(s['rotation'], float))[0],
                                   atol=1e-15)
        np.testing.assert_array_equal(cam.t, np.array(s['translation'], float))
        assert (cam.width, cam.height) == tuple(int(v) for v in s['size'])
    if count >= 10:  # cam_10 comes after cam_9 (a string sort would put it after cam_1)
        string_order = sorted(f'cam_{i}' for i in range(count))
        assert string_order[2] == 'cam_10'
        assert cams[10].name == sections[10]['name'] != sections[2]['name']


def test_pose2sim_toml_size_is_width_height(shared_data):
    cams = load_rig(shared_data / 'pose2sim_demo_balancing/S00_Calibration/Calib_qualisys.toml')
    assert [c.name for c in cams] == ['cam_01', 'cam_02', 'cam_03', 'cam_04']
    assert all((c.width, c.height) == (1088, 1920) for c in cams)
    # portrait images: principal point near the middle of a 1088 x 1920 image
    assert all(abs(c.K[0, 2] - 544) < 40 and abs(c.K[1, 2] - 960) < 40 for c in cams)


def test_camera_info_yaml(tmp_path):
    path = tmp_path / 'narrow.yaml'
    path.write_text(CAMERA_INFO_YAML)
    (cam,) = load_rig(path)
    assert cam.name == 'narrow_stereo' and (cam.width, cam.height) == (640, 480)
    np.testing.assert_array_equal(cam.K, [[414.2, 0, 319.5], [0, 413.9, 239.5], [0, 0, 1]])
    np.testing.assert_array_equal(cam.dist, [-0.0531, 0.0981, 0.0012, -0.0021, 0])
    np.testing.assert_array_equal(cam.R, np.eye(3))
    np.testing.assert_array_equal(cam.t, np.zeros(3))
    path.write_text(CAMERA_INFO_YAML.replace('plumb_bob', 'equidistant'))
    with pytest.raises(RigError, match='distortion_model'):
        load_rig(path)


def test_opencv_filestorage_single_and_stereo(tmp_path):
    rng = np.random.default_rng(3)
    ref = random_camera(rng, name='calib', dist_len=5)
    for suffix in ('.yaml', '.xml'):
        path = tmp_path / f'calib{suffix}'
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write('image_width', ref.width)
        fs.write('image_height', ref.height)
        fs.write('camera_matrix', ref.K)
        fs.write('distortion_coefficients', ref.dist.reshape(5, 1))
        fs.release()
        (cam,) = load_rig(path)
        assert cam.name == 'calib' and (cam.width, cam.height) == (ref.width, ref.height)
        np.testing.assert_array_equal(cam.K, ref.K)
        np.testing.assert_array_equal(cam.dist, ref.dist)
        np.testing.assert_array_equal(cam.R, np.eye(3))
    other = random_camera(rng, dist_len=5)
    R_ij = other.R @ ref.R.T
    T_ij = other.t - R_ij @ ref.t
    path = tmp_path / 'stereo.yml'
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in (('M1', ref.K), ('D1', ref.dist), ('M2', other.K), ('D2', other.dist),
                       ('R', R_ij), ('T', T_ij.reshape(3, 1))):
        fs.write(key, value)
    fs.write('image_size', np.array([[1280.0, 960.0]]))
    fs.release()
    a, b = load_rig(path)
    np.testing.assert_array_equal(b.K, other.K)
    np.testing.assert_allclose(b.R, R_ij, atol=1e-15)
    assert (b.width, b.height) == (1280, 960)


def test_dannce_mat_conventions(shared_data):
    import scipy.io
    path = shared_data / 'dannce_markerless_mouse_1' / 'label3d_dannce.mat'
    with pytest.warns(UserWarning, match='image size'):
        cams = load_rig(path)
    cams = load_rig(path, image_size=(1152, 1024))
    assert [c.name for c in cams] == [f'Camera{i}' for i in range(1, 7)]
    mat = scipy.io.loadmat(str(path))
    p0 = mat['params'][0, 0]
    K_mat = p0['K'][0, 0]
    assert cams[0].K[0, 1] == K_mat[1, 0] != 0  # skew moved to the upper triangle
    np.testing.assert_array_equal(cams[0].R, p0['r'][0, 0].T)
    np.testing.assert_array_equal(cams[0].dist[[0, 1, 4]], p0['RDistort'][0, 0].ravel())
    np.testing.assert_array_equal(cams[0].dist[[2, 3]], p0['TDistort'][0, 0].ravel())
    # the labels: data_2d is the distorted projection of data_3d (MATLAB conventions)
    for v, cam in enumerate(cams):
        labels = mat['labelData'][v, 0]
        X = labels['data_3d'][0, 0].reshape(-1, 3)
        uv = labels['data_2d'][0, 0].reshape(-1, 2)
        ok = np.isfinite(X).all(1) & np.isfinite(uv).all(1)
        assert ok.sum() > 1000
        assert np.abs(cam.project(X[ok]) - uv[ok]).max() < 1e-6


VALID = """frame_id: world
cameras:
  - name: a
    width: 640
    height: 480
    K: [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
    D: [0.0, 0.0, 0.0, 0.0, 0.0]
    R: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    t: [0.0, 0.0, 2.0]
"""


@pytest.mark.parametrize('old, new, field', [
    ('    t: [0.0, 0.0, 2.0]\n', '', 'cameras[0].t'),
    ('    width: 640\n', '', 'cameras[0].width'),
    ('K: [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]',
     'K: [[500.0, 0.0], [0.0, 500.0]]', 'cameras[0].K'),
    ('R: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]',
     'R: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]]', 'cameras[0].R'),
    ('K: [[500.0,', 'K: [[-500.0,', 'cameras[0].K'),
    ('D: [0.0, 0.0, 0.0, 0.0, 0.0]', 'D: [0.0, 0.0, 0.0]', 'cameras[0].D'),
    ('frame_id: world', 'frame_id: 7', 'frame_id'),
    ('  - name: a\n', '  - name: a\n    focal: 3\n', 'cameras[0].focal'),
])
def test_bad_project_rig_names_file_and_field(tmp_path, old, new, field):
    assert old in VALID
    path = tmp_path / 'bad.yaml'
    path.write_text(VALID.replace(old, new))
    with pytest.raises(RigError) as info:
        load_rig(path)
    assert info.value.field == field
    assert str(path) in str(info.value) and repr(field) in str(info.value)


def test_bad_toml_names_section_field(shared_data, tmp_path):
    text = (shared_data / 'aniposelib_testdata/7cam-allen-mouse/calibration.toml').read_text()
    cases = [
        (re.sub(r'translation = \[[^\]]*\]\n', '', text, count=1), 'cam_0.translation'),
        (text.replace('size = [ 1440, 1080,]', 'size = [ 1440,]', 1), 'cam_0.size'),
        (re.sub(r'rotation = \[[^\]]*\]', 'rotation = [ 1.0, 2.0,]', text, count=1),
         'cam_0.rotation'),
        (re.sub(r'matrix = \[ \[ ', 'matrix = [ [ -', text, count=1), 'cam_0.matrix'),
    ]
    for k, (bad, field) in enumerate(cases):
        assert bad != text
        path = tmp_path / f'bad{k}.toml'
        path.write_text(bad)
        with pytest.raises(RigError) as info:
            load_rig(path)
        assert info.value.field == field, str(info.value)
        assert str(path) in str(info.value)


def test_unknown_and_unreadable_files(tmp_path):
    cases = {'rig.json': '{"cameras": []}', 'weird.yaml': 'just: text\n',
             'binary.yaml': None, 'broken.toml': '[cam_0\nname = ', 'notmat.mat': 'hello'}
    for name, content in cases.items():
        path = tmp_path / name
        if content is None:
            path.write_bytes(bytes(range(256)) * 4)
        else:
            path.write_text(content)
        with pytest.raises(RigError) as info:
            load_rig(path)
        assert str(path) in str(info.value)
    with pytest.raises(RigError, match='no such file'):
        load_rig(tmp_path / 'missing.yaml')
    with pytest.raises(RigError, match='not a file'):
        load_rig(tmp_path)
    with pytest.raises(RigError, match='unknown rig format'):
        load_rig(tmp_path / 'rig.json')


def test_rig_cameras_are_cameras(repo_root):
    assert all(isinstance(c, Camera) for c in load_rig(repo_root / 'config/rigs/example.yaml'))
