"""The detector takes its image transport from the recording, says when its image topics
have no publisher (log and /diagnostics), and takes tracking settings live."""
from diagnostic_msgs.msg import DiagnosticArray
from helpers.recordings import detector_recording
from helpers.ros import NodeProcess, RosHarness, newest_status
import numpy as np
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from monet_ros.io import (
    camera_info_from_camera,
    compressed_image_msg,
    image_msg_to_heatmaps,
)
from monet_ros.io.jpeg_scale import decode_for_crop
from monet_ros.models import Detector

T0 = 1_600_000_000_000_000_000


def detector_status(diagnostics, name):
    return newest_status(diagnostics, f'monet detector: {name}')


def test_compressed_only_recording_selects_compressed_and_reports_silent_topics(ros_env,
                                                                                tmp_path):
    # JPEG topics only, like the real Pose2Sim recording
    rig, params = detector_recording(tmp_path, compressed=True)
    model = params['model']
    frame = np.random.default_rng(1).integers(0, 255, (240, 320, 3), np.uint8)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        heat = ros.collect('/monet/cam0/heatmaps', Image)
        heat_info = ros.collect('/monet/cam0/camera_info', CameraInfo)
        # cam1 has a raw publisher only: the report names the transport that would work
        raw_cam1 = ros.publisher('/cam1/image_raw', Image)

        def reported():   # once the detector has discovered the raw publisher too
            status = detector_status(diagnostics, 'cam1')
            return status is not None and 'transport:=raw' in status.message
        assert ros.spin_until(reported, timeout=60, process=node), node.output()
        cam0 = detector_status(diagnostics, 'cam0').message
        cam1 = detector_status(diagnostics, 'cam1').message
        assert 'no publisher on /cam0/image_raw/compressed' in cam0
        assert ('no publisher on /cam1/image_raw/compressed (but /cam1/image_raw has one: '
                'transport:=raw)') in cam1
        assert raw_cam1.get_subscription_count() == 0      # it did not subscribe raw
        # a compressed publisher: the detector runs on its frames
        pub = ros.publisher('/cam0/image_raw/compressed', CompressedImage)
        info = ros.publisher('/cam0/camera_info', CameraInfo)
        ros.wait_for_subscribers(pub, process=node)
        for _ in range(60):
            info.publish(camera_info_from_camera(rig[0], T0, 'cam0_optical'))
            pub.publish(compressed_image_msg(frame, T0, 'cam0_optical'))
            if ros.spin_until(lambda: heat, timeout=1.0, process=node):
                break
        assert heat, node.output()
        assert ros.spin_until(lambda: heat_info, timeout=10, process=node), node.output()
        assert node.stop() == 0, node.output()
    output = node.output()
    assert output.count('no publisher on /cam0/image_raw/compressed') == 1, output
    # the 320x240 JPEG's crop shrinks 2.5x to the 128x96 input: decoded at 1/2 (jpeg_scale),
    # the heatmaps are the core's on that decode and their camera the full frame's crop
    detector = Detector.from_checkpoint(model, device='cpu', precision='auto')  # the node's
    box = detector.boxes_for(rig[:1])[0]
    data = compressed_image_msg(frame, T0, 'cam0_optical').data
    image, layout, small, small_box, s = decode_for_crop(data, rig[0], box, (128, 96))
    assert s == 2
    expected, _ = detector.predict([image], [small], small_box[None], keep_aspect=False,
                                   encodings=[layout])
    np.testing.assert_allclose(image_msg_to_heatmaps(heat[-1]), expected[0], atol=1e-5)
    h, w = detector.heatmap_size
    np.testing.assert_allclose(np.reshape(heat_info[-1].k, (3, 3)),
                               rig[0].crop(box, (w, h)).K, rtol=1e-12, atol=1e-9)
    assert 'Traceback' not in output


def test_tracking_parameters_are_live_the_rest_read_only(ros_env, tmp_path):
    _, params = detector_recording(tmp_path, compressed=True)

    def double(name, value):
        return Parameter(name=name, value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=value))

    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        setter = ros.node.create_client(SetParameters, '/monet/detector/set_parameters')
        getter = ros.node.create_client(GetParameters, '/monet/detector/get_parameters')
        assert ros.spin_until(lambda: setter.service_is_ready() and getter.service_is_ready(),
                              timeout=60, process=node), node.output()
        results = []
        for param in (double('track_margin', 0.5), double('track_margin', -1.0),
                      double('debug_image_rate_hz', 5.0)):
            future = setter.call_async(SetParameters.Request(parameters=[param]))
            assert ros.spin_until(future.done, timeout=30, process=node)
            results.append(future.result().results[0])
        future = getter.call_async(GetParameters.Request(names=['track_margin',
                                                               'debug_image_rate_hz']))
        assert ros.spin_until(future.done, timeout=30, process=node)
        values = [v.double_value for v in future.result().values]
        assert node.stop() == 0, node.output()
    assert results[0].successful, results[0].reason
    assert not results[1].successful                      # out of range (>= 0)
    assert not results[2].successful                      # read-only
    assert values == [0.5, 2.0]
