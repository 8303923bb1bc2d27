"""The detector executable in its own process: heatmap messages, virtual camera_info,
stamps, tracked crops, bad messages and checkpoint hot reload."""
import hashlib
import json
import signal

from helpers.detector_crops import INPUT, expected_box, expected_K, make_checkpoint
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import cv2_project, ring_rig
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from std_msgs.msg import String
import torch

from monet_ros.crop_rule import crop_boxes
from monet_ros.geometry import save_rig
from monet_ros.io import (
    camera_info_from_camera,
    header_stamp_ns,
    image_msg_to_heatmaps,
    keypoints3d_to_cloud,
    numpy_to_image_msg,
)
from monet_ros.models import Detector, load_checkpoint
from monet_ros.models.detector import bfloat16_native
from monet_ros.nodes.qos import LATCHED

T0 = 1_650_000_000_000_000_000


@pytest.fixture
def setup(tmp_path):
    rig = ring_rig(2)
    rig_path = tmp_path / 'rig.yaml'
    save_rig(rig_path, rig)
    first = make_checkpoint(tmp_path / 'first.pt', 1)
    second = make_checkpoint(tmp_path / 'second.pt', 2)
    images = np.random.default_rng(0).integers(0, 255, (2, 480, 640, 3), dtype=np.uint8)
    return rig, rig_path, first, second, images


class Stream:
    """Publishes images + camera_info of the rig and collects the detector's outputs."""

    def __init__(self, ros, rig):
        self.rig = rig
        self.pubs = {c.name: (ros.publisher(f'/{c.name}/image_raw', Image),
                              ros.publisher(f'/{c.name}/camera_info', CameraInfo))
                     for c in rig}
        self.heat = {c.name: ros.collect(f'/monet/{c.name}/heatmaps', Image, 100)
                     for c in rig}
        self.info = {c.name: ros.collect(f'/monet/{c.name}/camera_info', CameraInfo, 100)
                     for c in rig}
        self.ros = ros

    def wait_matched(self, node):
        """Until the detector subscribes every image and camera_info topic."""
        for image_pub, info_pub in self.pubs.values():
            self.ros.wait_for_subscribers(image_pub, timeout=120, process=node)
            self.ros.wait_for_subscribers(info_pub, process=node)

    def send(self, stamp, images):
        for cam, image in zip(self.rig, images):
            self.pubs[cam.name][1].publish(camera_info_from_camera(cam, stamp, cam.name))
            self.pubs[cam.name][0].publish(numpy_to_image_msg(image, stamp, cam.name))

    def result(self, name, stamp):
        for heat, info in zip(self.heat[name], self.info[name]):
            if header_stamp_ns(heat) == stamp:
                assert header_stamp_ns(info) == stamp
                return heat, info
        return None

    def roundtrip(self, stamp, images, node, tries=20):
        for _ in range(tries):
            self.send(stamp, images)
            if self.ros.spin_until(lambda: all(self.result(c.name, stamp) for c in self.rig),
                                   timeout=1.5, process=node):
                return {c.name: self.result(c.name, stamp) for c in self.rig}
        raise AssertionError(f'no heatmaps for stamp {stamp}\n{node.output()}')


def detector_boxes(checkpoint, rig, boxes):
    model, metadata = load_checkpoint(checkpoint)
    return Detector(model, metadata, device='cpu').boxes_for(rig, boxes)


def reference(checkpoint, images, rig, boxes, precision='auto'):
    model, metadata = load_checkpoint(checkpoint)
    return Detector(model, metadata, device='cpu', precision=precision).predict(
        list(images), rig, boxes, keep_aspect=False)[0]


