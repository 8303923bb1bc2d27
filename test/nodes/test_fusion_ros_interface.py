"""The fusion node as a ROS user drives it: namespaces (two rigs side by side), best-effort
publishers, and parameters through the rcl_interfaces services (what `ros2 param` calls)."""
import signal

import cv2
from helpers.fusion_frames import Frame, run_frames
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
import pytest
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
from rclpy.duration import Duration
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from visualization_msgs.msg import Marker, MarkerArray
import yaml

from monet_ros.geometry import save_rig
from monet_ros.io import cloud_to_keypoints3d
from monet_ros.nodes.qos import LATCHED, STREAM_OUT
from monet_ros.skeleton import load_skeleton

BEST_EFFORT = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                         reliability=ReliabilityPolicy.BEST_EFFORT)


@pytest.fixture
def rig_file(tmp_path):
    rig = ring_rig(4)
    path = tmp_path / 'rig.yaml'
    save_rig(path, rig, frame_id='world')
    return rig, path


def publishers(ros, names, namespace='/monet', qos=10):
    return {n: (ros.publisher(f'{namespace}/{n}/heatmaps', Image, qos),
                ros.publisher(f'{namespace}/{n}/camera_info', CameraInfo, qos)) for n in names}


def wait_matched(ros, pubs, node):
    for heat_pub, info_pub in pubs.values():
        ros.wait_for_subscribers(heat_pub, timeout=60, process=node)
        ros.wait_for_subscribers(info_pub, timeout=60, process=node)


def test_two_rigs_in_two_namespaces_each_fuse_only_their_own_heatmaps(ros_env, rig_file):
    rig, path = rig_file
    names = [c.name for c in rig]
    rng = np.random.default_rng(3)
    truth = {ns: rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(14, 3))
             for ns in ('rig1', 'rig2')}
    nodes = {ns: NodeProcess('fusion', ros_env, dict(rig=str(path), timeout_s=2.0),
                             extra_args=['-r', f'__ns:=/{ns}']) for ns in truth}
    with RosHarness(ros_env) as ros, nodes['rig1'] as one, nodes['rig2'] as two:
        clouds = {ns: ros.collect(f'/{ns}/keypoints3d', PointCloud2) for ns in truth}
        default = ros.collect('/monet/keypoints3d', PointCloud2)
        pubs = {ns: publishers(ros, names, f'/{ns}') for ns in truth}
        for ns, node in (('rig1', one), ('rig2', two)):
            wait_matched(ros, pubs[ns], node)
        # each rig gets a different subject; a rig fed the other's heatmaps would differ
        for ns, node in (('rig1', one), ('rig2', two)):
            frames = [Frame(rig, truth[ns], i, rng, 0.0) for i in range(2)]
            run_frames(ros, node, pubs[ns], frames, clouds[ns])
        assert one.stop() == 0, one.output()
        assert two.stop() == 0, two.output()
    assert not default, 'a namespaced fusion published on /monet/keypoints3d'
    for ns in truth:
        for cloud in clouds[ns]:
            X = cloud_to_keypoints3d(cloud, units='m')['X']
            assert np.abs(X - truth[ns]).max() < 1e-3, ns


def test_best_effort_heatmap_publisher_is_fused(ros_env, rig_file):
    rig, path = rig_file
    rng = np.random.default_rng(4)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(14, 3))
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env,
                                                 dict(rig=str(path), timeout_s=2.0)) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        pubs = publishers(ros, [c.name for c in rig], qos=BEST_EFFORT)
        wait_matched(ros, pubs, node)
        got = run_frames(ros, node, pubs, [Frame(rig, X, 0, rng, 0.0)], clouds)
        assert node.stop() == 0, node.output()
    X_got = cloud_to_keypoints3d(next(iter(got.values())), units='m')['X']
    assert np.abs(X_got - X).max() < 1e-3


