"""Nothing that arrives on a topic stops a node (issue 14, kind 1 and the node cases of the
"traceback" list), with the real node executables over DDS:

- a header stamp before 1970 (sec = -1) passes through the detector and the fusion node
  (the outputs keep the stamp);
- a /monet/model announcement (right sha256, latched) of a checkpoint whose metadata has
  the wrong type (`input_size: 64`) is rejected and counted, the detector keeps its weights,
  and a detector started while it is still latched runs too (no crash loop);
- a camera_info with K = 1e300 is counted as bad; 16-bit mono images are detected;
- 2x2 heatmaps from one camera: that view is skipped and counted, the others are fused;
- SIGINT / SIGTERM in the first fraction of a second of a node: exit 0, no traceback.
"""
import hashlib
import json
import signal
import time

from diagnostic_msgs.msg import DiagnosticArray
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import cv2_project, gaussian_heatmaps, ring_rig, subject_box, to_crop
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from std_msgs.msg import String
import torch

from monet_ros.geometry import save_rig
from monet_ros.io import (
    camera_info_from_camera,
    cloud_to_keypoints3d,
    header_stamp_ns,
    heatmaps_to_image_msg,
    numpy_to_image_msg,
)
from monet_ros.models import build_model, save_checkpoint
from monet_ros.nodes.qos import LATCHED
from monet_ros.skeleton import load_skeleton

BEFORE_1970 = -1_000_000_000          # header.stamp sec = -1, nanosec = 0
T0 = 1_700_000_000_000_000_000
GRID = (48, 64)                       # heatmap (w, h)


def diag_values(diagnostics, name):
    """{key: value} of the newest status called `name` (None if none yet)."""
    for msg in reversed(diagnostics):
        for status in msg.status:
            if status.name == name:
                return {kv.key: kv.value for kv in status.values}
    return None


# ------------------------------------------------------------------------------ detector

@pytest.fixture
def detector_setup(tmp_path):
    rig = ring_rig(2)
    rig_path = tmp_path / 'rig.yaml'
    save_rig(rig_path, rig)
    torch.manual_seed(0)
    names = list(load_skeleton('human14').keypoints)
    good = tmp_path / 'good.pt'
    save_checkpoint(good, build_model('small', 14, input_size=(96, 128)), {'keypoints': names})
    bad = tmp_path / 'bad.pt'             # the example: input_size is an int
    payload = torch.load(good, weights_only=True)
    payload['metadata']['input_size'] = 64
    torch.save(payload, bad)
    return rig, rig_path, good, bad


def _announce(path):
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    return String(data=json.dumps({'path': str(path), 'sha256': sha, 'step': 1}))


