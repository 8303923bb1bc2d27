"""Several subjects live, end to end over DDS with real nodes in their own processes: the
player replays a recording of two subjects of three coloured blobs walking past each other
(helpers.subject_blobs: 4 cameras, 12 frames, 96x96), the detector node (subjects:=2, a
real trained detector: the blob net) crops each subject of the latest keypoints3d and the
full frame while fewer than 2 are tracked, the fusion node (subjects:=2) associates and
tracks them. Lockstep (player and detector), so every frame's crops follow the previous
frame's 3D whatever the load. Both subjects are published in every frame, each body keeps
one identity, and its 3D is within 10 mm of the ground truth on average and 30 mm in every
frame (the tolerances of `monet process --subjects 2` on the same scene,
test_process_subjects)."""
import signal

from diagnostic_msgs.msg import DiagnosticArray
from helpers.blob_net import NAMES, train_blob_net
from helpers.fusion_frames import fusion_statuses
from helpers.ros import NodeProcess, RosHarness
from helpers.subject_blobs import blob_checkpoint, write_two_subjects
import numpy as np
from sensor_msgs.msg import PointCloud2
import yaml

from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns

T = 12


def test_player_detector_fusion_track_two_subjects(ros_env, tmp_path):
    folder, cams, X = write_two_subjects(tmp_path / 'rec', T=T)      # X (T, 2, 3, 3) m
    stamps = np.load(folder / 'ground_truth.npz')['stamps']
    model = blob_checkpoint(train_blob_net(steps=400, sigma=(1.2, 4.0)), tmp_path / 'b.pt')
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text(yaml.safe_dump({'name': 'blobs', 'keypoints': list(NAMES),
                                        'bones': [[NAMES[0], NAMES[1]],
                                                  [NAMES[0], NAMES[2]]]}))
    rig = str(folder / 'rig.yaml')
    fusion = dict(rig=rig, skeleton=str(skeleton), subjects=2, link_mm=450.0,
                  timeout_s=30.0, max_queue_ms=0.0, camera_markers=False)
    detector = dict(rig=rig, model=str(model), subjects=2, device='cpu', threads=1,
                    precision='float32', lockstep=True, lockstep_timeout_s=60.0,
                    batch_wait_ms=10000.0)
    player = dict(bag=str(folder / 'recording'), rate=0.0, lockstep=True,
                  lockstep_timeout_s=60.0, wait_for_subscribers=1, start_delay_s=1.0,
                  shutdown_when_done=True)
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        with NodeProcess('fusion', ros_env, fusion) as fuse, \
                NodeProcess('detector', ros_env, detector) as detect:
            # the fusion node subscribes every crop slot before the first frame is played
            assert ros.spin_until(lambda: all(
                ros.node.count_subscribers(f'/monet/{c.name}/crop{k}/heatmaps')
                and ros.node.count_publishers(f'/monet/{c.name}/crop{k}/heatmaps')
                for c in cams for k in range(3)), timeout=120, process=detect), \
                detect.output() + fuse.output()
            with NodeProcess('player', ros_env, player) as play:
                def done():
                    return {header_stamp_ns(c) for c in clouds} >= set(stamps.tolist())
                assert ros.spin_until(done, timeout=180, process=fuse), \
                    play.output() + detect.output() + fuse.output()
                assert play.wait(timeout=60) == 0, play.output()
            assert ros.spin_until(lambda: 'monet fusion: subject 1' in
                                  fusion_statuses(diagnostics), timeout=30, process=fuse)
            status = fusion_statuses(diagnostics)
            assert detect.stop(signal.SIGINT) == 0, detect.output()
            assert fuse.stop(signal.SIGINT) == 0, fuse.output()

    by_stamp = {header_stamp_ns(c): c for c in clouds}
    identity_of, errors = {}, []
    for t, stamp in enumerate(stamps.tolist()):
        k = cloud_to_keypoints3d(by_stamp[stamp], units='m')
        ids = np.unique(k['subject'])
        assert len(ids) == 2, f'frame {t}: subjects {ids}'
        for ident in ids:
            mine = k['X'][k['subject'] == ident]                       # (3, 3)
            assert np.isfinite(mine).all(), f'frame {t}'
            d = np.linalg.norm(mine[None] - X[t], axis=-1).mean(-1)     # to each body
            body = int(np.argmin(d))
            assert identity_of.setdefault(body, int(ident)) == int(ident), f'frame {t}'
            errors.append(d[body])
    assert sorted(identity_of) == [0, 1] and len(set(identity_of.values())) == 2
    errors = np.array(errors)
    assert errors.mean() < 0.010 and errors.max() < 0.030, errors
    summary = {kv.key: kv.value for kv in status['monet fusion'].values}
    assert summary['births'] == '2' and summary['deaths'] == '0', summary