def call(ros, srv_type, name, request, node):
    """One service call (RosHarness.call: sent again when no response comes)."""
    return ros.call(srv_type, name, request, node)


def set_request(**values):
    params = []
    for name, value in values.items():
        if isinstance(value, float):
            pv = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
        else:
            pv = ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
        params.append(Parameter(name=name, value=pv))
    return SetParameters.Request(parameters=params)


def dump_value(value):
    """A ParameterValue as `ros2 param dump` writes it (rosidl value, None when unset)."""
    return {ParameterType.PARAMETER_NOT_SET: None,
            ParameterType.PARAMETER_BOOL: value.bool_value,
            ParameterType.PARAMETER_INTEGER: value.integer_value,
            ParameterType.PARAMETER_DOUBLE: value.double_value,
            ParameterType.PARAMETER_STRING: value.string_value,
            ParameterType.PARAMETER_STRING_ARRAY: list(value.string_array_value),
            ParameterType.PARAMETER_DOUBLE_ARRAY: list(value.double_array_value),
            ParameterType.PARAMETER_INTEGER_ARRAY: list(value.integer_array_value),
            }[value.type]


def test_parameters_ranges_live_changes_and_dump_round_trip(ros_env, rig_file, tmp_path):
    rig, path = rig_file
    rng = np.random.default_rng(5)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(14, 3))
    service = '/monet/fusion'
    # a long timeout: with min_views 4 a frame released early (a view late under load)
    # would be dropped, and its re-sent views are repeats, never fused
    params = dict(rig=str(path), timeout_s=30.0, input_reliability='reliable')
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        described = call(ros, DescribeParameters, f'{service}/describe_parameters',
                         DescribeParameters.Request(names=['threshold_px', 'min_views',
                                                           'slop_ms']), node).descriptors
        threshold, min_views, slop = described
        assert threshold.floating_point_range[0].from_value > 0.0     # exclusive minimum
        assert not threshold.read_only and not min_views.read_only and slop.read_only
        assert min_views.integer_range[0].from_value == 2

        # a live change: min_views 4 -> only keypoints seen by 4 inlier views (cam2 is
        # wrong in every frame, so none) are triangulated from the next frame on
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        pubs = publishers(ros, [c.name for c in rig])
        wait_matched(ros, pubs, node)
        first, second = Frame(rig, X, 0, rng, 0.0), Frame(rig, X, 1, rng, 0.0)
        before = run_frames(ros, node, pubs, [first], clouds)[first.stamp]
        result = call(ros, SetParameters, f'{service}/set_parameters',
                      set_request(min_views=4, threshold_px=10.0), node).results
        assert all(r.successful for r in result), [r.reason for r in result]
        after = run_frames(ros, node, pubs, [second], clouds)[second.stamp]
        refused = {
            'slop_ms': set_request(slop_ms=5.0),                # read-only
            'min_views': set_request(min_views=5),              # > the 4 cameras
            'threshold_px': set_request(threshold_px=-1.0),     # out of range
        }
        reasons = {name: call(ros, SetParameters, f'{service}/set_parameters', request,
                              node).results[0] for name, request in refused.items()}
        names = call(ros, GetParameters, f'{service}/get_parameters', GetParameters.Request(
            names=['min_views', 'threshold_px', 'slop_ms', 'cameras', 'rig']), node).values
        assert node.stop() == 0, node.output()
    early = cloud_to_keypoints3d(before, units='m')
    assert np.abs(early['X'] - X).max() < 1e-3 and (early['num_views'] >= 2).all()
    late = cloud_to_keypoints3d(after, units='m')
    assert np.isnan(late['X']).all() and (late['num_views'] == 0).all()
    for name, result in reasons.items():
        assert not result.successful, name
    assert '5 > the 4 cameras' in reasons['min_views'].reason
    values = [dump_value(v) for v in names]
    assert values[:3] == [4, 10.0, 0.0]
    # the dump (empty `cameras` included) loads back into a new node
    dump = tmp_path / 'dump.yaml'
    keys = ['min_views', 'threshold_px', 'slop_ms', 'cameras', 'rig']
    dump.write_text(yaml.safe_dump({service: {'ros__parameters': dict(zip(keys, values))}}))
    assert values[3] is None
    for spelling in ('null', '[]'):
        text = dump.read_text().replace('cameras: null', f'cameras: {spelling}')
        (tmp_path / f'dump_{spelling}.yaml').write_text(text)
        with RosHarness(ros_env) as ros, NodeProcess(
                'fusion', ros_env, extra_args=['--params-file',
                                               str(tmp_path / f'dump_{spelling}.yaml')]) as again:
            got = call(ros, GetParameters, f'{service}/get_parameters',
                       GetParameters.Request(names=['min_views', 'threshold_px']), again)
            assert [dump_value(v) for v in got.values] == [4, 10.0], again.output()
            assert again.stop() == 0, again.output()