def test_detector_survives_bad_stamps_models_intrinsics_and_takes_16bit(ros_env,
                                                                       detector_setup):
    rig, rig_path, good, bad = detector_setup
    params = dict(rig=str(rig_path), model=str(good), device='cpu', track=False)
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, (480, 640, 3), dtype=np.uint8)
    with RosHarness(ros_env) as ros:
        model_pub = ros.publisher('/monet/model', String, LATCHED)
        model_pub.publish(_announce(bad))           # latched before any detector starts
        heat = {c.name: ros.collect(f'/monet/{c.name}/heatmaps', Image, 100) for c in rig}
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pubs = {c.name: (ros.publisher(f'/{c.name}/image_raw', Image),
                         ros.publisher(f'/{c.name}/camera_info', CameraInfo)) for c in rig}

        def roundtrip(node, stamp, make_image, cams=rig):
            def arrived():
                return all(any(header_stamp_ns(m) == stamp for m in heat[c.name]) for c in cams)
            for _ in range(40):
                for cam in cams:
                    pubs[cam.name][1].publish(camera_info_from_camera(cam, stamp, cam.name))
                    pubs[cam.name][0].publish(make_image(stamp, cam.name))
                if ros.spin_until(arrived, timeout=1.0, process=node):
                    return
            raise AssertionError(f'no heatmaps for {stamp}\n{node.output()}')

        with NodeProcess('detector', ros_env, params) as node:
            for image_pub, info_pub in pubs.values():
                ros.wait_for_subscribers(image_pub, process=node)
                ros.wait_for_subscribers(info_pub, process=node)
            # 1. a stamp before 1970 is kept on the outputs
            roundtrip(node, BEFORE_1970, lambda s, n: numpy_to_image_msg(image, s, n))
            out = next(m for m in heat['cam0'] if header_stamp_ns(m) == BEFORE_1970)
            assert (out.header.stamp.sec, out.header.stamp.nanosec) == (-1, 0)
            # 2. the bad announcement was rejected and counted, the node runs on
            assert ros.spin_until(lambda: (diag_values(diagnostics, 'monet detector: cam0')
                                           or {}).get('model_rejects') == '1', 60, node)
            # 3. 16-bit mono images are detected (normalised to the network's input)
            raw = rng.integers(100, 4000, (480, 640), dtype=np.uint16)
            roundtrip(node, T0, lambda s, n: numpy_to_image_msg(raw, s, n, encoding='mono16'))
            # 4. camera_info with K = 1e300: counted as bad, the node runs on
            absurd = camera_info_from_camera(rig[0], T0 + 1, 'cam0')
            absurd.k[0] = 1e300

            def bad_counted():
                return int((diag_values(diagnostics, 'monet detector: cam0')
                            or {}).get('bad_messages', 0)) >= 1
            for _ in range(60):           # best-effort in: sent until counted
                pubs['cam0'][1].publish(absurd)
                if ros.spin_until(bad_counted, timeout=1.0, process=node):
                    break
            assert bad_counted(), node.output()
            assert node.running()
            assert node.stop(signal.SIGINT) == 0, node.output()
        output = node.output()
        assert 'rejected, keeping the current weights' in output
        assert 'metadata.input_size' in output and 'Traceback' not in output

        # 5. a detector started while the bad announcement is still latched runs too
        with NodeProcess('detector', ros_env, params) as again:
            for image_pub, _ in pubs.values():
                ros.wait_for_subscribers(image_pub, process=again)
            roundtrip(again, T0 + 5, lambda s, n: numpy_to_image_msg(image, s, n))
            assert again.stop(signal.SIGTERM) == 0, again.output()


# ------------------------------------------------------------------------------ fusion

def _views(rig, X, stamp, tiny=()):
    """(name, heatmap msg, camera_info msg) per camera; cameras in `tiny` send 2x2 grids."""
    out = []
    for cam in rig:
        uv = cv2_project(cam, X)
        box = subject_box(uv, cam.width, cam.height, GRID[0] / GRID[1])
        if cam.name in tiny:
            heat = np.full((len(X), 2, 2), 0.5, np.float32)
            info = camera_info_from_camera(cam.crop(box, (2, 2)), stamp, cam.name)
        else:
            heat = gaussian_heatmaps(to_crop(uv, box, GRID), GRID[::-1], sigma=1.5, peak=0.9)
            info = camera_info_from_camera(cam.crop(box, GRID), stamp, cam.name)
        out.append((cam.name, heatmaps_to_image_msg(heat, stamp, cam.name), info))
    return out


