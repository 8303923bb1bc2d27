"""TF: fusion publishes the rig on /tf_static; a recording whose TF root is `map` gives
keypoints in `map`. tf2_msgs is built into the venv by `make venv` (tools/build_tf2_msgs.sh);
without it these tests skip with that reason."""
from helpers.fusion_frames import Frame, publishers, run_frames
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2

from monet_ros.geometry import save_rig
from monet_ros.io import BagWriter, cloud_to_keypoints3d
from monet_ros.io.fields import quaternion_to_matrix
from monet_ros.nodes.qos import LATCHED

tf2_msgs = pytest.importorskip('tf2_msgs.msg', reason='tf2_msgs not built: run '
                               'tools/build_tf2_msgs.sh .venv (make venv does)')


def test_fusion_publishes_the_rig_on_tf_static(ros_env, tmp_path):
    rig = ring_rig(4)
    path = tmp_path / 'rig.yaml'
    save_rig(path, rig, frame_id='lab')
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, dict(rig=str(path))) as node:
        tf = ros.collect('/tf_static', tf2_msgs.TFMessage, LATCHED)
        assert ros.spin_until(lambda: tf, timeout=30, process=node), node.output()
        assert node.stop() == 0
    transforms = {t.child_frame_id: t for t in tf[0].transforms}
    assert set(transforms) == {f'{c.name}_optical' for c in rig}
    for cam in rig:
        t = transforms[f'{cam.name}_optical']
        assert t.header.frame_id == 'lab'
        p, q = t.transform.translation, t.transform.rotation
        # the camera's pose: centre C = -R^T t, orientation R^T (x_lab = R^T x_cam + C)
        np.testing.assert_allclose([p.x, p.y, p.z], -cam.R.T @ cam.t, atol=1e-9)
        np.testing.assert_allclose(quaternion_to_matrix(q.x, q.y, q.z, q.w), cam.R.T,
                                   atol=1e-9)


def test_recording_rooted_in_map_gives_keypoints_in_map(ros_env, tmp_path):
    rig = ring_rig(4)
    stamp = 1_700_000_000_000_000_000
    with BagWriter(tmp_path / 'rec') as writer:
        writer.write_tf_static(stamp, rig, parent='map')
        for cam in rig:
            writer.write_camera_info(f'/{cam.name}/camera_info', stamp, cam,
                                     f'{cam.name}_optical')
    rng = np.random.default_rng(9)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(14, 3))
    params = dict(rig=str(tmp_path / 'rec'), timeout_s=2.0)
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        tf = ros.collect('/tf_static', tf2_msgs.TFMessage, LATCHED)
        pubs = publishers(ros, [c.name for c in rig])
        for heat_pub, info_pub in pubs.values():
            ros.wait_for_subscribers(heat_pub, process=node)
            ros.wait_for_subscribers(info_pub, process=node)
        frame = Frame(rig, X, 0, rng, 0.0)
        got = run_frames(ros, node, pubs, [frame], clouds)[frame.stamp]
        assert ros.spin_until(lambda: tf, timeout=20, process=node)
        assert node.stop() == 0
    assert got.header.frame_id == 'map'
    assert np.abs(cloud_to_keypoints3d(got, units='m')['X'] - X).max() < 1e-3
    assert {t.header.frame_id for t in tf[0].transforms} == {'map'}
