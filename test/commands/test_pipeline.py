"""`monet pipeline` as a user runs it: every frame fused, clean exits, the detector in a
child process that never outlives the command."""
import json
import os
from pathlib import Path
import re
import signal
import sys
import time

from helpers.recordings import noise_recording, small_checkpoint
from helpers.ros import NodeProcess, RosHarness
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from monet_ros.geometry import save_rig
from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns
from monet_ros.nodes.qos import LATCHED


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
        assert cloud_to_keypoints3d(cloud, units='m')['X'].shape == (14, 3)
    # the final summary line, and a quiet exit (no callback failing under a destroyed node)
    assert f'frames {len(stamps)} fused of {len(stamps)} played' in proc.output()
    assert 'never retrieved' not in proc.output()
    # (no check of 'no publisher' warnings here: a detector that starts long before the
    # player, under load, rightly warns; the recording's end is not warned:
    # test/nodes/test_detector_no_publisher.py, deterministic)


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
    """A bad option, file or parameter: exit 2 with one line naming it, and nothing else (no
    start-up line of a node or of the command before it, no summary of a run that never
    started after it), whichever check finds it (the arguments, a node's parameters, the
    model against the skeleton)."""
    rig, _ = noise_recording(tmp_path / 'rec', cameras=2, frames=1)
    model = small_checkpoint(tmp_path / 'model.pt')
    save_rig(tmp_path / 'one.yaml', rig[:1])
    run = ('--bag', tmp_path / 'rec', '--model', model, '--lockstep')
    cases = [
        (('--bag', tmp_path / 'rec', '--model', tmp_path / 'missing.pt'),
         'missing.pt: checkpoint file not found'),
        ((*run, '--rig', tmp_path / 'one.yaml'),
         "parameter 'cameras': needs at least 2 cameras"),
        ((*run, '--cameras', 'cam0', 'cam5'), "unknown camera 'cam5'"),
        ((*run, '--backend', 'onnxruntime', '--precision', 'bfloat16'),
         'precision bfloat16 needs backend torch'),
        ((*run, '--detector-processes', 3),
         "parameter 'detector_processes': 3 detector processes for 2 cameras; give at most 2"),
        ((*run, '--subjects', 0),              # the option named, not fusion's parameter
         "--subjects: SubjectsConfig: parameter 'subjects': must be >= 1, got 0"),
        ((*run, '--subjects', 2, '--discovery-tiles', -1),
         "--discovery-tiles: SubjectsConfig: parameter 'discovery_tiles': must be >= 0, got -1"),
        ((*run, '--skeleton', 'quadruped13'),
         "parameter 'skeleton': quadruped13 has keypoints ['nose', "),
    ]
    for args, message in cases:
        with pipeline(ros_env, *args) as proc:
            assert proc.wait(timeout=90) == 2, proc.output()
        out, err = proc.output().split('--- stderr\n')
        lines = out.removeprefix('--- stdout\n').splitlines() + err.splitlines()
        assert len(lines) == 1 and message in lines[0], proc.output()
        assert lines[0].startswith('monet pipeline: error: '), proc.output()


def test_a_detector_process_that_fails_at_start_is_one_line(ros_env, tmp_path):
    # a parameter file for the detector alone, with a value its own start check refuses
    # (the command checks only what it gives the detectors): the detector child process
    # prints its one line and exits 2, the command exits 2 without a second line (before:
    # also 'monet pipeline: error: the detector process exited with code 2')
    rig, _ = noise_recording(tmp_path / 'rec', cameras=2, frames=1)
    model = small_checkpoint(tmp_path / 'model.pt')
    params = tmp_path / 'params.yaml'
    params.write_text('/**/detector:\n  ros__parameters:\n    batch_wait_ms: -1.0\n')
    with pipeline(ros_env, '--bag', tmp_path / 'rec', '--model', model, '--lockstep',
                  '--ros-args', '--params-file', params) as proc:
        assert proc.wait(timeout=120) == 2, proc.output()
    out, err = proc.output().split('--- stderr\n')
    errors = [line for line in out.removeprefix('--- stdout\n').splitlines()
              + err.splitlines() if 'error' in line]
    assert len(errors) == 1 and 'batch_wait_ms' in errors[0], proc.output()
    assert errors[0].startswith('detector: error: '), proc.output()


