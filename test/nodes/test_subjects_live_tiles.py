"""A discovery_tiles mismatch between the detector and fusion nodes (subjects 2), live over
DDS with real nodes in their own processes on the two-subject blob recording of
test_subjects_live (4 cameras, 12 frames, 96x96: the whole frame fits the blob net, so
the frame's discovery map is crop slot 2 whatever discovery_tiles; with discovery_tiles 2
the detector publishes 4 discovery slots per camera, crop2..crop5, with 1 a single one).
Either way round, the fusion node reads the detector's slot count from the ROS graph,
says once which parameter differs, with both values, the nodes and the cameras, counts
the instants of each camera in /diagnostics (discovery_slot_mismatch), does not wait for
slots that are never sent, and keeps publishing both subjects in every frame."""
import ast
import signal

from diagnostic_msgs.msg import DiagnosticArray
from helpers.blob_net import NAMES, train_blob_net
from helpers.fusion_frames import fusion_statuses
from helpers.ros import NodeProcess, RosHarness
from helpers.subject_blobs import blob_checkpoint, write_two_subjects
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2
import yaml

from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns
from monet_ros.subjects.detection import discovery_slots

T = 12


def summary_value(diagnostics, key):
    """A value of the fusion summary status in the newest fusion /diagnostics (None if
    none yet), a dict / list read back from its text."""
    status = fusion_statuses(diagnostics).get('monet fusion')
    if status is None:
        return None
    text = {kv.key: kv.value for kv in status.values}.get(key)
    return None if text is None else ast.literal_eval(text)


@pytest.mark.parametrize('detector_tiles, fusion_tiles', [(2, 1), (1, 2)])
def test_discovery_tiles_mismatch_is_said_counted_and_does_not_stall(
        ros_env, tmp_path, detector_tiles, fusion_tiles):
    folder, cams, X = write_two_subjects(tmp_path / 'rec', T=T)
    stamps = np.load(folder / 'ground_truth.npz')['stamps']
    names = [c.name for c in cams]
    size = (cams[0].width, cams[0].height)
    sent, expected = (discovery_slots(*size, detector_tiles),
                      discovery_slots(*size, fusion_tiles))
    assert (sent, expected) in ((4, 1), (1, 4))
    model = blob_checkpoint(train_blob_net(steps=400, sigma=(1.2, 4.0)), tmp_path / 'b.pt')
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text(yaml.safe_dump({'name': 'blobs', 'keypoints': list(NAMES),
                                        'bones': [[NAMES[0], NAMES[1]],
                                                  [NAMES[0], NAMES[2]]]}))
    rig = str(folder / 'rig.yaml')
    # timeout_s 30: a frame that waited for a slot never sent would wait that long
    fusion = dict(rig=rig, skeleton=str(skeleton), subjects=2, link_mm=450.0,
                  timeout_s=30.0, max_queue_ms=0.0, camera_markers=False,
                  discovery_tiles=fusion_tiles)
    detector = dict(rig=rig, model=str(model), subjects=2, device='cpu', threads=1,
                    precision='float32', lockstep=True, lockstep_timeout_s=60.0,
                    batch_wait_ms=10000.0, discovery_tiles=detector_tiles)
    player = dict(bag=str(folder / 'recording'), rate=0.0, lockstep=True,
                  lockstep_timeout_s=60.0, wait_for_subscribers=1, start_delay_s=1.0,
                  shutdown_when_done=True)
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)     # last: wait_heard
        with NodeProcess('fusion', ros_env, fusion) as fuse, \
                NodeProcess('detector', ros_env, detector) as detect:
            # every slot the detector sends is published, every slot fusion takes is
            # subscribed (the slots both have: crop0..crop2)
            assert ros.spin_until(lambda: all(
                (k >= 2 + sent or ros.node.count_publishers(f'/monet/{n}/crop{k}/heatmaps'))
                and (k >= 2 + expected
                     or ros.node.count_subscribers(f'/monet/{n}/crop{k}/heatmaps'))
                for n in names for k in range(2 + max(sent, expected))),
                timeout=120, process=detect), detect.output() + fuse.output()
            ros.wait_heard(diagnostics, ['monet fusion', f'monet detector: {names[0]}'],
                           process=fuse)
            # fusion has read the detector's slots from the graph before the first frame
            assert ros.spin_until(lambda: sorted(
                summary_value(diagnostics, 'discovery_slot_mismatch') or {}) == sorted(names),
                timeout=60, process=fuse), (fusion_statuses(diagnostics).get('monet fusion'),
                                            fuse.output())
            assert summary_value(diagnostics, 'detector_discovery_slots') == {
                n: [sent] for n in names}
            with NodeProcess('player', ros_env, player) as play:
                def done():
                    return {header_stamp_ns(c) for c in clouds} >= set(stamps.tolist())
                assert ros.spin_until(done, timeout=180, process=fuse), (
                    sorted(set(stamps.tolist()) - {header_stamp_ns(c) for c in clouds}),
                    play.output() + detect.output() + fuse.output())
                assert play.wait(timeout=60) == 0, play.output()
            # every camera's T instants counted
            assert ros.spin_until(
                lambda: summary_value(diagnostics, 'discovery_slot_mismatch') == {
                    n: T for n in names}, timeout=30, process=fuse), \
                fusion_statuses(diagnostics).get('monet fusion')
            status = fusion_statuses(diagnostics)
            assert detect.stop(signal.SIGINT) == 0, detect.output()
            assert fuse.stop(signal.SIGINT) == 0, fuse.output()

    summary = {kv.key: kv.value for kv in status['monet fusion'].values}
    assert summary['frames'] == str(T), summary
    # a slot the detector never sends makes no frame partial (none was waited for)
    assert summary['partial_frames'] == '0', summary
    for n in names:
        for k in range(2 + sent, 2 + expected):      # subscribed, never sent
            slot = status[f'monet fusion: {n}/crop{k}']
            assert 'not published by the detector' in slot.message, slot
        if sent > expected:
            assert 'discovery_tiles' in status[f'monet fusion: {n}/crop2'].message
    # one line says it: the parameter, both values, the nodes and the cameras
    lines = [line for line in fuse.output().splitlines() if 'discovery_tiles differs' in line]
    assert len(lines) == 1, fuse.output()
    line = lines[0]
    assert 'ERROR' in line and '/monet/detector' in line and '/monet/fusion' in line, line
    # read back from the slot count: 0 and 1 both give one slot on a square camera
    assert f'its discovery_tiles {"0 or 1" if detector_tiles == 1 else 2}' in line, line
    assert f'(its discovery_tiles {fusion_tiles})' in line, line
    assert f'publishes {sent} discovery crop slot(s)' in line, line
    assert f'this node expects {expected}' in line, line
    assert all(n in line for n in names), line
    # both subjects tracked in every frame, as with equal discovery_tiles
    by_stamp = {header_stamp_ns(c): c for c in clouds}
    for t, stamp in enumerate(stamps.tolist()):
        k = cloud_to_keypoints3d(by_stamp[stamp], units='m')
        assert len(np.unique(k['subject'])) == 2, f'frame {t}'
        assert np.isfinite(k['X']).all(), f'frame {t}'
