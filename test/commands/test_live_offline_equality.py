"""One crop rule live and offline: `monet pipeline --lockstep` (real nodes over DDS) and
`monet process` give the same 3D for the same recording and model, frame by frame."""
import sys

from helpers.recordings import noise_recording, small_checkpoint
from helpers.ros import NodeProcess, RosHarness
import numpy as np
from sensor_msgs.msg import PointCloud2

from monet_ros.cli import main as monet
from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns, open_bag


def test_process_and_lockstep_pipeline_agree_within_a_millimetre(ros_env, tmp_path):
    rig, stamps = noise_recording(tmp_path / 'rec', cameras=4, frames=8, seed=3)
    model = small_checkpoint(tmp_path / 'model.pt', seed=1)
    # a low confidence threshold so that the random network triangulates its peaks and the
    # crops follow them (tracking engaged from the second frame on)
    assert monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out',
                  str(tmp_path / 'out'), '--confidence-threshold', '0', '--quiet']) == 0
    offline = {m.stamp_ns: cloud_to_keypoints3d(m.msg)['X'] for m in
               open_bag(tmp_path / 'out').messages(['/monet/keypoints3d'])}
    assert sorted(offline) == stamps
    tracked = [np.isfinite(X).all(axis=1).sum() >= 3 for X in offline.values()]
    assert sum(tracked[:-1]) >= 3, 'the tracked rule was not exercised'
    argv = [sys.executable, '-m', 'monet_ros.cli', 'pipeline', '--bag', str(tmp_path / 'rec'),
            '--model', str(model), '--lockstep', '--start-delay', '2.0', '--quiet',
            '--confidence-threshold', '0']
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        with NodeProcess('pipeline', ros_env, argv=argv) as proc:
            ros.spin_until(lambda: len(clouds) >= len(stamps), timeout=180, process=None)
            assert proc.wait(timeout=90) == 0, proc.output()
    live = {header_stamp_ns(c): cloud_to_keypoints3d(c)['X'] for c in clouds}
    assert sorted(live) == stamps, proc.output()
    for stamp in stamps:
        a, b = offline[stamp], live[stamp]
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=f'stamp {stamp}')
        diff = np.abs(a - b)[np.isfinite(a)]
        assert diff.size == 0 or diff.max() <= 1e-3, (stamp, diff.max())