def test_heatmaps_camera_info_stamps_tracking_and_hot_reload(ros_env, setup):
    rig, rig_path, first, second, images = setup
    aspect = INPUT[1] / INPUT[0]
    params = dict(rig=str(rig_path), model=str(first), box=[100.0, 50.0, 400.0, 450.0],
                  track_timeout_s=3600.0, device='cpu', debug_image=True,
                  debug_image_scale=1.0)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        stream = Stream(ros, rig)
        overlays = ros.collect('/monet/cam1/debug_image', Image, 100)
        overlay_infos = ros.collect('/monet/cam1/debug_image/camera_info', CameraInfo, 100)
        stream.wait_matched(node)

        # 1. the configured box (grown to the network's aspect)
        got = stream.roundtrip(T0, images, node)
        box = expected_box((100, 50, 400, 450), aspect)
        for cam in rig:
            heat_msg, info = got[cam.name]
            assert heat_msg.encoding == '32FC14'
            assert (heat_msg.height, heat_msg.width) == (24, 32)
            assert heat_msg.header.frame_id == cam.name
            assert (info.width, info.height) == (32, 24)
            np.testing.assert_allclose(np.reshape(info.k, (3, 3)),
                                       expected_K(cam.K, box, 32, 24), rtol=1e-12)
            np.testing.assert_allclose(info.d, cam.dist)
        assert ros.spin_until(lambda: any(header_stamp_ns(m) == T0 for m in overlays),
                              timeout=60, process=node), node.output()
        overlay = next(m for m in overlays if header_stamp_ns(m) == T0)
        assert (overlay.encoding, overlay.width, overlay.height) == ('bgr8', 640, 480)
        assert ros.spin_until(lambda: overlay_infos, timeout=60, process=node)
        np.testing.assert_allclose(np.reshape(overlay_infos[0].k, (3, 3)), rig[1].K)
        # the source image (as bgr) with the crop box drawn in yellow on its right edge
        pixels = np.frombuffer(overlay.data, np.uint8).reshape(480, 640, 3)
        x0, y0, x1, y1 = np.round(box).astype(int)
        assert tuple(pixels[(y0 + y1) // 2, x1 - 1]) == (0, 220, 255)
        untouched = pixels[y0 + 10:y1 - 10, x1 - 40:x1 - 20]
        source = images[1][y0 + 10:y1 - 10, x1 - 40:x1 - 20, ::-1]
        assert np.mean(untouched == source) > 0.8
        want = reference(first, images, rig, np.array([box, box]))
        for v, cam in enumerate(rig):
            np.testing.assert_allclose(image_msg_to_heatmaps(got[cam.name][0]), want[v],
                                       atol=1e-4)

        # 2. a bad image (wrong size) is counted, the node lives on (sent until the node
        # says so: images are best-effort, newest only)
        def logged(text, publish):
            for _ in range(60):
                publish()
                if ros.spin_until(lambda: text in node.output(), timeout=1.0, process=node):
                    return True
            return False
        assert logged('bad message (image is 320x240 but the camera is 640x480)',
                      lambda: stream.pubs['cam0'][0].publish(numpy_to_image_msg(
                          images[0][:240, :320], T0 + 1, 'cam0'))), node.output()

        # 3. crop around the projection of /monet/keypoints3d; one wild joint (1.5 m off)
        # is left out of the box (crop_rule: median/MAD trim)
        X = np.random.default_rng(3).uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))
        X[13, 2] += 1.5
        cloud_pub = ros.publisher('/monet/keypoints3d', PointCloud2)
        ros.wait_for_subscribers(cloud_pub, process=node)
        # the very function evaluation and `monet process` crop with (crop_rule), on the
        # same keypoints at the precision the cloud carries
        rule = detector_boxes(first, rig, crop_boxes(rig, X.astype(np.float32)))

        def cropped_around_X(got):
            return all(np.allclose(np.reshape(got[cam.name][1].k, (3, 3)),
                                   expected_K(cam.K, rule[v], 32, 24), rtol=1e-12)
                       for v, cam in enumerate(rig))
        # the cloud (best-effort in) is sent with every frame until the crops follow it
        for stamp in range(T0 + 100, T0 + 160):
            cloud_pub.publish(keypoints3d_to_cloud(T0, 'world', X, units='m'))
            got = stream.roundtrip(stamp, images, node)
            if cropped_around_X(got):
                break
        tracked = []
        for v, cam in enumerate(rig):
            np.testing.assert_allclose(np.reshape(got[cam.name][1].k, (3, 3)),
                                       expected_K(cam.K, rule[v], 32, 24), rtol=1e-12)
        for cam in rig:
            uv = cv2_project(cam, X.astype(np.float32))    # the cloud carries float32
            dev = np.abs(uv - np.median(uv, axis=0))
            keep = (dev <= 4 * np.maximum(1.4826 * np.median(dev, axis=0), 8.0)).all(axis=1)
            assert not keep[13] and keep.sum() >= 10
            uv = uv[keep]
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            pad = 0.3 * (hi - lo)
            tracked.append(expected_box((*(lo - pad + 0.5), *(hi + pad + 0.5)), aspect))
            np.testing.assert_allclose(np.reshape(got[cam.name][1].k, (3, 3)),
                                       expected_K(cam.K, tracked[-1], 32, 24), rtol=1e-9)
        tracked = np.array(tracked)

        # 4. hot reload: a verified announcement swaps the weights between frames
        model_pub = ros.publisher('/monet/model', String, LATCHED)
        sha = hashlib.sha256(second.read_bytes()).hexdigest()
        model_pub.publish(String(data=json.dumps({'path': str(second), 'sha256': sha,
                                                  'step': 7})))
        new = reference(second, images, rig, tracked)
        old = reference(first, images, rig, tracked)

        def heatmaps(got):
            return [image_msg_to_heatmaps(got[c.name][0]) for c in rig]

        stamp = T0 + 3
        for stamp in range(T0 + 3, T0 + 63):      # frames keep flowing while it loads
            got = stream.roundtrip(stamp, images, node)
            if np.allclose(heatmaps(got)[0], new[0], atol=1e-4):
                break
        for v, heat in enumerate(heatmaps(got)):
            np.testing.assert_allclose(heat, new[v], atol=1e-4)
            assert np.abs(heat - old[v]).max() > 1e-2

        # 5. a corrupt file and a mismatched sha256 are refused, the new weights stay
        corrupt = second.with_name('corrupt.pt')
        corrupt.write_bytes(b'not a checkpoint at all')
        for path, digest in ((corrupt, hashlib.sha256(corrupt.read_bytes()).hexdigest()),
                             (first, '0' * 64)):
            model_pub.publish(String(data=json.dumps({'path': str(path), 'sha256': digest})))
            said = 'corrupt.pt' if path == corrupt else 'does not match the announced'
            assert ros.spin_until(lambda s=said: s in node.output(), timeout=60, process=node), \
                node.output()
        got_after = stream.roundtrip(stamp + 1, images, node)
        assert node.stop(signal.SIGINT) == 0, node.output()
    output = node.output()
    assert 'bad message (image is 320x240 but the camera is 640x480)' in output
    assert 'loaded new weights' in output and str(second) in output
    assert 'rejected, keeping the current weights' in output and 'corrupt.pt' in output
    assert 'does not match the announced' in output
    for v, cam in enumerate(rig):     # still the second model's weights
        np.testing.assert_allclose(image_msg_to_heatmaps(got_after[cam.name][0]), new[v],
                                   atol=1e-4)


