"""Inputs other camera drivers produce (issue 14, kind 10): camera_info with binning and a
region of interest, rational_polynomial with 5 coefficients (one rule for YAML files and
recorded/live camera_info), absurd intrinsics (K = 1e300), 16-bit images for the detector.
"""
import cv2
from helpers.io_bags import make_camera
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo, RegionOfInterest

from monet_ros.geometry import load_rig
from monet_ros.io import convert
from monet_ros.io.images import ImageDecodeError, to_rgb8


def _info(cam, **fields):
    msg = convert.camera_info_from_camera(cam, 1, 'c')
    for key, value in fields.items():
        setattr(msg, key, value)
    return msg


def _cv2_project(cam, X):
    rvec = cv2.Rodrigues(cam.R)[0]
    return cv2.projectPoints(X, rvec, cam.t, cam.K, cam.dist)[0].reshape(-1, 2)


@pytest.mark.parametrize('bx, by', [(2, 2), (4, 2)])
def test_binning_scales_K_and_size(bx, by):
    """A driver publishing binned images keeps the full-resolution K in camera_info; the
    camera of its images is K / binning (as ROS image_geometry), size / binning."""
    cam = make_camera(size=(640, 480))
    binned = convert.camera_from_camera_info(_info(cam, binning_x=bx, binning_y=by), 'c',
                                             cam.R, cam.t)
    assert (binned.width, binned.height) == (640 // bx, 480 // by)
    X = np.random.default_rng(0).normal(size=(30, 3)) * 0.3 + cam.center + 3 * cam.R[2]
    full = _cv2_project(cam, X)           # OpenCV, full-resolution pixels
    np.testing.assert_allclose(binned.project(X), full / [bx, by], atol=1e-9)
    # binning 0 or 1 = none (the message default)
    same = convert.camera_from_camera_info(_info(cam, binning_x=0, binning_y=1), 'c')
    np.testing.assert_array_equal(same.K, cam.K)


def test_roi_then_binning():
    cam = make_camera(size=(640, 480))
    roi = RegionOfInterest(x_offset=100, y_offset=60, width=320, height=240)
    got = convert.camera_from_camera_info(_info(cam, roi=roi, binning_x=2, binning_y=2), 'c',
                                          cam.R, cam.t)
    assert (got.width, got.height) == (160, 120)
    X = np.random.default_rng(1).normal(size=(20, 3)) * 0.2 + cam.center + 3 * cam.R[2]
    expected = (_cv2_project(cam, X) - [100, 60]) / 2
    np.testing.assert_allclose(got.project(X), expected, atol=1e-9)


def test_rational_polynomial_5_coefficients_one_rule(tmp_path):
    """Accepted alike from a camera_info YAML file and from a CameraInfo message (bag or
    live), with the same coefficients."""
    d5 = [0.1, -0.05, 0.001, 0.002, 0.01]
    cam = make_camera(dist=d5)
    msg = _info(cam, distortion_model='rational_polynomial', d=d5)
    from_msg = convert.camera_from_camera_info(msg, 'cam0')
    path = tmp_path / 'cam0.yaml'
    K = cam.K.ravel().tolist()
    path.write_text(
        'image_width: 640\nimage_height: 480\ncamera_name: cam0\n'
        f'camera_matrix: {{rows: 3, cols: 3, data: {K}}}\n'
        'distortion_model: rational_polynomial\n'
        f'distortion_coefficients: {{rows: 1, cols: 5, data: {d5}}}\n')
    from_yaml = load_rig(path)[0]
    np.testing.assert_array_equal(from_msg.dist, d5)
    np.testing.assert_array_equal(from_yaml.dist, from_msg.dist)
    # the same refusals on both paths
    for model, d in (('equidistant', [0.1, 0, 0, 0]), ('plumb_bob', [0.1, 0.2, 0.3])):
        with pytest.raises(ValueError, match='cam0.*' + model):
            convert.camera_from_camera_info(_info(cam, distortion_model=model, d=d), 'cam0')
        text = path.read_text().replace('rational_polynomial', model).replace(
            f'cols: 5, data: {d5}', f'cols: {len(d)}, data: {d}')
        path.write_text(text)
        with pytest.raises(ValueError, match=r'cam0\.yaml.*distortion'):
            load_rig(path)
        path.write_text(text.replace(model, 'rational_polynomial').replace(
            f'cols: {len(d)}, data: {d}', f'cols: 5, data: {d5}'))


@pytest.mark.parametrize('value', [1e300, float('inf'), float('nan')])
def test_absurd_intrinsics_are_refused(value):
    cam = make_camera()
    k = list(cam.K.ravel())
    k[0] = value
    with pytest.raises(ValueError, match='c7.*K'):
        convert.camera_from_camera_info(_info(cam, k=k), 'c7')


def test_16bit_images_to_network_rgb8():
    """mono16 / 16UC1 (e.g. a 12-bit sensor in a 16-bit container) stretched min..max to
    0..255, checked against OpenCV's NORM_MINMAX; 8-bit images pass unchanged."""
    rng = np.random.default_rng(0)
    raw = rng.integers(200, 4096, (48, 64), dtype=np.uint16)
    for encoding in ('mono16', '16UC1'):
        msg = convert.numpy_to_image_msg(raw, 5, 'c', encoding=encoding)
        got = to_rgb8(convert.image_to_numpy(msg))
        want = cv2.normalize(raw.astype(np.float32), None, 0, 255, cv2.NORM_MINMAX)
        assert got.shape == (48, 64, 3) and got.dtype == np.uint8
        assert np.abs(got[..., 0].astype(int) - np.round(want)).max() <= 1
        assert (got[..., 0] == got[..., 2]).all()
    rgb = rng.integers(0, 256, (8, 9, 3), dtype=np.uint8)
    assert to_rgb8(rgb) is rgb or np.array_equal(to_rgb8(rgb), rgb)
    flat = np.full((4, 4), 700, np.uint16)          # no contrast: black, not NaN
    assert (to_rgb8(flat) == 0).all()
    with pytest.raises(ImageDecodeError):
        to_rgb8(np.zeros((4, 4, 2), np.uint8))
    with pytest.raises(ImageDecodeError):
        to_rgb8(np.zeros((0, 0), np.uint16))


def test_binned_camera_info_message_type_is_real():
    assert hasattr(CameraInfo(), 'binning_x') and hasattr(CameraInfo(), 'roi')


def test_stereo_calib_file_takes_the_size_of_the_recording(tmp_path):
    """OpenCV stereo_calib's intrinsics.yml (M1 D1 M2 D2, no image size) used as the rig of
    a recording: the size comes from the recording's images."""
    from monet_ros.geometry import RigError
    from monet_ros.io import BagWriter, rig_from_bag

    folder = tmp_path / 'calib'
    folder.mkdir()
    K = np.array([[80.0, 0, 32], [0, 80.0, 24], [0, 0, 1]])
    for name, entries in (('intrinsics.yml', {'M1': K, 'D1': np.zeros((1, 5)), 'M2': K,
                                              'D2': np.zeros((1, 5))}),
                          ('extrinsics.yml', {'R': np.eye(3), 'T': np.array([-0.1, 0, 0])})):
        fs = cv2.FileStorage(str(folder / name), cv2.FILE_STORAGE_WRITE)
        for key, value in entries.items():
            fs.write(key, value)
        fs.release()
    image = np.zeros((48, 64, 3), np.uint8)
    with BagWriter(tmp_path / 'rec') as bag:
        for cam in ('cam1', 'cam2'):
            bag.write_image(f'/{cam}/image_raw', 1000, image, cam)
    cams = rig_from_bag(tmp_path / 'rec', rig_file=folder / 'intrinsics.yml')
    assert [(c.name, c.width, c.height) for c in cams] == [('cam1', 64, 48), ('cam2', 64, 48)]
    with BagWriter(tmp_path / 'mixed') as bag:       # sizes differ: no size to take
        bag.write_image('/cam1/image_raw', 1000, image, 'cam1')
        bag.write_image('/cam2/image_raw', 1000, image[:24], 'cam2')
    with pytest.raises(RigError, match='intrinsics.yml.*image_width.*recording'):
        rig_from_bag(tmp_path / 'mixed', rig_file=folder / 'intrinsics.yml')


def test_split_stamp_signed_seconds():
    from monet_ros.io.fields import split_stamp
    assert split_stamp(-1_000_000_000) == (-1, 0)
    assert split_stamp(-1) == (-1, 999_999_999)
    assert split_stamp(1_700_000_000_123_456_789) == (1_700_000_000, 123_456_789)
    with pytest.raises(ValueError, match='int32'):
        split_stamp(2**31 * 1_000_000_000)
