"""rclpy message conversions: Image, CameraInfo, heatmaps (32FC<C>), keypoint PointCloud2,
markers; checked against rclpy's own CDR round trip and independent byte parsing."""
import struct

from helpers.io_bags import make_camera
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from visualization_msgs.msg import MarkerArray

from monet_ros.crop_rule import TrackedCrops
from monet_ros.geometry.units import rescale
from monet_ros.io import BagWriter, convert, open_bag, rig_from_bag
from monet_ros.io.fields import (
    camera_pose_transform,
    extrinsics_from_pose,
    matrix_to_quaternion,
    quaternion_to_matrix,
)
from monet_ros.io.markers import frustum_marker_specs


def test_image_msg_round_trip_through_rclpy_cdr():
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, (30, 41, 3), dtype=np.uint8)
    msg = convert.numpy_to_image_msg(rgb, 1_700_000_000_123_456_789, 'cam0_optical')
    back = deserialize_message(serialize_message(msg), Image)
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert convert.header_stamp_ns(back) == 1_700_000_000_123_456_789
    assert back.header.frame_id == 'cam0_optical' and back.step == 41 * 3
    np.testing.assert_array_equal(convert.image_to_numpy(back), rgb)
    bgr = convert.numpy_to_image_msg(rgb, 5, 'f', encoding='bgr8')
    np.testing.assert_array_equal(np.frombuffer(bgr.data, np.uint8).reshape(rgb.shape),
                                  rgb[:, :, ::-1])
    comp = convert.compressed_image_msg(rgb, 5, 'f', fmt='png')
    np.testing.assert_array_equal(convert.compressed_image_to_numpy(comp), rgb)


def test_camera_info_round_trip():
    cam = make_camera()
    msg = convert.camera_info_from_camera(cam, 42, 'cam0_optical')
    back = deserialize_message(serialize_message(msg), CameraInfo)
    assert back.distortion_model == 'plumb_bob' and len(back.d) == 5
    np.testing.assert_array_equal(np.asarray(back.p).reshape(3, 4)[:, :3], cam.K)
    got = convert.camera_from_camera_info(back, 'cam0', cam.R, cam.t)
    np.testing.assert_array_equal(got.K, cam.K)
    np.testing.assert_array_equal(got.dist, cam.dist)
    assert (got.width, got.height) == (640, 480)
    X = np.random.default_rng(2).normal(size=(20, 3)) + cam.center + 3 * cam.R[2]
    np.testing.assert_allclose(got.project(X), cam.project(X), atol=1e-9)
    # 8-coefficient model
    cam8 = make_camera(dist=(0.1, -0.05, 0.001, 0.002, 0.01, 0.02, 0.0, 0.001))
    msg8 = convert.camera_info_from_camera(cam8, 1, 'c')
    assert msg8.distortion_model == 'rational_polynomial'
    np.testing.assert_array_equal(convert.camera_from_camera_info(msg8, 'c').dist, cam8.dist)


def test_camera_info_unsupported_model_is_named():
    msg = convert.camera_info_from_camera(make_camera(), 1, 'c')
    msg.distortion_model = 'equidistant'
    msg.d = [0.1, 0.0, 0.0, 0.0]
    try:
        convert.camera_from_camera_info(msg, 'cam7')
    except ValueError as exc:
        assert 'cam7' in str(exc) and 'equidistant' in str(exc)
    else:
        raise AssertionError('equidistant accepted')


def test_heatmaps_32fc_round_trip_and_layout():
    rng = np.random.default_rng(3)
    heat = rng.random((14, 46, 40), dtype=np.float32)
    msg = convert.heatmaps_to_image_msg(heat, 7, 'cam0_heat')
    back = deserialize_message(serialize_message(msg), Image)
    assert back.encoding == '32FC14' and (back.height, back.width) == (46, 40)
    assert back.step == 40 * 14 * 4
    # channel-interleaved: pixel (v=5, u=7), channel 3 at byte ((5*40+7)*14+3)*4
    off = ((5 * 40 + 7) * 14 + 3) * 4
    assert struct.unpack_from('<f', bytes(back.data), off)[0] == heat[3, 5, 7]
    np.testing.assert_array_equal(convert.image_msg_to_heatmaps(back), heat)
    # the detector's heatmaps are channel-interleaved in memory (Detector.forward): the same
    # message
    interleaved = np.ascontiguousarray(np.moveaxis(heat, 0, -1))
    view = np.moveaxis(interleaved, -1, 0)
    assert not view.flags['C_CONTIGUOUS']
    again = convert.heatmaps_to_image_msg(view, 7, 'cam0_heat')
    assert bytes(again.data) == bytes(msg.data)