@pytest.mark.parametrize('change, message', [
    ({'model': '/nonexistent/model.pt'}, '/nonexistent/model.pt: checkpoint file not found'),
    ({'cameras': ['cam0', 'cam7']}, "parameter 'cameras': unknown camera 'cam7'"),
    ({'precision': 'bfloat16', 'backend': 'onnxruntime'},
     "precision bfloat16 needs backend torch, got 'onnxruntime'"),
    pytest.param({'device': 'cuda', 'precision': 'bfloat16'},
                 "parameter 'device': 'cuda': CUDA is not available",
                 marks=pytest.mark.skipif(torch.cuda.is_available(), reason='CUDA is here')),
])
def test_bad_parameters_fail_at_start(ros_env, setup, change, message):
    _, rig_path, first, _, _ = setup
    params = {'rig': str(rig_path), 'model': str(first), **change}
    with NodeProcess('detector', ros_env, params) as node:
        assert node.wait(timeout=90) == 2, node.output()
        assert message in node.output()


@pytest.mark.parametrize('backend, precision', [
    ('onnxruntime', 'float32'),
    pytest.param('torch', 'bfloat16', marks=pytest.mark.skipif(
        not bfloat16_native('cpu'), reason='no native bfloat16 on this CPU'))])
def test_backend_and_precision_give_the_core_frame_and_report_stages(ros_env, setup, backend,
                                                                     precision):
    """backend onnxruntime: the same heatmaps as torch (1e-4) for a bgr8 frame (cropped in
    its own layout), the export cached beside the checkpoint; precision bfloat16: the core
    Detector's bfloat16 heatmaps (1e-4), within 3% of the peak of float32's; per-stage
    timers, backend and precision in /diagnostics."""
    from diagnostic_msgs.msg import DiagnosticArray

    from monet_ros.atomic import sha256_file
    from monet_ros.models.onnx_backend import onnx_path_for

    rig, rig_path, first, _, images = setup
    box = [100.0, 50.0, 400.0, 450.0]
    params = dict(rig=str(rig_path), model=str(first), box=box, track=False, device='cpu',
                  backend=backend, threads=1, precision=precision)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        stream = Stream(ros, rig)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        stream.wait_matched(node)
        for _ in range(20):  # the same frames as bgr8 messages
            for cam, image in zip(rig, images):
                stream.pubs[cam.name][1].publish(camera_info_from_camera(cam, T0, cam.name))
                stream.pubs[cam.name][0].publish(numpy_to_image_msg(image, T0, cam.name,
                                                                    encoding='bgr8'))
            if ros.spin_until(lambda: all(stream.result(c.name, T0) for c in rig),
                              timeout=1.5, process=node):
                break
        got = {c.name: stream.result(c.name, T0) for c in rig}
        assert all(got.values()), node.output()
        aspect = INPUT[1] / INPUT[0]
        boxes = np.array([expected_box(box, aspect)] * len(rig))
        # the torch backend at this precision, rgb frames
        expected = reference(first, images, rig, boxes, precision)
        float32 = reference(first, images, rig, boxes, 'float32')
        for v, cam in enumerate(rig):
            heat = image_msg_to_heatmaps(got[cam.name][0])
            np.testing.assert_allclose(heat, expected[v], atol=1e-4, rtol=0)
            peak = np.abs(float32[v]).max()
            np.testing.assert_allclose(heat, float32[v], atol=0.03 * peak, rtol=0)
        if backend == 'onnxruntime':   # (torch: another test's auto backend may have made it)
            assert onnx_path_for(first, sha256_file(first)).is_file()

        def stage_report():
            for msg in diagnostics:
                for status in msg.status:
                    values = {kv.key: kv.value for kv in status.values}
                    if (values.get('backend') == backend and 'forward_calls' in values
                            and values.get('precision') == precision):
                        return values
            return None
        assert ros.spin_until(lambda: stage_report() is not None, timeout=30, process=node)
        values = stage_report()
        for stage in ('convert', 'crop', 'forward', 'publish'):   # each stage ran and has
            assert float(values[f'{stage}_ms_mean']) >= 0, values  # a figure (0.000 if fast)
            assert int(values[f'{stage}_calls']) >= 1


