"""Logs name the topic a node really listens on (issue 25 item 14): a detector and a fusion
node in the namespace /rig1 say /rig1/model, /rig1/keypoints3d, /rig1/cam0/heatmaps (the
resolved names), never the default /monet/... or an unresolved relative name."""
import json
import re
import signal

from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from std_msgs.msg import String
import torch

from monet_ros.geometry import save_rig
from monet_ros.io import camera_info_from_camera, heatmaps_to_image_msg
from monet_ros.models import build_model, save_checkpoint
from monet_ros.nodes.qos import LATCHED
from monet_ros.skeleton import load_skeleton

NAMESPACE = ['-r', '__ns:=/rig1']
T0 = 1_700_000_000_000_000_000


def logged_topics(output):
    """The topic names that start a log message ('[node]: /a/b: bad message' or
    '[node]: /a/b rejected')."""
    return set(re.findall(r'\]: (\S+?):? (?:bad message|rejected)', output))


def test_detector_logs_name_the_resolved_topics(ros_env, tmp_path):
    rig = ring_rig(2)
    save_rig(tmp_path / 'rig.yaml', rig)
    torch.manual_seed(0)
    model = tmp_path / 'model.pt'
    save_checkpoint(model, build_model('small', 14, input_size=(96, 128)),
                    {'keypoints': list(load_skeleton('human14').keypoints)})
    params = dict(rig=str(tmp_path / 'rig.yaml'), model=str(model), device='cpu')
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params,
                                                 extra_args=NAMESPACE) as node:
        model_pub = ros.publisher('/rig1/model', String, LATCHED)
        cloud_pub = ros.publisher('/rig1/keypoints3d', PointCloud2)
        ros.wait_for_subscribers(model_pub, process=node)
        ros.wait_for_subscribers(cloud_pub, process=node)
        model_pub.publish(String(data=json.dumps({'path': str(tmp_path / 'none.pt'),
                                                  'sha256': '0' * 64})))
        expected = {'/rig1/model', '/rig1/keypoints3d'}

        def logged():
            cloud_pub.publish(PointCloud2())          # no x, y, z fields: a bad message
            return expected <= logged_topics(node.output())
        assert ros.spin_until(logged, timeout=60, process=node), node.output()
        assert node.stop(signal.SIGINT) == 0, node.output()
    output = node.output()
    assert logged_topics(output) == expected, output
    assert '/monet/' not in output, output


def test_fusion_logs_name_the_resolved_heatmap_topic(ros_env, tmp_path):
    rig = ring_rig(2)
    save_rig(tmp_path / 'rig.yaml', rig)
    params = dict(rig=str(tmp_path / 'rig.yaml'), skeleton='human14')
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params,
                                                 extra_args=NAMESPACE) as node:
        heat_pub = ros.publisher('/rig1/cam0/heatmaps', Image)
        info_pub = ros.publisher('/rig1/cam0/camera_info', CameraInfo)
        ros.wait_for_subscribers(heat_pub, process=node)
        ros.wait_for_subscribers(info_pub, process=node)
        cam = rig[0]
        heat = np.zeros((3, 48, 64), np.float32)        # 3 channels, human14 has 14: bad
        info = camera_info_from_camera(cam.crop((0, 0, cam.width, cam.height), (64, 48)),
                                       T0, cam.name)

        def logged():
            info_pub.publish(info)
            heat_pub.publish(heatmaps_to_image_msg(heat, T0, cam.name))
            return '/rig1/cam0/heatmaps' in logged_topics(node.output())
        assert ros.spin_until(logged, timeout=60, process=node), node.output()
        assert node.stop(signal.SIGINT) == 0, node.output()
    output = node.output()
    assert logged_topics(output) == {'/rig1/cam0/heatmaps'}, output
    assert '3 channels' in output