def test_keypoint_cloud_layout_and_round_trip():
    rng = np.random.default_rng(4)
    X = rng.normal(size=(14, 3))
    X[3] = np.nan
    conf = rng.random(14)
    err = rng.random(14) * 5
    nv = rng.integers(0, 8, 14)
    msg = convert.keypoints3d_to_cloud(9, 'world', X, conf, err, nv, units='m')
    back = deserialize_message(serialize_message(msg), PointCloud2)
    assert [f.name for f in back.fields] == ['x', 'y', 'z', 'confidence',
                                             'reprojection_error', 'num_views', 'keypoint']
    assert [f.offset for f in back.fields] == [0, 4, 8, 12, 16, 20, 24]
    assert [f.datatype for f in back.fields] == [7, 7, 7, 7, 7, 6, 6]
    assert back.point_step == 28 and back.row_step == 28 * 14 and back.width == 14
    assert not back.is_dense
    raw = bytes(back.data)
    x, y, z, c, e, n, k = struct.unpack_from('<5f2I', raw, 28 * 5)   # independent parse
    np.testing.assert_allclose([x, y, z, c, e], [*X[5], conf[5], err[5]], rtol=1e-6)
    assert (n, k) == (nv[5], 5)
    d = convert.cloud_to_keypoints3d(back, units='m')
    np.testing.assert_allclose(d['X'], X.astype(np.float32), rtol=0, equal_nan=True)
    assert np.isnan(d['X'][3]).all()
    np.testing.assert_allclose(d['confidence'], conf.astype(np.float32))
    np.testing.assert_array_equal(d['num_views'], nv)
    np.testing.assert_array_equal(d['keypoint'], np.arange(14))


def test_quaternions_and_tf_extrinsics():
    rng = np.random.default_rng(5)
    for _ in range(50):
        R = Rotation.from_rotvec(rng.normal(size=3) * 2).as_matrix()
        q = matrix_to_quaternion(R)
        ref = Rotation.from_matrix(R).as_quat()            # scipy: (x, y, z, w)
        assert min(np.abs(q - ref).max(), np.abs(q + ref).max()) < 1e-12
        np.testing.assert_allclose(quaternion_to_matrix(*q), R, atol=1e-12)
    cam = make_camera(seed=7)
    trans, quat = camera_pose_transform(cam)
    np.testing.assert_allclose(trans, cam.center, atol=1e-12)
    R, t = extrinsics_from_pose(trans, quat)
    np.testing.assert_allclose(R, cam.R, atol=1e-12)
    np.testing.assert_allclose(t, cam.t, atol=1e-12)


def test_skeleton_markers():
    X = np.array([[0, 0, 0], [1, 0, 0], [np.nan, 0, 0], [0, 1, 0]], float)
    bones = [[0, 1], [1, 2], [0, 3]]
    arr = convert.skeleton_marker_array(3, 'world', X, bones, units='m')
    back = deserialize_message(serialize_message(arr), MarkerArray)
    joints, lines = back.markers
    assert joints.type == joints.SPHERE_LIST and len(joints.points) == 3
    assert lines.type == lines.LINE_LIST and len(lines.points) == 4   # bone 1-2 dropped
    assert (lines.points[3].x, lines.points[3].y) == (0.0, 1.0)