def test_a_mm_rig_crops_around_keypoints3d_in_metres_as_a_metre_rig(ros_env, setup, tmp_path):
    """/monet/keypoints3d is in metres (REP 103) whatever the rig's unit: a detector whose
    rig is in mm reads it into mm before projecting, so its crops land on the subject
    exactly where a metre rig's do (before, metres projected with mm cameras put the
    subject near the camera centres)."""
    from monet_ros.geometry.units import rescale

    rig_m, _, first, _, images = setup
    rig_mm = rescale(rig_m, 'mm')
    path = tmp_path / 'rig_mm.yaml'
    save_rig(path, rig_mm)
    params = dict(rig=str(path), model=str(first), box=[100.0, 50.0, 400.0, 450.0],
                  track_timeout_s=3600.0, device='cpu', debug_image=True,
                  debug_image_scale=1.0, debug_image_rate_hz=100.0)
    X = np.random.default_rng(5).uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))   # m
    # the metre rig's crops around the keypoints as the cloud carries them (float32 m)
    rule = detector_boxes(first, rig_m, crop_boxes(rig_m, X.astype(np.float32)))
    fixed = expected_box((100, 50, 400, 450), INPUT[1] / INPUT[0])
    assert np.abs(rule - np.array([fixed, fixed])).max() > 20      # a different crop

    def cropped_around_X(got):
        return all(np.allclose(np.reshape(got[cam.name][1].k, (3, 3)),
                               expected_K(cam.K, rule[v], 32, 24), rtol=1e-9)
                   for v, cam in enumerate(rig_mm))
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        stream = Stream(ros, rig_mm)
        cloud_pub = ros.publisher('/monet/keypoints3d', PointCloud2)
        overlays = ros.collect('/monet/cam1/debug_image', Image, 100)
        stream.wait_matched(node)
        ros.wait_for_subscribers(cloud_pub, process=node)
        got = stream.roundtrip(T0, images, node)           # no keypoints yet: the box
        for cam in rig_mm:
            np.testing.assert_allclose(np.reshape(got[cam.name][1].k, (3, 3)),
                                       expected_K(cam.K, fixed, 32, 24), rtol=1e-12)
        # what fusion publishes for this subject: metres (a mm fusion converts at publish)
        cloud = keypoints3d_to_cloud(T0, 'world', X * 1000.0, units='mm')
        for stamp in range(T0 + 1, T0 + 61):    # best-effort in: sent with every frame
            cloud_pub.publish(cloud)
            got = stream.roundtrip(stamp, images, node)
            if cropped_around_X(got):
                break
        tracked = stamp
        for stamp in range(tracked + 1, tracked + 41):     # a debug image of a tracked frame
            if any(header_stamp_ns(m) >= tracked for m in overlays):
                break
            stream.roundtrip(stamp, images, node)
        assert node.stop(signal.SIGINT) == 0, node.output()
    for v, cam in enumerate(rig_mm):
        np.testing.assert_allclose(np.reshape(got[cam.name][1].k, (3, 3)),
                                   expected_K(cam.K, rule[v], 32, 24), rtol=1e-9)
    # the debug image's red crosses (the fused keypoints reprojected) are where the metre
    # rig projects the subject (a peak's green dot may cover a few)
    overlay = next(m for m in overlays if header_stamp_ns(m) >= tracked)
    pixels = np.frombuffer(overlay.data, np.uint8).reshape(480, 640, 3)
    uv = np.round(cv2_project(rig_m[1], X.astype(np.float32))).astype(int)
    inside = ((uv >= 0) & (uv < [640, 480])).all(axis=1)
    red = [tuple(pixels[y, x]) == (40, 40, 240) for x, y in uv[inside]]
    assert inside.sum() >= 10 and sum(red) >= 0.7 * len(red), (sum(red), len(red))


