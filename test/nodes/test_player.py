"""The player executable replays a recording: order, bytes, stamps, rate, offset, /clock."""
import signal
import time

from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
import pytest
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image

from monet_ros.io import BagWriter, header_stamp_ns, image_to_numpy

T0 = 1_600_000_000_000_000_000
PERIOD = 50_000_000   # 20 Hz


@pytest.fixture
def small_bag(tmp_path):
    """2 cameras x 8 frames of 32x24 images whose pixels encode (camera, frame)."""
    rig = [cam.replace(width=32, height=24) for cam in ring_rig(2)]
    path = tmp_path / 'small'
    with BagWriter(path) as writer:
        for i in range(8):
            for v, cam in enumerate(rig):
                stamp = T0 + i * PERIOD
                image = np.full((24, 32, 3), (v, i, 7), np.uint8)
                writer.write_image(f'/{cam.name}/image_raw', stamp, image, cam.name)
                writer.write_camera_info(f'/{cam.name}/camera_info', stamp, cam, cam.name)
    return path


def collect_all(ros):
    images = {n: ros.collect(f'/{n}/image_raw', Image, 50) for n in ('cam0', 'cam1')}
    infos = ros.collect('/cam0/camera_info', CameraInfo, 50)
    ros.collect('/cam1/camera_info', CameraInfo, 50)   # the player waits for every topic
    clock = ros.collect('/clock', Clock, 50)
    return images, infos, clock


def test_replays_every_message_in_order_with_its_bytes(ros_env, small_bag):
    params = dict(bag=str(small_bag), rate=2.0, wait_for_subscribers=1,
                  start_delay_s=1.0, shutdown_when_done=True)
    with RosHarness(ros_env) as ros:
        images, infos, clock = collect_all(ros)
        def last_clock_ns():
            return clock[-1].clock.sec * 10**9 + clock[-1].clock.nanosec if clock else None

        with NodeProcess('player', ros_env, params) as player:
            # every topic, not a pause for the stragglers: messages of different topics
            # arrive in any order
            assert ros.spin_until(lambda: all(len(v) == 8 for v in images.values())
                                  and len(infos) == 8 and last_clock_ns() == T0 + 7 * PERIOD,
                                  timeout=60, process=None), player.output()
            code = player.wait(timeout=60)
            assert code == 0, player.output()
    for v, name in enumerate(('cam0', 'cam1')):
        stamps = [header_stamp_ns(m) for m in images[name]]
        assert stamps == [T0 + i * PERIOD for i in range(8)]
        pixels = [tuple(image_to_numpy(m)[0, 0]) for m in images[name]]
        assert pixels == [(v, i, 7) for i in range(8)]
    np.testing.assert_allclose(np.asarray(infos[0].k).reshape(3, 3), ring_rig(2)[0].K)
    clock_ns = [c.clock.sec * 10**9 + c.clock.nanosec for c in clock]
    assert clock_ns == sorted(clock_ns) and clock_ns[0] == T0 and clock_ns[-1] == T0 + 7 * PERIOD