def test_markers_expire_are_labelled_and_deleted_on_shutdown(ros_env, rig_file):
    rig, path = rig_file
    rng = np.random.default_rng(6)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(14, 3))
    params = dict(rig=str(path), timeout_s=2.0, marker_lifetime_s=0.7, marker_labels=True,
                  camera_marker_depth=0.3)
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        markers = ros.collect('/monet/skeleton', MarkerArray, STREAM_OUT)
        rig_markers = ros.collect('/monet/rig_markers', MarkerArray, LATCHED)
        pubs = publishers(ros, [c.name for c in rig])
        wait_matched(ros, pubs, node)
        run_frames(ros, node, pubs, [Frame(rig, X, 0, rng, 0.0)], clouds)
        assert ros.spin_until(lambda: markers and rig_markers, timeout=20, process=node)
        assert node.stop(signal.SIGINT) == 0, node.output()
        assert ros.spin_until(lambda: any(m.action == Marker.DELETEALL
                                          for a in markers for m in a.markers), timeout=60)
    first = markers[0].markers
    assert {m.ns for m in first} == {'human14/subject0', 'human14/subject0/names'}
    assert all(Duration.from_msg(m.lifetime).nanoseconds == 700_000_000 for m in first)
    names = load_skeleton('human14').keypoints
    texts = {m.text: m.pose.position for m in first if m.type == Marker.TEXT_VIEW_FACING}
    assert set(texts) == set(names)
    for k, name in enumerate(names):
        p = texts[name]
        np.testing.assert_allclose([p.x, p.y, p.z - 0.045], X[k], atol=1e-3)
    # DELETEALL arrived after the skeleton, on the same topic
    last = markers[-1].markers
    assert len(last) == 1 and last[0].action == Marker.DELETEALL, node.output()
    # a frustum per camera: centre -> corners that project onto the image corners
    lines = [m for m in rig_markers[-1].markers if m.type == Marker.LINE_LIST]
    assert len(lines) == len(rig)
    for cam, m in zip(rig, lines):
        pts = np.array([[p.x, p.y, p.z] for p in m.points])
        assert pts.shape == (16, 3)
        np.testing.assert_allclose(pts[0], cam.center, atol=1e-9)
        corners = pts[1:8:2]
        rvec, _ = cv2.Rodrigues(cam.R)
        uv, _ = cv2.projectPoints(np.ascontiguousarray(corners), rvec,
                                  np.asarray(cam.t, np.float64), cam.K, None)
        w, h = cam.width, cam.height
        np.testing.assert_allclose(uv.reshape(4, 2), [[-0.5, -0.5], [w - 0.5, -0.5],
                                                      [w - 0.5, h - 0.5], [-0.5, h - 0.5]],
                                   atol=1e-6)
        depth = (corners - cam.center) @ cam.R[2]
        np.testing.assert_allclose(depth, 0.3, atol=1e-9)
