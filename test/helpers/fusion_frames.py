"""Heatmap + camera_info frames of a known 3D subject for fusion tests (a wrong view
included), and the publish-until-fused loop."""
import numpy as np
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

from helpers.scenes import cv2_project, gaussian_heatmaps, subject_box, to_crop
from monet_ros.io import camera_info_from_camera, header_stamp_ns, heatmaps_to_image_msg

GRID = (48, 64)      # heatmap (w, h)
T0 = 1_700_000_000_000_000_000
PEAKS = [0.9, 0.8, 0.95, 0.7]
WRONG = 2


class Frame:
    """Heatmap + camera_info messages of every camera for one stamp, and the truth."""

    def __init__(self, rig, X, index, rng, noise, silent=()):
        self.stamp = T0 + index * 33_000_000
        self.X = X
        self.centres, self.messages, self.maxima = {}, [], {}
        for v, cam in enumerate(rig):
            uv = cv2_project(cam, X)
            box = subject_box(uv, cam.width, cam.height, GRID[0] / GRID[1])
            p = to_crop(uv, box, GRID)
            if v == WRONG:
                p = p + np.where(p < np.array(GRID) / 2, 12.0, -12.0)
            else:
                p = p + rng.normal(0, noise, p.shape)
            x0, y0, x1, y1 = box
            scale = np.array([GRID[0] / (x1 - x0), GRID[1] / (y1 - y0)])
            self.centres[cam.name] = (p + 0.5) / scale - 0.5 + np.array([x0, y0])
            if cam.name in silent:
                continue
            heat = gaussian_heatmaps(p, GRID[::-1], sigma=1.5, peak=PEAKS[v])
            self.maxima[cam.name] = heat.max(axis=(1, 2))
            self.messages.append((cam.name, heatmaps_to_image_msg(heat, self.stamp, cam.name),
                                  camera_info_from_camera(cam.crop(box, GRID), self.stamp,
                                                          cam.name)))


def publishers(ros, names):
    return {n: (ros.publisher(f'/monet/{n}/heatmaps', Image),
                ros.publisher(f'/monet/{n}/camera_info', CameraInfo)) for n in names}


def reliable_publishers(ros, names, node):
    """{name: (heatmaps, camera_info)} reliable publishers (100 deep: a burst is neither
    dropped nor merged), returned once the fusion node `node` subscribes to each."""
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE)
    pubs = {n: (ros.publisher(f'/monet/{n}/heatmaps', Image, qos),
                ros.publisher(f'/monet/{n}/camera_info', CameraInfo, qos)) for n in names}
    for heat_pub, info_pub in pubs.values():
        ros.wait_for_subscribers(heat_pub, process=node)
        ros.wait_for_subscribers(info_pub, process=node)
    return pubs


def send(pubs, frame):
    for name, heat, info in frame.messages:
        pubs[name][1].publish(info)
        pubs[name][0].publish(heat)


def fusion_statuses(diagnostics):
    """{status name: DiagnosticStatus} of the newest /diagnostics message of the fusion node
    ({} if none yet; other publishers of /diagnostics, such as a callback guard, are
    skipped)."""
    for msg in reversed(diagnostics):
        statuses = {s.name: s for s in msg.status}
        if 'monet fusion' in statuses:
            return statuses
    return {}


def fused_frames(diagnostics):
    """'frames' of the fusion summary in the newest fusion /diagnostics (0 if none)."""
    status = fusion_statuses(diagnostics).get('monet fusion')
    return int({kv.key: kv.value for kv in status.values}['frames']) if status else 0


def run_frames(ros, node, pubs, frames, clouds, timeout=30.0):
    """Publish each frame until its keypoints3d comes back; returns {stamp: cloud}."""
    got = {}
    for frame in frames:
        def arrived(stamp=frame.stamp):
            got.update({header_stamp_ns(c): c for c in clouds})
            return stamp in got
        for _ in range(int(timeout / 0.5)):
            send(pubs, frame)
            if ros.spin_until(arrived, timeout=0.5, process=node):
                break
        assert arrived(), f'no keypoints3d for stamp {frame.stamp}\n{node.output()}'
    return got


def set_parameters(ros, node, target='/monet/fusion', **values):
    """SetParameters on the node `target` (what `ros2 param set` sends) -> the results."""
    params = []
    for name, value in values.items():
        if isinstance(value, bool):
            pv = ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value)
        else:
            pv = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
        params.append(Parameter(name=name, value=pv))
    client = ros.node.create_client(SetParameters, f'{target}/set_parameters')
    assert ros.spin_until(client.service_is_ready, timeout=30, process=node)
    for _ in range(3):   # a response sent before the client's reader matched is lost
        future = client.call_async(SetParameters.Request(parameters=params))
        if ros.spin_until(future.done, timeout=10, process=node):
            return future.result().results
        client.remove_pending_request(future)
    raise AssertionError('set_parameters: no response')
