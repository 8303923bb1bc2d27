"""Every message the fusion node receives ends in exactly one counter (issue 25 item 13), with
the real executable over DDS: heatmaps that never get a camera_info are unpaired (not lost
from the counts), a repeated heatmap is repeated, a camera_info without heatmaps is an
unpaired camera_info, and the stop summary says the same as /diagnostics."""
import signal

from diagnostic_msgs.msg import DiagnosticArray
from helpers.fusion_frames import Frame, fusion_statuses, reliable_publishers
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
from sensor_msgs.msg import PointCloud2

from monet_ros.geometry import save_rig
from monet_ros.io import header_stamp_ns
from monet_ros.nodes.fusion import OUTCOMES

FRAMES = 7


def camera_values(diagnostics, name):
    for msg in reversed(diagnostics):
        for status in msg.status:
            if status.name == f'monet fusion: {name}':
                return {kv.key: kv.value for kv in status.values}
    return None


def test_every_received_message_ends_in_one_counter(ros_env, tmp_path):
    rig = ring_rig(3)
    path = tmp_path / 'rig.yaml'
    save_rig(path, rig)
    rng = np.random.default_rng(3)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], (14, 3))
    frames = [Frame(rig, X, i, rng, noise=0.0) for i in range(FRAMES)]
    # max_queue_ms 0: every frame fused however long the burst below waits in the queue
    # (a loaded machine); the stale outcome has its own test (test_fusion_stale.py)
    # silent_after_s 5: cam0 (heatmaps only) is let go after it, and a stall of the test's
    # publishing loop on a loaded machine shorter than it cannot make cam1 or cam2 silent
    # (their frames would then be dropped below min_views, the late views counted late)
    params = dict(rig=str(path), skeleton='human14', input_reliability='reliable',
                  timeout_s=60.0, silent_after_s=5.0, diagnostics_period_s=0.2,
                  max_queue_ms=0.0)
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pubs = reliable_publishers(ros, [c.name for c in rig], node)
        # cam0: heatmaps only, never a camera_info; they are let go as unpaired once
        # silent_after_s passed (cam0 is silent then, the others' frames do not wait for it)
        for frame in frames:
            pubs['cam0'][0].publish(frame.messages[0][1])
        assert ros.spin_until(lambda: (camera_values(diagnostics, 'cam0') or {}).get(
            'unpaired') == str(FRAMES), timeout=60, process=node), node.output()
        for frame in frames:
            for name, heat, info in frame.messages[1:]:
                pubs[name][1].publish(info)
                pubs[name][0].publish(heat)
        _, heat, info = frames[0].messages[2]
        pubs['cam2'][1].publish(info)         # cam2 sends frame 0 again: a repeated stamp
        pubs['cam2'][0].publish(heat)
        _, _, info = Frame(rig, X, FRAMES, rng, noise=0.0).messages[1]
        pubs['cam1'][1].publish(info)         # a camera_info whose heatmaps never come

        expected = {'cam0': dict(received=FRAMES, unpaired=FRAMES),
                    'cam1': dict(received=FRAMES, fused=FRAMES),
                    'cam2': dict(received=FRAMES + 1, fused=FRAMES, repeated=1)}
        info_expected = {'cam0': dict(camera_info_received=0),
                         'cam1': dict(camera_info_received=FRAMES + 1,
                                      camera_info_paired=FRAMES, camera_info_unpaired=1),
                         'cam2': dict(camera_info_received=FRAMES + 1,
                                      camera_info_paired=FRAMES + 1)}

        def want(name):
            counts = dict.fromkeys(('received',) + OUTCOMES, 0)
            counts.update(camera_info_received=0, camera_info_paired=0, camera_info_unpaired=0,
                          camera_info_waiting=0)
            return {k: str(v) for k, v in {**counts, **expected[name],
                                           **info_expected[name]}.items()}

        def settled():
            values = {c.name: camera_values(diagnostics, c.name) for c in rig}
            return all(v is not None and {k: v.get(k) for k in want(n)} == want(n)
                       for n, v in values.items())
        ok = ros.spin_until(settled, timeout=60, process=node)
        values = {c.name: camera_values(diagnostics, c.name) for c in rig}
        # on failure: only the counters that differ, {camera: {counter: (got, wanted)}}
        differ = {n: {k: ((v or {}).get(k), w) for k, w in want(n).items()
                      if (v or {}).get(k) != w} for n, v in values.items()}
        assert ok, ({n: d for n, d in differ.items() if d}, node.output())
        assert node.stop(signal.SIGINT) == 0, node.output()

    assert sorted(header_stamp_ns(c) for c in clouds) == [f.stamp for f in frames]
    for name, v in values.items():
        # received = the sum of the outcomes, and each count as sent
        assert int(v['received']) == sum(int(v[k]) for k in OUTCOMES), (name, v)
        assert int(v['camera_info_received']) == sum(
            int(v[f'camera_info_{k}']) for k in ('paired', 'unpaired', 'waiting'))
    assert 'heatmaps without a camera_info' in \
        fusion_statuses(diagnostics)['monet fusion: cam0'].message
    # the stop summary: one line per camera, the same counts
    output = node.output()
    assert (f'cam0: {FRAMES} heatmaps received: fused 0, bad_messages 0, unpaired {FRAMES}, '
            'repeated 0, late 0, dropped 0, stale 0, waiting 0; 0 camera_info received') in output
    assert (f'cam2: {FRAMES + 1} heatmaps received: fused {FRAMES}, bad_messages 0, '
            'unpaired 0, repeated 1') in output