def test_start_offset_loop_and_sigterm(ros_env, small_bag):
    params = dict(bag=str(small_bag), rate=4.0, loop=True, start_offset_s=0.2,
                  topics=['/cam0/image_raw'], clock=False, wait_for_subscribers=1,
                  start_delay_s=1.0)
    with RosHarness(ros_env) as ros:
        images = ros.collect('/cam0/image_raw', Image, 50)
        with NodeProcess('player', ros_env, params) as player:
            assert ros.spin_until(lambda: len(images) >= 9, timeout=60, process=player)
            assert player.stop(signal.SIGTERM) == 0, player.output()
    stamps = [(header_stamp_ns(m) - T0) // PERIOD for m in images]
    pixels = [int(image_to_numpy(m)[0, 0, 1]) for m in images]
    # frames 4..7 (0.2 s = 4 frames skipped), then again from frame 4 on every pass ...
    assert pixels[:9] == [4, 5, 6, 7, 4, 5, 6, 7, 4]
    # ... with stamps shifted by the length of a pass (4 frames) so that time runs on
    assert stamps[:9] == [4, 5, 6, 7, 8, 9, 10, 11, 12]


def test_bad_bag_and_unknown_topic_fail_at_start(ros_env, small_bag, tmp_path):
    with NodeProcess('player', ros_env, {'bag': str(tmp_path / 'missing')}) as player:
        assert player.wait(timeout=60) == 2
        assert 'missing' in player.output()
    params = {'bag': str(small_bag), 'topics': ['/nope']}
    with NodeProcess('player', ros_env, params) as player:
        assert player.wait(timeout=60) == 2
        assert "parameter 'topics': '/nope' is not in" in player.output()



def test_waits_for_subscribers_bounded_then_plays(ros_env, small_bag):
    """No subscriber: the player gives up after wait_for_subscribers_s and plays anyway;
    with subscribers it starts once every image topic is matched (and start_delay_s, by
    default 1 s, has passed: a best-effort subscriber matches the player a moment after the
    player matches it, and would lose the first frames)."""
    # rate 1 (not 0, a burst): the point is the waiting; a burst of 8 frames may overrun
    # the publishers' 5-deep history before a reliable reader has acknowledged
    params = dict(bag=str(small_bag), rate=1.0, wait_for_subscribers=1,
                  wait_for_subscribers_s=1.0, shutdown_when_done=True)
    with NodeProcess('player', ros_env, params) as player:
        assert player.wait(timeout=60) == 0, player.output()
    assert 'playing without waiting longer (wait_for_subscribers_s=1.0)' in player.output()
    assert 'played 32 messages' in player.output()
    params['wait_for_subscribers_s'] = 0.0      # wait as long as it takes
    with RosHarness(ros_env) as ros, NodeProcess('player', ros_env, params) as player:
        ros.spin_for(3.0)
        assert player.running() and 'played' not in player.output()
        images, _, _ = collect_all(ros)
        assert ros.spin_until(lambda: all(len(v) == 8 for v in images.values()), timeout=60,
                              process=None), player.output()
        assert player.wait(timeout=60) == 0, player.output()


def test_sigint_twice_exits_zero_without_traceback(ros_env, small_bag):
    params = dict(bag=str(small_bag), rate=1.0, loop=True, wait_for_subscribers=0)
    with RosHarness(ros_env) as ros, NodeProcess('player', ros_env, params) as player:
        images, _, _ = collect_all(ros)
        assert ros.spin_until(lambda: images['cam0'], timeout=60, process=player)
        player.process.send_signal(signal.SIGINT)
        assert player.stop(signal.SIGINT) == 0, player.output()
    assert 'Traceback' not in player.output() and 'KeyboardInterrupt' not in player.output()


def test_waits_for_the_fusion_topics_too(ros_env, small_bag):
    """wait_for_topics: the player also waits for subscribers of `{camera}/heatmaps` (in its
    namespace: /monet/cam0/heatmaps, /monet/cam1/heatmaps), i.e. for the fusion node."""
    params = dict(bag=str(small_bag), rate=1.0, wait_for_subscribers=1,
                  wait_for_subscribers_s=0.0, wait_for_topics=['{camera}/heatmaps'],
                  shutdown_when_done=True)
    with RosHarness(ros_env) as ros, NodeProcess('player', ros_env, params) as player:
        images, _, _ = collect_all(ros)
        ros.spin_for(4.0)
        assert player.running() and 'played' not in player.output(), player.output()
        assert not images['cam0']
        for cam in ('cam0', 'cam1'):
            ros.collect(f'/monet/{cam}/heatmaps', Image)
        assert ros.spin_until(lambda: all(len(v) == 8 for v in images.values()), timeout=60,
                              process=None), player.output()
        assert player.wait(timeout=60) == 0, player.output()


def test_lockstep_waits_for_keypoints3d_and_announces_each_frame(ros_env, small_bag):
    """lockstep: frame i+1 goes out only after a keypoints3d stamped frame i arrived;
    announce_frames: played_frames carries [stamp, wall time] before each frame's image and
    [] at the end of the replay."""
    from sensor_msgs.msg import PointCloud2
    from std_msgs.msg import Int64MultiArray

    from monet_ros.nodes.qos import STREAM_OUT

    params = dict(bag=str(small_bag), rate=0.0, topics=['/cam0/image_raw'], clock=False,
                  wait_for_subscribers=1, wait_for_topics=['played_frames'],
                  start_delay_s=0.5, lockstep=True, lockstep_timeout_s=300.0,
                  announce_frames=True)
    with RosHarness(ros_env) as ros:
        images = ros.collect('/cam0/image_raw', Image, 50)
        frames = ros.collect('/monet/played_frames', Int64MultiArray, STREAM_OUT)
        fused = ros.publisher('/monet/keypoints3d', PointCloud2, STREAM_OUT)
        start_ns = time.time_ns()
        with NodeProcess('player', ros_env, params) as player:
            for i in range(8):
                assert ros.spin_until(lambda i=i: len(frames) > i, timeout=60,
                                      process=player), player.output()
                if i < 3:      # nothing more until its keypoints3d is published
                    ros.spin_for(0.3)
                    assert len(frames) == i + 1, [list(f.data) for f in frames]
                cloud = PointCloud2()
                cloud.header.stamp.sec, cloud.header.stamp.nanosec = divmod(
                    int(frames[i].data[0]), 10**9)
                fused.publish(cloud)
            assert ros.spin_until(lambda: len(frames) == 9 and len(images) == 8, timeout=60,
                                  process=player), player.output()
            assert player.stop(signal.SIGTERM) == 0, player.output()
    end_ns = time.time_ns()
    expected = [T0 + i * PERIOD for i in range(8)]
    assert [int(f.data[0]) for f in frames[:8]] == expected
    assert [header_stamp_ns(m) for m in images] == expected
    walls = [int(f.data[1]) for f in frames[:8]]
    assert walls == sorted(walls) and start_ns <= walls[0] and walls[-1] <= end_ns
    assert list(frames[8].data) == []
