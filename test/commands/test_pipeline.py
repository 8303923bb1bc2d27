"""`monet pipeline` as a user runs it: one process, every frame fused, clean exits."""
import signal
import sys

from helpers.recordings import noise_recording, small_checkpoint
from helpers.ros import NodeProcess, RosHarness
from sensor_msgs.msg import PointCloud2

from monet_ros.geometry import save_rig
from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns


def pipeline(env, *args):
    argv = [sys.executable, '-m', 'monet_ros.cli', 'pipeline', *map(str, args)]
    return NodeProcess('pipeline', env, argv=argv)


def test_lockstep_publishes_keypoints3d_for_every_frame(ros_env, tmp_path):
    rig, stamps = noise_recording(tmp_path / 'rec', frames=6)
    model = small_checkpoint(tmp_path / 'model.pt')
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        with pipeline(ros_env, '--bag', tmp_path / 'rec', '--model', model, '--lockstep',
                      '--start-delay', 2.0) as proc:
            ros.spin_until(lambda: len(clouds) >= len(stamps), timeout=120, process=None)
            assert proc.wait(timeout=60) == 0, proc.output()
    assert [header_stamp_ns(c) for c in clouds] == stamps, proc.output()
    for cloud in clouds:
        assert cloud.header.frame_id == 'world'
        assert cloud_to_keypoints3d(cloud)['X'].shape == (14, 3)
    # the final summary line, and a quiet exit (no callback failing under a destroyed node)
    assert f'frames {len(stamps)} fused of {len(stamps)} played' in proc.output()
    assert 'never retrieved' not in proc.output()


def test_sigterm_and_sigint_exit_zero(ros_env, tmp_path):
    noise_recording(tmp_path / 'rec', cameras=2, frames=3)
    model = small_checkpoint(tmp_path / 'model.pt')
    for sig in (signal.SIGTERM, signal.SIGINT):
        with RosHarness(ros_env) as ros:
            clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
            with pipeline(ros_env, '--bag', tmp_path / 'rec', '--model', model,
                          '--loop', '--rate', 2.0) as proc:
                assert ros.spin_until(lambda c=clouds: c, timeout=120, process=proc), \
                    proc.output()
                assert proc.stop(sig) == 0, proc.output()
                assert 'never retrieved' not in proc.output()


def test_bad_arguments_fail_at_start(ros_env, tmp_path):
    rig, _ = noise_recording(tmp_path / 'rec', cameras=2, frames=1)
    model = small_checkpoint(tmp_path / 'model.pt')
    save_rig(tmp_path / 'one.yaml', rig[:1])
    cases = [
        (('--bag', tmp_path / 'rec', '--model', tmp_path / 'missing.pt'),
         'missing.pt: checkpoint file not found'),
        (('--bag', tmp_path / 'rec', '--model', model, '--rig', tmp_path / 'one.yaml'),
         "parameter 'cameras': needs at least 2 cameras"),
        (('--bag', tmp_path / 'rec', '--model', model, '--cameras', 'cam0', 'cam5'),
         "unknown camera 'cam5'"),
    ]
    for args, message in cases:
        with pipeline(ros_env, *args) as proc:
            assert proc.wait(timeout=90) == 2, proc.output()
            assert message in proc.output()
