"""A fusion node that falls behind skips stale frames instead of queueing them (issue 26:
16 cameras on 2 cores queued half a second in fusion's input): a frame whose input waited
longer than max_queue_ms is not fused but counted stale per camera, received = the sum of
the outcomes still holds, the first one is logged once, and setting max_queue_ms to 0 while
running fuses every frame again.

Deterministic without overloading anything: max_queue_ms 1e-3 (1 us) is shorter than any
message's way from the middleware's reception (MessageInfo received_timestamp) to its
Python callback, so every frame is stale; 0 switches the check off."""
import signal

from diagnostic_msgs.msg import DiagnosticArray
from helpers.fusion_frames import (
    Frame,
    fusion_statuses,
    reliable_publishers,
    run_frames,
    set_parameters,
)
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
from sensor_msgs.msg import PointCloud2

from monet_ros.geometry import save_rig
from monet_ros.io import header_stamp_ns
from monet_ros.nodes.fusion import OUTCOMES

STALE_FRAMES = 5


def values_of(diagnostics, name):
    status = fusion_statuses(diagnostics).get(name)
    return {kv.key: kv.value for kv in status.values} if status else {}


def test_frames_queued_too_long_are_skipped_and_counted_stale(ros_env, tmp_path):
    rig = ring_rig(3)
    path = tmp_path / 'rig.yaml'
    save_rig(path, rig)
    rng = np.random.default_rng(5)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))
    frames = [Frame(rig, X, i, rng, noise=0.0) for i in range(STALE_FRAMES + 2)]
    params = dict(rig=str(path), skeleton='human14', input_reliability='reliable',
                  timeout_s=60.0, diagnostics_period_s=0.2, max_queue_ms=1e-3)
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pubs = reliable_publishers(ros, [c.name for c in rig], node)
        for frame in frames[:STALE_FRAMES]:
            for name, heat, info in frame.messages:
                pubs[name][1].publish(info)
                pubs[name][0].publish(heat)

        def all_stale():
            return all(values_of(diagnostics, f'monet fusion: {c.name}').get('stale')
                       == str(STALE_FRAMES) for c in rig)
        assert ros.spin_until(all_stale, timeout=60, process=node), (
            {c.name: values_of(diagnostics, f'monet fusion: {c.name}') for c in rig},
            node.output())
        stale_values = {c.name: values_of(diagnostics, f'monet fusion: {c.name}')
                        for c in rig}
        summary = values_of(diagnostics, 'monet fusion')
        assert not clouds, 'a stale frame was fused'

        results = set_parameters(ros, node, max_queue_ms=0.0)      # off, while running
        assert all(r.successful for r in results), [r.reason for r in results]
        got = run_frames(ros, node, pubs, frames[STALE_FRAMES:], clouds)
        assert node.stop(signal.SIGINT) == 0, node.output()

    assert summary['stale_frames'] == str(STALE_FRAMES) and summary['frames'] == '0', summary
    for name, v in stale_values.items():
        assert v['received'] == str(STALE_FRAMES) and v['fused'] == '0', (name, v)
        assert int(v['received']) == sum(int(v[k]) for k in OUTCOMES), (name, v)
    # the frames sent after the switch are fused; no earlier (stale) stamp ever came out
    fused = {header_stamp_ns(c) for c in clouds}
    assert {f.stamp for f in frames[STALE_FRAMES:]} <= set(got) and \
        fused <= {f.stamp for f in frames[STALE_FRAMES:]}, sorted(fused)
    output = node.output()
    assert output.count('falling behind') == 1, output
    # the stop summary counts the same (one line per camera)
    assert output.count(f'dropped 0, stale {STALE_FRAMES}, waiting') == len(rig), output
