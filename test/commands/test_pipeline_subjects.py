"""`monet pipeline --subjects 2` as a user runs it: the blob scene of two subjects walking
past each other (helpers.subject_blobs, the trained blob net) through the player, a
detector child process and fusion with several subjects, lockstep: keypoints3d of both
subjects for every frame, each body one identity, the summary says so."""
import sys

from helpers.ros import NodeProcess, RosHarness
from helpers.subject_blobs import two_subject_scene
import numpy as np
from sensor_msgs.msg import PointCloud2

from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns

T = 12


def test_pipeline_tracks_two_subjects(ros_env, tmp_path):
    folder, stamps, X, model, skeleton = two_subject_scene(tmp_path, T=T)
    argv = [sys.executable, '-m', 'monet_ros.cli', 'pipeline', '--bag',
            str(folder / 'recording'), '--rig', str(folder / 'rig.yaml'), '--model',
            str(model), '--skeleton', str(skeleton), '--subjects', '2', '--lockstep',
            '--precision', 'float32', '--threads', '1', '--quiet', '--start-delay', '2.0']
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        with NodeProcess('pipeline', ros_env, argv=argv) as proc:
            ros.spin_until(lambda: len(clouds) >= T or not proc.running(), timeout=180)
            assert proc.wait(timeout=120) == 0, proc.output()
    assert [header_stamp_ns(c) for c in clouds] == stamps, proc.output()
    identity_of = {}
    for t, cloud in enumerate(clouds):
        k = cloud_to_keypoints3d(cloud, units='m')
        assert len(np.unique(k['subject'])) == 2, f'frame {t}'
        for ident in np.unique(k['subject']):
            mine = k['X'][k['subject'] == ident]
            d = np.linalg.norm(mine[None] - X[t], axis=-1).mean(-1)
            body = int(np.argmin(d))
            assert d[body] < 0.030, (t, d)
            assert identity_of.setdefault(body, int(ident)) == int(ident), f'frame {t}'
    last = proc.output().strip().splitlines()
    line = next(x for x in reversed(last) if x.startswith('monet pipeline:'))
    assert f'frames {T} fused of {T} played' in line, line
    assert 'subjects 2 in the last frame (2 identities alive), 2 births, 0 deaths' in line, line
    assert 'joints triangulated 100%' in line, line


def test_subjects_refuse_the_one_subject_demo_and_learn(ros_env):
    import subprocess
    for extra in ([], ['--bag', 'rec', '--model', 'm.pt', '--learn']):
        done = subprocess.run([sys.executable, '-m', 'monet_ros.cli', 'pipeline',
                               '--subjects', '2', *extra], env=ros_env, capture_output=True,
                              text=True, timeout=120)
        assert done.returncode == 2, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and 'subjects' in lines[0], done.stderr
    # a negative --discovery-period-s, or one without --subjects: one line naming it
    for extra in (['--subjects', '2', '--discovery-period-s', '-1'],
                  ['--discovery-period-s', '1']):
        done = subprocess.run([sys.executable, '-m', 'monet_ros.cli', 'pipeline',
                               '--bag', 'rec', '--model', 'm.pt', *extra], env=ros_env,
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 2, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and '--discovery-period-s' in lines[0], done.stderr


def test_detectors_take_the_fusion_nodes_discovery_tiles(ros_env, tmp_path):
    # a parameter file that sets discovery_tiles for the fusion node alone (1: one discovery
    # slot per 96 px camera, crop2; the detectors' default 2 would send crop2..crop5): the
    # detector child process is given fusion's value, so the two nodes' crop slots agree
    import yaml
    folder, stamps, _, model, skeleton = two_subject_scene(tmp_path, T=T)
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump({'/**/fusion': {'ros__parameters': {
        'discovery_tiles': 1}}}))
    argv = [sys.executable, '-m', 'monet_ros.cli', 'pipeline', '--bag',
            str(folder / 'recording'), '--rig', str(folder / 'rig.yaml'), '--model',
            str(model), '--skeleton', str(skeleton), '--subjects', '2', '--lockstep',
            '--precision', 'float32', '--threads', '1', '--quiet', '--start-delay', '2.0',
            '--discovery-period-s', '0.5', '--ros-args', '--params-file', str(params)]
    seen = {'crop2': 0, 'crop3': 0}
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)

        def look():
            for slot in seen:
                seen[slot] = max(seen[slot], ros.node.count_publishers(
                    f'/monet/cam0/{slot}/heatmaps'))
            return len(clouds) >= T or not proc.running()
        with NodeProcess('pipeline', ros_env, argv=argv) as proc:
            ros.spin_until(look, timeout=180)
            assert proc.wait(timeout=120) == 0, proc.output()
    assert [header_stamp_ns(c) for c in clouds] == stamps, proc.output()
    assert seen == {'crop2': 1, 'crop3': 0}, (seen, proc.output())
    assert 'discovery_tiles 1' in proc.output(), proc.output()      # fusion's start line
    assert 'discovery_tiles differs' not in proc.output(), proc.output()
    # --discovery-period-s reaches the detector (its start line)
    assert ('discovery maps (discovery_tiles 1) in the first frame of each 0.5 s window'
            in proc.output()), proc.output()
