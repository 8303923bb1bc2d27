"""Bounded state under a long run (kind 9), clean stops on SIGINT / SIGTERM, values that
reach the nodes through the same typed configs (topic templates, skeleton vs model)."""
import os
import signal
import subprocess
import sys
import time

from helpers.reliability import outcome, record
import numpy as np
import pytest

from monet_ros.commands.pipeline import SUMMARY_SAMPLES, Summary
from monet_ros.config import ConfigError
from monet_ros.sync import StampSynchronizer


class Result:
    """What the summary reads of a fusion result: 2 keypoints, the second not fused."""

    def __init__(self, error):
        self.reprojection_error = np.array([error, np.nan])
        self.X = np.array([[0.0, 0.0, 1.0], [np.nan, np.nan, np.nan]])
        self.num_views = np.array([2, 0])


def test_pipeline_summary_stays_bounded_over_a_long_loop():
    """Kind 9: `monet pipeline --loop` kept every per-frame sample; a day at 30 fps is 2.6 M.
    The samples kept are bounded, the whole-run figures are running totals (checked against
    a direct computation)."""
    summary = Summary()
    rng = np.random.default_rng(0)
    errors = rng.uniform(0.5, 3.0, 50_000)
    for k, error in enumerate(errors):
        summary.on_image('/cam0/image_raw', k, time.monotonic())
        summary.on_fused(k, Result(error))
    assert len(summary.latencies) == len(summary.errors) == SUMMARY_SAMPLES
    assert len(summary.published) <= 10_000
    line = summary.line()
    assert 'frames 50000 fused of 50000 played' in line
    assert f'reprojection error {errors.mean():5.2f} px' in line
    record('monet pipeline (state)', 'right result')


def test_synchronizer_state_is_bounded():
    sync = StampSynchronizer(['a', 'b'], max_pending=8, history=16, timeout_s=1e9)
    for k in range(5000):
        sync.add('a', k * 1000, k)              # b never comes
    assert len(sync.pending) <= 8 and all(len(r) <= 16 for r in sync.recent.values())
    assert len(sync.released) <= 16 and sync.stats.dropped == 5000 - len(sync.pending)
    record('StampSynchronizer (state)', 'right result')


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_synth_stopped_by_a_signal_exits_0_and_leaves_nothing(repo_root, tmp_path, signum):
    """SIGINT / SIGTERM at any moment: exit 0, no traceback, no half-written output (the
    rerun is not refused)."""
    out = tmp_path / 'out'
    env = dict(os.environ, PYTHONPATH=str(repo_root))
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    proc = subprocess.Popen(
        [sys.executable, '-m', 'monet_ros.cli', 'synth', '--out', str(out), '--cameras', '2',
         '--frames', '5000', '--width', '64', '--height', '48'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not any(tmp_path.glob('.out.*')):
        time.sleep(0.1)                          # wait until it writes
    time.sleep(0.5)
    proc.send_signal(signum)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert 'Traceback' not in stderr
    assert list(tmp_path.iterdir()) == []
    record('monet synth (signal)', 'right result')


def test_topic_templates_with_unknown_fields_are_named():
    """A topic template with an unknown {field} was a KeyError when the node subscribed."""
    from monet_ros.nodes.detector import DetectorConfig
    from monet_ros.nodes.fusion import FusionNodeConfig

    for cls, field in ((FusionNodeConfig, 'heatmap_topic'),
                       (FusionNodeConfig, 'camera_info_topic'),
                       (DetectorConfig, 'image_topic'),
                       (DetectorConfig, 'camera_info_topic')):
        for template in ('/monet/{cam}/x', '/{camera}/{0}', '/{camera!r}/x', '/{camera'):
            with pytest.raises(ConfigError, match=field) as caught:
                cls(**{field: template})
            assert template in str(caught.value)
            record('node topic templates', 'clear error')
        assert getattr(cls(**{field: '/rig/{camera}/x'}), field) == '/rig/{camera}/x'
        record('node topic templates', 'right result')


def test_pipeline_refuses_a_skeleton_that_is_not_the_models(process_inputs, monkeypatch,
                                                            tmp_path, ros_domain_id):
    """Kind 8: the pipeline ran with every heatmap counted bad; now it stops at start naming
    the skeleton and the model."""
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain_id))
    monkeypatch.setenv('ROS_LOG_DIR', str(tmp_path / 'ros_log'))
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    rec, model = process_inputs
    _, _, err = outcome('pipeline', ['pipeline', '--bag', rec, '--model', model,
                                     '--skeleton', 'quadruped13', '--quiet'],
                        names=('skeleton',), expect='clear error')
    assert 'quadruped13' in err and str(model) in err