def test_ros_args_move_the_rig_with_debug_images_and_tf(ros_env, tmp_path):
    """`--ros-args -r __ns:=/rig1` moves every topic of the pipeline; the debug image of each
    camera is on by default (bgr8, half the source size, with its camera_info) and the recording's
    /tf_static is replayed (when tf2_msgs is installed)."""
    rig, stamps = noise_recording(tmp_path / 'rec', cameras=2, frames=4)
    model = small_checkpoint(tmp_path / 'model.pt')
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        TFMessage = None
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/rig1/keypoints3d', PointCloud2, 100)
        default = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        debug = ros.collect('/rig1/cam0/debug_image', Image, 100)
        debug_info = ros.collect('/rig1/cam0/debug_image/camera_info', CameraInfo, 100)
        tf = ros.collect('/tf_static', TFMessage, LATCHED) if TFMessage else None
        with pipeline(ros_env, '--bag', tmp_path / 'rec', '--model', model, '--loop',
                      '--rate', 2.0, '--quiet', '--ros-args', '-r', '__ns:=/rig1') as proc:
            ok = ros.spin_until(lambda: clouds and debug and debug_info and (tf is None or tf),
                                timeout=120, process=proc)
            assert ok, proc.output()
            assert proc.stop() == 0, proc.output()
    assert not default
    image = debug[0]
    assert (image.encoding, image.width, image.height) == ('bgr8', 160, 120)   # scale 0.5
    np.testing.assert_allclose(np.reshape(debug_info[0].k, (3, 3)),
                               rig[0].crop((0, 0, 320, 240), (160, 120)).K)
    if tf is not None:
        assert {t.child_frame_id for t in tf[0].transforms} == {'cam0_optical', 'cam1_optical'}


def children(pid):
    """{pid: command line} of the live (not zombie) child processes of `pid`."""
    found = {}
    for task in Path(f'/proc/{pid}/task').glob('*'):
        for child in (task / 'children').read_text().split():
            try:
                state = Path(f'/proc/{child}/stat').read_text().rsplit(')', 1)[1].split()[0]
                cmdline = Path(f'/proc/{child}/cmdline').read_bytes().replace(b'\0', b' ')
            except OSError:
                continue
            if state != 'Z':
                found[int(child)] = cmdline.decode()
    return found


def alive(pid):
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state != 'Z'


def test_detector_runs_in_a_child_process_that_ends_with_the_pipeline(ros_env, tmp_path):
    """The detector is the pipeline's child process (its own interpreter lock: see
    monet_ros.nodes.child); SIGTERM to the pipeline alone stops both (exit 0), and a killed
    pipeline leaves no detector behind. Its OpenMP threads wait passively (unless the user
    chose a policy): monet_ros.nodes.passive_openmp."""
    noise_recording(tmp_path / 'rec', cameras=2, frames=3)
    model = small_checkpoint(tmp_path / 'model.pt')
    env = {k: v for k, v in ros_env.items() if k != 'OMP_WAIT_POLICY'}
    for how in ('sigterm', 'kill'):
        with RosHarness(env) as ros:
            clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
            with pipeline(env, '--bag', tmp_path / 'rec', '--model', model,
                          '--loop', '--rate', 2.0, '--quiet') as proc:
                assert ros.spin_until(lambda c=clouds: c, timeout=120, process=proc), \
                    proc.output()
                detectors = [pid for pid, cmd in children(proc.process.pid).items()
                             if 'monet_ros.nodes.detector' in cmd]
                assert len(detectors) == 1, (children(proc.process.pid), proc.output())
                environ = Path(f'/proc/{detectors[0]}/environ').read_bytes().split(b'\0')
                assert b'OMP_WAIT_POLICY=PASSIVE' in environ
                if how == 'sigterm':
                    assert proc.stop(signal.SIGTERM) == 0, proc.output()
                    assert not alive(detectors[0]), proc.output()
                else:
                    os.kill(proc.process.pid, signal.SIGKILL)
                    proc.process.wait()
                    deadline = time.monotonic() + 60
                    while alive(detectors[0]) and time.monotonic() < deadline:
                        time.sleep(0.1)
                    assert not alive(detectors[0]), proc.output()


