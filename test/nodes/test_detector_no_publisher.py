"""The detector's "no publisher" report (nodes.detector.DetectorNode.no_publisher): a camera
that loses its publisher while another still publishes is warned; when every image topic
loses its publishers together (a recording that ended: `monet pipeline`'s player finished)
it is said at info level, not warned. /diagnostics name the silent topic either way."""
from diagnostic_msgs.msg import DiagnosticArray
from helpers.recordings import detector_recording
from helpers.ros import NodeProcess, RosHarness, newest_status
from sensor_msgs.msg import Image


def silent(diagnostics, name):
    """Whether the last /diagnostics status of camera `name` says it has no publisher."""
    status = newest_status(diagnostics, f'monet detector: {name}')
    return status is not None and f'no publisher on /{name}/image_raw' in status.message


def test_a_lost_camera_is_warned_an_ended_recording_is_not(ros_env, tmp_path):
    _, params = detector_recording(tmp_path)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pubs = {name: ros.publisher(f'/{name}/image_raw', Image) for name in ('cam0', 'cam1')}
        for pub in pubs.values():
            ros.wait_for_subscribers(pub, timeout=60, process=node)
        # both publish: neither is reported
        assert ros.spin_until(lambda: len(diagnostics) >= 5, timeout=60, process=node)
        assert not silent(diagnostics, 'cam0') and not silent(diagnostics, 'cam1')
        # cam1's publisher goes while cam0's stays: a camera lost
        ros.node.destroy_publisher(pubs.pop('cam1'))
        assert ros.spin_until(lambda: silent(diagnostics, 'cam1'), timeout=60,
                              process=node), node.output()
        # then cam0's too: no image topic has a publisher any more (the source ended)
        ros.node.destroy_publisher(pubs.pop('cam0'))
        assert ros.spin_until(lambda: silent(diagnostics, 'cam0'), timeout=60,
                              process=node), node.output()
        assert node.stop() == 0, node.output()
    lines = node.output().splitlines()
    about = {name: [line for line in lines if f'no publisher on /{name}/image_raw' in line]
             for name in ('cam0', 'cam1')}
    assert len(about['cam1']) == 1 and '[WARN]' in about['cam1'][0], about
    assert len(about['cam0']) == 1 and '[WARN]' not in about['cam0'][0], about
    assert '[INFO]' in about['cam0'][0] and 'recording ended' in about['cam0'][0], about
