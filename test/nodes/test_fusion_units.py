"""The fusion executable with a rig in mm (an anipose TOML that states no unit, the
`rig_units` parameter saying mm): fusion and the live filter run in mm (the filter's mm /
m/s^2 settings converted: nothing gated on a still subject, as in metres), but every topic
is in metres (ROS REP 103): keypoints3d and keypoints3d_raw are the mm triangulation / 1000
(checked against the core run in process and against an independent undistort + DLT),
the skeleton and rig markers and /tf_static are in m; /diagnostics states both units. The
filter's numbers are checked in mm, at start and live (a noise usable in metres whose
covariance overflows in mm is refused naming it)."""
import re

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from helpers.fusion_frames import WRONG, Frame, fusion_statuses, publishers, run_frames
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import Marker, MarkerArray

from monet_ros.fusion import fuse_heatmaps
from monet_ros.geometry import save_anipose_toml, save_rig
from monet_ros.geometry.units import rescale
from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns, image_msg_to_heatmaps
from monet_ros.nodes.qos import LATCHED, STREAM_OUT
from monet_ros.nodes.tf import tf_message_class
from monet_ros.temporal.live import LiveFilter, LiveFilterConfig


def dlt(cameras, points):
    """Independent triangulation of one point: undistort each view's pixel with OpenCV,
    then linear least squares on the normalised rows (in the cameras' unit)."""
    rows = []
    for cam, uv in zip(cameras, points):
        x, y = cv2.undistortPoints(np.asarray(uv, np.float64).reshape(1, 1, 2), cam.K,
                                   np.asarray(cam.dist)).reshape(2)
        P = np.hstack([cam.R, np.asarray(cam.t).reshape(3, 1)])
        rows += [x * P[2] - P[0], y * P[2] - P[1]]
    _, _, vt = np.linalg.svd(np.array(rows))
    return vt[-1][:3] / vt[-1][3]