def test_lockstep_waits_for_the_previous_frames_keypoints3d(ros_env, setup):
    """lockstep: a frame that arrives before the 3D of the previous processed frame waits
    for it, then is cropped around it (whatever order the messages arrive in); after
    lockstep_timeout_s it goes on without it, counted in /diagnostics."""
    from diagnostic_msgs.msg import DiagnosticArray

    rig, rig_path, first, _, images = setup
    params = dict(rig=str(rig_path), model=str(first), box=[100.0, 50.0, 400.0, 450.0],
                  track_timeout_s=3600.0, device='cpu', lockstep=True, lockstep_timeout_s=10.0)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        stream = Stream(ros, rig)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        cloud_pub = ros.publisher('/monet/keypoints3d', PointCloud2)
        stream.wait_matched(node)
        ros.wait_for_subscribers(cloud_pub, process=node)
        stream.roundtrip(T0, images, node)          # the first frame waits for nothing

        def done(stamp):
            return all(stream.result(c.name, stamp) for c in rig)
        # frame 2 before the 3D of frame 1: held back (a second is hundreds of forwards)
        stream.send(T0 + 1, images)
        assert not ros.spin_until(lambda: done(T0 + 1), timeout=1.0, process=node)
        X = np.random.default_rng(4).uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))
        cloud_pub.publish(keypoints3d_to_cloud(T0, 'world', X, units='m'))
        assert ros.spin_until(lambda: done(T0 + 1), timeout=120, process=node), node.output()
        rule = detector_boxes(first, rig, crop_boxes(rig, X.astype(np.float32)))
        for v, cam in enumerate(rig):       # cropped around the 3D it waited for
            info = stream.result(cam.name, T0 + 1)[1]
            np.testing.assert_allclose(np.reshape(info.k, (3, 3)),
                                       expected_K(cam.K, rule[v], 32, 24), rtol=1e-12)
        # frame 3 whose previous 3D never comes: held, then processed after
        # lockstep_timeout_s (10 s) counted from frame 2's processing (seen just now)
        stream.send(T0 + 2, images)
        assert not ros.spin_until(lambda: done(T0 + 2), timeout=2.0, process=node)
        assert ros.spin_until(lambda: done(T0 + 2), timeout=120, process=node), node.output()

        def timeouts():
            counts = [int(kv.value) for msg in diagnostics for status in msg.status
                      for kv in status.values if kv.key == 'lockstep_timeouts']
            return max(counts, default=0)
        assert ros.spin_until(lambda: timeouts() == 1, timeout=120, process=node), node.output()
        assert node.stop(signal.SIGINT) == 0, node.output()