def test_messages_are_in_metres_whatever_the_rig_unit(tmp_path):
    # REP 103: keypoints in a mm rig go out in m and come back in the reader's unit
    rng = np.random.default_rng(8)
    X_m = rng.uniform(-2, 2, size=(5, 3))
    X_m[2] = np.nan
    X_mm = X_m * 1000.0
    msg = deserialize_message(serialize_message(convert.keypoints3d_to_cloud(
        9, 'world', X_mm, reprojection_error=np.full(5, 3.5), units='mm')), PointCloud2)
    raw = np.frombuffer(bytes(msg.data), np.float32).reshape(5, 7)   # independent parse
    np.testing.assert_array_equal(raw[:, :3], X_m.astype(np.float32))
    np.testing.assert_array_equal(raw[:, 4], 3.5)                   # px, not converted
    on_topic = X_m.astype(np.float32).astype(np.float64)
    np.testing.assert_allclose(convert.cloud_to_keypoints3d(msg, units='m')['X'], on_topic,
                               rtol=0, atol=0)
    back_mm = convert.cloud_to_keypoints3d(msg, units='mm')['X']
    np.testing.assert_allclose(back_mm, on_topic * 1000.0, rtol=1e-15)
    np.testing.assert_allclose(convert.cloud_to_keypoints3d(msg, units='cm')['X'],
                               on_topic * 100.0, rtol=1e-15)
    # the crop rule (offline: fed the rig-unit fusion) keeps the very numbers a subscriber
    # reads, and keeps what it read as it is
    for X, units, read in ((X_mm, 'mm', back_mm), (X_m, 'm', on_topic)):
        tracker = TrackedCrops(units=units)
        tracker.update(X)
        np.testing.assert_array_equal(tracker.X, read)
        tracker.update(read)
        np.testing.assert_array_equal(tracker.X, read)
    # skeleton markers: m, the joint size in m
    bones = [[0, 1], [3, 4]]
    joints = convert.skeleton_marker_array(3, 'world', X_mm, bones, units='mm').markers[0]
    pts = np.array([[p.x, p.y, p.z] for p in joints.points])
    np.testing.assert_allclose(pts, X_m[[0, 1, 3, 4]], rtol=1e-12)
    assert joints.scale.x == 0.03
    # TF and camera frustums of a mm camera: metres, equal to those of the m camera
    cam_m = make_camera(seed=9)
    cam_mm = rescale([cam_m], 'mm')[0]
    assert cam_mm.units == 'mm' and np.allclose(cam_mm.t, cam_m.t * 1000.0)
    trans, quat = camera_pose_transform(cam_mm)
    np.testing.assert_allclose(trans, cam_m.center, rtol=1e-12)
    for a, b in zip(frustum_marker_specs([cam_mm], 0.3), frustum_marker_specs([cam_m], 0.3)):
        np.testing.assert_allclose(a['points'], b['points'], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(a.get('position', 0), b.get('position', 0), atol=1e-12)
    # the MCAP writer: the same metres; a rig read back from its /tf_static is that in m
    with BagWriter(tmp_path / 'b') as bag:
        bag.write_tf_static(5, [cam_mm])
        bag.write_camera_info('/cam0/camera_info', 5, cam_mm, 'cam0_optical')
        bag.write_keypoints3d('/monet/keypoints3d', 5, 'world', X_mm, units='mm')
        bag.write_skeleton_markers('/monet/skeleton', 5, 'world', X_mm, bones, units='mm')
    got = {m.topic: m.msg for m in open_bag(tmp_path / 'b').messages()}
    np.testing.assert_allclose(convert.cloud_to_keypoints3d(
        got['/monet/keypoints3d'], units='m')['X'], on_topic, rtol=0, atol=0)
    pts = np.array([[p.x, p.y, p.z] for p in got['/monet/skeleton'].markers[0].points])
    np.testing.assert_allclose(pts, X_m[[0, 1, 3, 4]], rtol=1e-12)
    (back,) = rig_from_bag(tmp_path / 'b', units='m')
    np.testing.assert_allclose(back.center, cam_m.center, atol=1e-9)


def test_io_package_import_does_not_import_rclpy():
    """monet_ros.io (BagWriter, pure-numpy conversions) imports without rclpy."""
    import subprocess
    import sys
    code = ('import sys, monet_ros.io, monet_ros.io.writer, monet_ros.io.fields; '
            'assert "rclpy" not in sys.modules, "rclpy imported"')
    subprocess.run([sys.executable, '-c', code], check=True)