def test_fusion_in_mm_publishes_metres_and_filters_as_in_metres(ros_env, tmp_path):
    rig = rescale(ring_rig(4), 'mm')
    path = tmp_path / 'calibration.toml'
    save_anipose_toml(path, rig)
    path.write_text(re.sub(r'(?m)^units = .*\n', '', path.read_text()))   # anipose's form
    rng = np.random.default_rng(5)
    X = rng.uniform([-300, -300, 600], [300, 300, 1500], size=(14, 3))       # mm
    frames = [Frame(rig, X, i, rng, noise=0.4) for i in range(8)]
    # every frame fused whole, however loaded the machine: no view timeout that a slow
    # process can reach, no stale skip (max_queue_ms 0); run_frames resends until fused
    params = dict(rig=str(path), rig_units='mm', filter=True, timeout_s=60.0,
                  max_queue_ms=0.0, input_reliability='reliable', diagnostics_period_s=0.2)
    TFMessage = tf_message_class()
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, STREAM_OUT)
        raw = ros.collect('/monet/keypoints3d_raw', PointCloud2, STREAM_OUT)
        skeleton = ros.collect('/monet/skeleton', MarkerArray, STREAM_OUT)
        rig_markers = ros.collect('/monet/rig_markers', MarkerArray, LATCHED)
        tf = ros.collect('/tf_static', TFMessage, LATCHED) if TFMessage else [None]
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pubs = publishers(ros, [c.name for c in rig])
        for heat_pub, info_pub in pubs.values():
            ros.wait_for_subscribers(heat_pub, timeout=60, process=node)
            ros.wait_for_subscribers(info_pub, timeout=60, process=node)
        run_frames(ros, node, pubs, frames, clouds)
        stamps = [f.stamp for f in frames]

        def counted():
            status = fusion_statuses(diagnostics).get('monet fusion')
            values = {kv.key: kv.value for kv in status.values} if status else {}
            # a frame resent before its cloud came back may be counted twice
            return values if int(values.get('frames', 0)) >= len(frames) else None
        assert ros.spin_until(lambda: counted() is not None and set(stamps) <= {
            header_stamp_ns(c) for c in raw} and skeleton and rig_markers and tf,
            timeout=30, process=node), node.output()
        values = counted()
        assert node.stop() == 0, node.output()
    assert values['units'] == 'mm' and values['topic_units'] == 'm', values
    assert values['filter_gated'] == '0', values
    raw_m = {header_stamp_ns(c): cloud_to_keypoints3d(c, units='m') for c in raw}
    raw_mm = {header_stamp_ns(c): cloud_to_keypoints3d(c, units='mm') for c in raw}
    filtered_m = {header_stamp_ns(c): cloud_to_keypoints3d(c, units='m') for c in clouds}
    filtered_mm = {header_stamp_ns(c): cloud_to_keypoints3d(c, units='mm') for c in clouds}
    good = [v for v in range(len(rig)) if v != WRONG]
    for frame in frames:
        # the topic is the mm triangulation / 1000: the fusion core on the same messages
        # with the mm rig, in this process
        views = [(image_msg_to_heatmaps(heat), np.asarray(info.k).reshape(3, 3))
                 for _, heat, info in frame.messages]
        core = fuse_heatmaps([h for h, _ in views], np.stack([K for _, K in views]), rig)
        got = raw_m[frame.stamp]
        assert (got['num_views'] == 3).all()
        np.testing.assert_allclose(got['X'], (core.X / 1000.0).astype(np.float32),
                                   rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(got['reprojection_error'], core.reprojection_error,
                                   rtol=1e-4, atol=1e-4)                  # px: as it is
        # ... and an independent triangulation of the good views' peaks, in mm (within
        # the decoding error of a Gaussian on a heatmap cell of ~5 px: a few mm)
        reference = np.array([dlt([rig[v] for v in good],
                                  [frame.centres[rig[v].name][k] for v in good])
                              for k in range(len(X))])
        assert np.abs(core.X - reference).max() < 5.0                     # mm
        assert np.abs(got['X'] - reference / 1000.0).max() < 5e-3         # m
        assert np.abs(got['X'] - X / 1000.0).max() < 0.03                 # m: the subject
    # the node's filter is LiveFilter in mm on the mm raw points, which equals the metre
    # filter on the metre ones; its output goes out in m too
    in_mm = LiveFilter(LiveFilterConfig(filter=True), 'mm')
    in_m = LiveFilter(LiveFilterConfig(filter=True))
    for stamp in stamps:
        expected, _ = in_mm.update(stamp, raw_mm[stamp]['X'])
        metres, _ = in_m.update(stamp, raw_m[stamp]['X'])
        np.testing.assert_allclose(filtered_mm[stamp]['X'], expected, atol=1e-2)
        np.testing.assert_allclose(filtered_m[stamp]['X'], metres, atol=1e-5)
        np.testing.assert_allclose(expected / 1000.0, metres, atol=1e-9)
    assert in_mm.gated == in_m.gated == 0
    # markers in m: the joints of a fused frame, the frustums from the camera centres
    by_stamp = {header_stamp_ns(a.markers[0]): a for a in skeleton if a.markers}
    for stamp, cloud in filtered_m.items():
        if stamp in by_stamp:
            joints = by_stamp[stamp].markers[0]
            assert joints.type == Marker.SPHERE_LIST and joints.scale.x == 0.03
            pts = np.array([[p.x, p.y, p.z] for p in joints.points])
            np.testing.assert_allclose(pts, cloud['X'][np.isfinite(cloud['X']).all(1)],
                                       atol=1e-6)
    assert set(by_stamp) & set(filtered_m)
    frustums = [m for m in rig_markers[-1].markers if m.type == Marker.LINE_LIST]
    for cam, m in zip(rig, frustums):
        np.testing.assert_allclose([m.points[0].x, m.points[0].y, m.points[0].z],
                                   cam.center / 1000.0, atol=1e-9)
    if TFMessage is not None:
        transforms = {t.child_frame_id: t.transform.translation for t in tf[0].transforms}
        for cam in rig:
            p = transforms[f'{cam.name}_optical']
            np.testing.assert_allclose([p.x, p.y, p.z], cam.center / 1000.0, atol=1e-9)


def test_the_filter_is_checked_in_the_rig_unit_at_start_and_live(ros_env, tmp_path):
    # 1e146 mm: a restart covariance of 2e286 m^2 / 1e-18 s^2 in metres, inf in mm
    path = tmp_path / 'rig.yaml'
    save_rig(path, rescale(ring_rig(2), 'mm'))
    params = dict(rig=str(path), filter=True)
    with NodeProcess('fusion', ros_env, {**params, 'filter_noise_mm': 1e146}) as node:
        assert node.wait(timeout=120) == 2, node.output()
    lines = [line for line in node.stderr_path.read_text().splitlines() if line.strip()]
    assert lines == ["fusion: error: parameter 'filter_noise_mm': 1e+146 mm gives a "
                     'non-finite restart covariance in mm'], node.output()
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        def set_noise(value):
            request = SetParameters.Request(parameters=[Parameter(
                name='filter_noise_mm', value=ParameterValue(
                    type=ParameterType.PARAMETER_DOUBLE, double_value=value))])
            return ros.call(SetParameters, '/monet/fusion/set_parameters', request,
                            node).results[0]
        refused = set_noise(1e146)
        accepted = set_noise(1e5)
        assert node.stop() == 0, node.output()
    assert not refused.successful and refused.reason == (
        "parameter 'filter_noise_mm': 1e+146 mm gives a non-finite restart covariance in mm")
    assert accepted.successful, accepted.reason