def test_lockstep_times_out_under_a_steady_stream(ros_env, setup):
    """lockstep: a keypoints3d that never comes (fusion skipped the instant) costs one
    lockstep_timeout_s, not the stream: while new frames keep replacing the pending ones,
    the detector still goes on after each timeout (it stalled for good while the wait was
    counted from the oldest pending frame, which a steady stream keeps young)."""
    from diagnostic_msgs.msg import DiagnosticArray

    rig, rig_path, first, _, images = setup
    params = dict(rig=str(rig_path), model=str(first), box=[100.0, 50.0, 400.0, 450.0],
                  track_timeout_s=3600.0, device='cpu', lockstep=True, lockstep_timeout_s=1.0)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        stream = Stream(ros, rig)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        stream.wait_matched(node)
        stream.roundtrip(T0, images, node)

        def processed():
            return {header_stamp_ns(m) for m in stream.heat[rig[0].name]} - {T0}
        stamp = T0
        for _ in range(600):          # 0.1 s apart, far faster than the timeout
            stamp += 1
            stream.send(stamp, images)
            if ros.spin_until(lambda: len(processed()) >= 3, timeout=0.1, process=node):
                break
        assert len(processed()) >= 3, (sorted(processed()), node.output())

        def timeouts():
            return max((int(kv.value) for msg in diagnostics for status in msg.status
                        for kv in status.values if kv.key == 'lockstep_timeouts'), default=0)
        assert ros.spin_until(lambda: timeouts() >= 3, timeout=30, process=node), node.output()
        assert 'lockstep: no /monet/keypoints3d for stamp' in node.output()
        assert node.stop(signal.SIGINT) == 0, node.output()


