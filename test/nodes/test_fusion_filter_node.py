"""The fusion executable's live filter: switched on with a parameter service call, filtered
keypoints on keypoints3d and the raw ones on keypoints3d_raw, reset on a stamp jump."""
from helpers.fusion_frames import Frame, publishers, run_frames, set_parameters
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2

from monet_ros.geometry import save_rig
from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns
from monet_ros.nodes.qos import STREAM_OUT
from monet_ros.temporal.live import LiveFilter, LiveFilterConfig


@pytest.fixture
def rig_file(tmp_path):
    rig = ring_rig(4)
    path = tmp_path / 'rig.yaml'
    save_rig(path, rig, frame_id='world')
    return rig, path


def by_stamp(clouds):
    return {header_stamp_ns(c): cloud_to_keypoints3d(c, units='m') for c in clouds}


def test_filter_switched_on_live_publishes_filtered_and_raw(ros_env, rig_file):
    rig, path = rig_file
    rng = np.random.default_rng(31)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(14, 3))
    # noisy peaks (0.4 heatmap px) every frame; frame 9 jumps 6 s ahead (a replay loop's
    # restart looks the same to the filter), frame 10 follows it
    indices = list(range(9)) + [200, 201]
    frames = [Frame(rig, X, i, rng, noise=0.4) for i in indices]
    # every frame fused whole, however loaded the machine (run_frames resends until fused)
    params = dict(rig=str(path), timeout_s=60.0, max_queue_ms=0.0, input_reliability='reliable')
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, STREAM_OUT)
        raw = ros.collect('/monet/keypoints3d_raw', PointCloud2, STREAM_OUT)
        pubs = publishers(ros, [c.name for c in rig])
        for heat_pub, info_pub in pubs.values():
            ros.wait_for_subscribers(heat_pub, timeout=60, process=node)
            ros.wait_for_subscribers(info_pub, timeout=60, process=node)
        run_frames(ros, node, pubs, frames[:1], clouds)             # filter off
        results = set_parameters(ros, node, filter=True)
        assert all(r.successful for r in results), [r.reason for r in results]
        refused = set_parameters(ros, node, filter_gate=-1.0)[0]
        run_frames(ros, node, pubs, frames[1:], clouds)
        stamps = [f.stamp for f in frames]
        assert ros.spin_until(lambda: set(stamps[1:]) <= set(by_stamp(raw)), timeout=10,
                              process=node), node.output()
        assert node.stop() == 0, node.output()
    assert not refused.successful and 'filter_gate' in refused.reason
    filtered, unfiltered = by_stamp(clouds), by_stamp(raw)
    assert stamps[0] not in unfiltered, 'keypoints3d_raw published with the filter off'
    # the filter, run here over the raw keypoints the node published, gives its output
    reference = LiveFilter(LiveFilterConfig(filter=True))
    for i, stamp in enumerate(stamps[1:], start=1):
        got, rawk = filtered[stamp], unfiltered[stamp]
        expected, _ = reference.update(stamp, rawk['X'].astype(np.float64))
        np.testing.assert_allclose(got['X'], expected, atol=1e-5)
        np.testing.assert_array_equal(got['num_views'], rawk['num_views'])
        np.testing.assert_array_equal(got['confidence'], rawk['confidence'])
        change = np.abs(got['X'] - rawk['X']).max()
        if i in (1, 9):      # the first filtered frame and the one after the jump: restarts
            assert change == 0, (i, change)
        else:                # filtered: differs from the noisy raw keypoints
            assert change > 1e-4, (i, change)
    assert reference.resets == 1
    # smoother than raw: the frame-to-frame motion of a still subject is smaller
    steady = stamps[2:9]
    jitter = [np.abs(np.diff([d[s]['X'] for s in steady], axis=0)).mean()
              for d in (filtered, unfiltered)]
    assert jitter[0] < jitter[1], jitter