@pytest.mark.slow
def test_player_and_two_detectors_run_in_child_processes_and_lockstep_fuses_every_frame(
        ros_env, tmp_path):
    """The player runs in its own process (its pid is not the pipeline's: fusion's
    interpreter lock is not shared with it), as does each of --detector-processes 2
    detectors (2 cameras each, half the cores each); lockstep across processes still fuses
    every frame of two loop passes, in order, and SIGTERM to the pipeline stops them all
    (exit 0)."""
    _, stamps = noise_recording(tmp_path / 'rec', cameras=4, frames=4)
    model = small_checkpoint(tmp_path / 'model.pt')
    span = stamps[-1] - stamps[0] + (stamps[1] - stamps[0])     # the loop's stamp shift
    expected = stamps + [s + span for s in stamps]
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        with pipeline(ros_env, '--bag', tmp_path / 'rec', '--model', model, '--lockstep',
                      '--loop', '--detector-processes', 2, '--quiet') as proc:
            ros.spin_until(lambda: len(clouds) >= len(expected), timeout=120, process=proc)
            found = children(proc.process.pid)
            players = [pid for pid, cmd in found.items() if 'monet_ros.nodes.player' in cmd]
            detectors = {pid: cmd for pid, cmd in found.items()
                         if 'monet_ros.nodes.detector' in cmd}
            assert proc.stop(signal.SIGTERM) == 0, proc.output()
    assert len(players) == 1 and players[0] != proc.process.pid, (found, proc.output())
    assert not alive(players[0])
    assert len(detectors) == 2 and not any(alive(pid) for pid in detectors), found
    groups = sorted(re.search(r'cameras:=(\[[^]]*\])', cmd).group(1) for cmd in detectors.values())
    assert [json.loads(g) for g in groups] == [['cam0', 'cam1'], ['cam2', 'cam3']], detectors
    # the cores shared out between the two (not 2 x all cores: oversubscribed)
    share = max(1, len(os.sched_getaffinity(0)) // 2)
    assert all(f'threads:={share}' in cmd.split() for cmd in detectors.values()), detectors
    assert [header_stamp_ns(c) for c in clouds[:len(expected)]] == expected, proc.output()
    assert 'monet pipeline: 2 detector processes for 4 cameras\n' in proc.output()


def test_a_recording_that_plays_no_frame_is_an_error(ros_env, tmp_path):
    """A recording cut short after its first chunk, which holds one view of the first
    instant (its rig given as a file): the replay ends without a frame, which exits 2 with
    one error line, not an empty 0. (Cut before any message, it is refused at start:
    test/commands/test_info_not_a_recording.py.)"""
    import io

    from mcap.reader import make_reader

    from monet_ros.io import BagWriter

    rig, _ = noise_recording(tmp_path / 'whole', cameras=2, frames=1)
    save_rig(tmp_path / 'rig.yaml', rig)
    model = small_checkpoint(tmp_path / 'model.pt')
    rng = np.random.default_rng(0)
    with BagWriter(tmp_path / 'rec', chunk_size=1000) as bag:   # a chunk per image
        bag.write_tf_static(1000, rig)
        for k in range(3):
            for cam in rig:
                image = rng.integers(0, 255, (cam.height, cam.width, 3), dtype=np.uint8)
                bag.write_image(f'/{cam.name}/image_raw', 1000 + k, image, f'{cam.name}_optical')
                bag.write_camera_info(f'/{cam.name}/camera_info', 1000 + k, cam,
                                      f'{cam.name}_optical')
    mcap = next((tmp_path / 'rec').glob('*.mcap'))
    data = mcap.read_bytes()
    summary = make_reader(io.BytesIO(data)).get_summary()
    first = min(summary.chunk_indexes, key=lambda ci: ci.chunk_start_offset)
    assert first.message_end_time == 1000         # /tf_static and cam0's first image only
    mcap.write_bytes(data[:first.chunk_start_offset + first.chunk_length + 20])
    with pipeline(ros_env, '--bag', tmp_path / 'rec', '--rig', tmp_path / 'rig.yaml',
                  '--model', model) as proc:
        assert proc.wait(timeout=120) == 2, proc.output()
    assert 'the replay ended without playing a frame' in proc.output(), proc.output()


def test_a_synth_folder_is_a_bag(ros_env, tmp_path):
    """`monet pipeline --bag D`, D a `monet synth` output folder (the bag in D/recording),
    as `monet train D` takes it: it said 'bag folder D has no readable .mcap files'."""
    _, stamps = noise_recording(tmp_path / 'synth' / 'recording', cameras=2, frames=3)
    model = small_checkpoint(tmp_path / 'model.pt')
    with pipeline(ros_env, '--bag', tmp_path / 'synth', '--model', model, '--lockstep') as proc:
        assert proc.wait(timeout=120) == 0, proc.output()
    assert f'frames {len(stamps)} fused of {len(stamps)} played' in proc.output(), proc.output()