def test_batches_one_instant_and_skips_whole_instants(ros_env, setup):
    """A camera a frame ahead of another: its frames wait until the other camera has the
    same instant, then that instant is batched (never two instants in one batch: fusion
    would get half of each) and the older frame is dropped, counted; with batch_wait_ms set
    live, a camera whose frame of the instant does not come is left out of an incomplete
    batch, counted."""
    from diagnostic_msgs.msg import DiagnosticArray
    from helpers.fusion_frames import set_parameters

    rig, rig_path, first, _, images = setup
    a, b = (c.name for c in rig)
    params = dict(rig=str(rig_path), model=str(first), box=[100.0, 50.0, 400.0, 450.0],
                  track=False, device='cpu', threads=1)
    other = np.random.default_rng(5).integers(0, 255, images.shape, dtype=np.uint8)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        stream = Stream(ros, rig)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        stream.wait_matched(node)
        stream.roundtrip(T0, images, node)    # (a warm-up view lost: batch_wait_ms runs it)
        assert all(r.successful for r in set_parameters(ros, node, target='/monet/detector',
                                                        batch_wait_ms=1e9))   # never, now

        def counts():
            """Per camera the latest /diagnostics counters, and the node's batch counts."""
            latest = {}
            for msg in diagnostics:
                for status in msg.status:
                    if status.name.startswith('monet detector: '):
                        latest[status.hardware_id] = {kv.key: kv.value for kv in status.values}
            return latest

        def settled():
            """Every frame received so far processed or dropped (no warm-up retry left)."""
            c = counts()
            return len(c) == 2 and all(
                int(v['received']) == int(v['processed']) + int(v['dropped_stale'])
                for v in c.values())
        assert ros.spin_until(settled, timeout=120, process=node), (counts(), node.output())
        ros.spin_for(1.5)        # a later /diagnostics: nothing more came in
        assert settled(), counts()
        before = counts()

        def send(name, stamp, image):
            cam = rig[[c.name for c in rig].index(name)]
            stream.pubs[name][1].publish(camera_info_from_camera(cam, stamp, name))
            stream.pubs[name][0].publish(numpy_to_image_msg(image, stamp, name))

        def received(name, n):
            return lambda: int(counts().get(name, {}).get('received', 0)) >= \
                int(before[name]['received']) + n
        t1, t2, t3 = T0 + 33_000_000, T0 + 66_000_000, T0 + 99_000_000
        send(a, t1, other[0])                     # camera a at t1, b not yet
        assert ros.spin_until(received(a, 1), timeout=120, process=node), node.output()
        send(b, t2, images[1])                    # b already at t2: no instant both have
        assert ros.spin_until(received(b, 1), timeout=120, process=node), node.output()
        assert not any(stream.result(n, t) for n in (a, b) for t in (t1, t2))
        send(a, t2, images[0])                    # a reaches t2: the instant is batched
        assert ros.spin_until(lambda: stream.result(a, t2) and stream.result(b, t2),
                              timeout=120, process=node), node.output()
        ros.spin_for(0.5)
        assert stream.result(a, t1) is None       # skipped, not run with b's t2
        expected = reference(first, images, rig, detector_boxes(
            first, rig, [[100.0, 50.0, 400.0, 450.0]] * 2))
        for v, name in enumerate((a, b)):         # a's t2 frame, not its t1 frame
            np.testing.assert_allclose(image_msg_to_heatmaps(stream.result(name, t2)[0]),
                                       expected[v], atol=1e-4)

        assert all(r.successful for r in set_parameters(ros, node, target='/monet/detector',
                                                        batch_wait_ms=50.0))
        send(a, t3, images[0])                    # b's t3 never comes
        assert ros.spin_until(lambda: stream.result(a, t3), timeout=120, process=node)
        assert stream.result(b, t3) is None

        def after():
            c = counts()
            return (int(c[a]['processed']) == int(before[a]['processed']) + 2
                    and int(c[b]['processed']) == int(before[b]['processed']) + 1)
        assert ros.spin_until(after, timeout=120, process=node), (counts(), node.output())
        c = counts()
        assert int(c[a]['dropped_stale']) - int(before[a]['dropped_stale']) == 1
        assert int(c[b]['dropped_stale']) == int(before[b]['dropped_stale'])
        assert int(c[a]['batches']) - int(before[a]['batches']) == 2
        assert int(c[a]['incomplete_batches']) - int(before[a]['incomplete_batches']) == 1
        assert node.stop(signal.SIGINT) == 0, node.output()