def test_fusion_keeps_pre_1970_stamps_and_skips_a_2x2_view(ros_env, tmp_path):
    rig = ring_rig(3)
    path = tmp_path / 'rig.yaml'
    save_rig(path, rig)
    X = np.random.default_rng(1).uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))
    # reliable in, a long timeout: a view lost or late under load would change num_views
    params = dict(rig=str(path), skeleton='human14', timeout_s=30.0,
                  input_reliability='reliable')
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pubs = {c.name: (ros.publisher(f'/monet/{c.name}/heatmaps', Image),
                         ros.publisher(f'/monet/{c.name}/camera_info', CameraInfo))
                for c in rig}
        for heat_pub, info_pub in pubs.values():
            ros.wait_for_subscribers(heat_pub, process=node)
            ros.wait_for_subscribers(info_pub, process=node)

        def fused(stamp, tiny=()):
            def arrived():
                return any(header_stamp_ns(c) == stamp for c in clouds)
            for _ in range(40):
                for name, heat, info in _views(rig, X, stamp, tiny):
                    pubs[name][1].publish(info)
                    pubs[name][0].publish(heat)
                if ros.spin_until(arrived, timeout=1.0, process=node):
                    return next(c for c in clouds if header_stamp_ns(c) == stamp)
            raise AssertionError(f'no keypoints3d for {stamp}\n{node.output()}')

        cloud = fused(BEFORE_1970)
        assert (cloud.header.stamp.sec, cloud.header.stamp.nanosec) == (-1, 0)
        got = cloud_to_keypoints3d(cloud, units='m')
        np.testing.assert_allclose(got['X'], X, atol=0.01)
        assert (got['num_views'] == 3).all()

        cloud = fused(T0, tiny=('cam2',))
        got = cloud_to_keypoints3d(cloud, units='m')
        np.testing.assert_allclose(got['X'], X, atol=0.01)     # the two good views
        assert (got['num_views'] == 2).all()
        assert ros.spin_until(lambda: int((diag_values(diagnostics, 'monet fusion: cam2')
                                           or {}).get('bad_messages', 0)) >= 1, 60, node)
        assert (diag_values(diagnostics, 'monet fusion: cam0') or {}).get('bad_messages') == '0'
        assert node.stop(signal.SIGINT) == 0, node.output()
    assert 'smaller than 3x3' in node.output()


# ------------------------------------------------------------------------------ signals

def _wait_for_library(process, name, timeout=60.0):
    """Wait until the process has mapped a shared library whose path contains `name`
    (numpy's = the node module's heavy imports have begun; rclpy's = ROS is starting)."""
    maps = f'/proc/{process.pid}/maps'
    end = time.monotonic() + timeout
    while time.monotonic() < end and process.poll() is None:
        try:
            with open(maps) as stream:
                if name in stream.read():
                    return True
        except OSError:
            return False
        time.sleep(0.002)
    return False


@pytest.mark.parametrize('module', ['fusion', 'detector'])
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize('moment', ['numpy', 'rclpy'])
def test_signal_during_start_exits_0_without_traceback(ros_env, tmp_path, module, sig,
                                                       moment):
    """The signal lands while the node module imports numpy/torch, or while rclpy loads
    (the window where a KeyboardInterrupt traceback / a -15 death used to happen). The
    interpreter's own start-up before the package is imported is out of any code's reach."""
    rig = tmp_path / 'rig.yaml'
    save_rig(rig, ring_rig(2))
    with NodeProcess(module, ros_env, {'rig': str(rig), 'model': str(tmp_path / 'no.pt'),
                                       'skeleton': 'human14'}) as node:
        if not _wait_for_library(node.process, moment):
            pytest.skip(f'{module} exited before loading {moment}: {node.output()}')
        code = node.stop(sig, timeout=30)
    output = node.output()
    assert 'Traceback' not in output, output
    assert code == 0, output


def test_bad_checkpoint_as_model_parameter_is_one_line_exit_2(ros_env, detector_setup):
    """The same CheckpointError path as hot reload: a clear start error, not a traceback."""
    rig, rig_path, good, bad = detector_setup
    with NodeProcess('detector', ros_env, dict(rig=str(rig_path), model=str(bad),
                                               device='cpu')) as node:
        code = node.wait(timeout=120)
    output = node.output()
    assert code == 2, output
    assert 'Traceback' not in output
    lines = [line for line in output.splitlines() if 'error' in line]
    assert len(lines) == 1 and str(bad) in lines[0] and 'metadata.input_size' in lines[0]
