"""Generated bad files and output folders for train / eval / demo / synth / process /
pipeline: recordings with only /compressed images (kind 10), evaluation without ground
truth or from a damaged results.json, a Pose2Sim trial with damaged files, and output
folders that are files, read-only or full. Each is a right result or one clear line."""
import errno
import json
import shutil

import cv2
from helpers.reliability import RELIABILITY, outcome, record
from helpers.scenes import ring_rig
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from monet_ros.commands.demo import CALIBRATION, TRIAL
from monet_ros.geometry.pose2sim import BODY_25B_IDS
from monet_ros.io import BagWriter, open_bag


# ------------------------------------------------------------------ kind 10: /compressed
@pytest.fixture(scope='module')
def compressed_folder(synth_folder, tmp_path_factory):
    """The synth folder with its images re-recorded as lossless PNG CompressedImage on
    /camK/image_raw/compressed only (the rig file still names /camK/image_raw)."""
    folder = tmp_path_factory.mktemp('compressed') / 'data'
    folder.mkdir()
    for name in ('rig.yaml', 'labels.csv', 'ground_truth.npz'):
        shutil.copy(synth_folder / name, folder / name)
    images = {}
    with BagWriter(folder / 'recording') as writer:
        for m in open_bag(synth_folder / 'recording').messages():
            if m.topic.endswith('/image_raw'):
                rgb = np.frombuffer(m.msg.data, np.uint8).reshape(m.msg.height, m.msg.width, 3)
                images[m.topic, m.stamp_ns] = rgb
                writer.write_compressed_image(m.topic + '/compressed', m.stamp_ns, rgb,
                                              str(m.msg.header.frame_id), fmt='png')
            elif m.topic.endswith('/camera_info'):
                pass
    return folder, images


def test_train_and_process_read_compressed_only_recordings(compressed_folder, tmp_path):
    """Kind 10: `monet train` on a recording with only /compressed image topics works, as
    `monet process` does (one image-topic rule); the decoded frames are the originals."""
    from monet_ros.learning.recording import load_recording

    folder, images = compressed_folder
    recording = load_recording(folder)
    assert recording.num_instants == 6
    for v, cam in enumerate(recording.cameras):
        for t, stamp in enumerate(recording.stamps):
            # the camera reads its compressed topic
            assert cam.topic.endswith('/compressed')
            np.testing.assert_array_equal(recording.frames[v][t],
                                          images[cam.topic.removesuffix('/compressed'), stamp])
    out = tmp_path / 'train'
    outcome('train', ['train', folder, '--out', out, '--mode', 'supervised', '--steps', '2',
                      '--input-size', '64', '--threads', '1', '--no-progress',
                      '--checkpoint-every', '2', '--eval-fraction', '0'], expect='right result')
    assert (out / 'model.pt').is_file()
    _, stdout, _ = outcome('process', ['process', folder / 'recording', '--rig',
                                       folder / 'rig.yaml', '--model', out / 'model.pt',
                                       '--out', tmp_path / 'processed', '--quiet'],
                           expect='right result')
    assert 'monet process: 6 frames (18 views, 0 missing)' in stdout
    # eval of that model, then the report again from its results.json
    _, stdout, _ = outcome('eval', ['eval', out / 'model.pt', '--data', folder, '--out',
                                    tmp_path / 'report', '--instants', 'all'],
                           expect='right result')
    assert (tmp_path / 'report' / 'results.json').is_file()
    outcome('eval', ['eval', '--from-json', tmp_path / 'report' / 'results.json', '--out',
                     tmp_path / 'report2'], expect='right result')
    assert (tmp_path / 'report2' / 'results.md').read_text() == \
        (tmp_path / 'report' / 'results.md').read_text()


def test_eval_without_ground_truth_is_named(synth_folder, process_inputs, tmp_path):
    data = tmp_path / 'no_gt'
    shutil.copytree(synth_folder, data)
    (data / 'ground_truth.npz').unlink()
    _, model = process_inputs
    outcome('eval', ['eval', model, '--data', data, '--out', tmp_path / 'r'],
            names=('ground truth',), expect='clear error')


JSONISH = st.recursive(st.none() | st.booleans() | st.floats() | st.text(max_size=8),
                       lambda c: st.lists(c, max_size=4) |
                       st.dictionaries(st.text(max_size=8), c, max_size=4), max_leaves=12)


@settings(RELIABILITY, max_examples=25)
@given(content=st.one_of(JSONISH.map(json.dumps), st.binary(max_size=64).map(
    lambda b: b.decode('latin-1')), st.just('[{"mode": "x"}]'), st.just('[]')))
def test_eval_from_damaged_json(tmp_path_factory, content):
    path = tmp_path_factory.mktemp('json') / 'results.json'
    path.write_text(content, encoding='utf-8', errors='replace')
    outcome('eval', ['eval', '--from-json', path, '--out', path.parent / 'r'],
            names=(str(path),), expect='clear error')


# ------------------------------------------------------------------ monet demo
MARKERS = ['Nose', 'LShoulder', 'RShoulder', 'LHip', 'RHip', 'LKnee']


def write_trial(root, frames=3, cameras=2, seed=0):
    """A Pose2Sim trial laid out as the demo expects: calibration TOML, OpenPose JSON per
    camera and frame (exact projections), and the .trc of the true markers."""
    rng = np.random.default_rng(seed)
    rig = ring_rig(cameras)
    calib = root / CALIBRATION
    calib.parent.mkdir(parents=True)
    lines = []
    for i, cam in enumerate(rig):
        rvec = cv2.Rodrigues(cam.R)[0].ravel()
        lines += [f'[cam_{i + 1:02d}]', f'name = "cam_{i + 1:02d}"',
                  f'size = [ {float(cam.width)}, {float(cam.height)}]',
                  f'matrix = {cam.K.tolist()}', 'distortions = [ 0.0, 0.0, 0.0, 0.0]',
                  f'rotation = {rvec.tolist()}', f'translation = {cam.t.tolist()}',
                  'fisheye = false', '']
    calib.write_text('\n'.join(lines))
    from monet_ros.geometry import load_rig
    loaded = load_rig(calib)
    world = rng.normal(scale=0.3, size=(frames, len(MARKERS), 3)) + [0, 0, 1.0]
    trial = root / TRIAL
    for v, cam in enumerate(loaded):
        folder = trial / 'pose-associated' / f'cam{v + 1:02d}_json'
        folder.mkdir(parents=True)
        uv = cam.project(world.reshape(-1, 3)).reshape(frames, len(MARKERS), 2)
        for f in range(frames):
            values = np.zeros((25, 3))
            for m, name in enumerate(MARKERS):
                values[BODY_25B_IDS[name]] = [*uv[f, m], 0.9]
            (folder / f'frame_{f:06d}.json').write_text(json.dumps(
                {'people': [{'pose_keypoints_2d': values.ravel().tolist()}]}))
    trc = trial / 'pose-3d' / 'trial.trc'
    trc.parent.mkdir(parents=True)
    header = ['PathFileType\t4\t(X/Y/Z)\ttrial.trc', 'DataRate', '30',
              'Frame#\tTime\t' + '\t\t\t'.join(MARKERS), '\t\t' + '\t'.join(
                  f'X{i}\tY{i}\tZ{i}' for i in range(1, len(MARKERS) + 1))]
    rows = ['\t'.join([str(f + 1), f'{f / 30:.4f}'] + [f'{c:.6f}' for m in world[f]
                                                         for c in (m[1], m[2], m[0])])
            for f in range(frames)]
    trc.write_text('\n'.join(header + rows) + '\n')
    return trial, calib


def test_demo_on_a_generated_trial(tmp_path):
    write_trial(tmp_path)
    _, stdout, _ = outcome('demo', ['demo', '--data', tmp_path], expect='right result')
    assert '18 of 18 points within 0.1 mm' in stdout


DAMAGE = st.one_of(st.text(max_size=40), st.binary(max_size=40).map(
    lambda b: b.decode('latin-1')), JSONISH.map(json.dumps), st.just(''))


@settings(RELIABILITY, max_examples=30)
@given(target=st.sampled_from(['calibration', 'json', 'trc', 'no trc', 'one json less',
                               'no json']),
       content=DAMAGE, seed=st.integers(0, 1000))
def test_demo_with_damaged_files(tmp_path_factory, target, content, seed):
    """A bad TOML / JSON / .trc or a missing file: a clear line naming it (was
    StopIteration, KeyError, ...), or a right result when the damage is harmless."""
    root = tmp_path_factory.mktemp('trial')
    trial, calib = write_trial(root, seed=seed)
    jsons = sorted((trial / 'pose-associated').rglob('*.json'))
    trc = trial / 'pose-3d' / 'trial.trc'
    if target == 'calibration':
        calib.write_text(content, encoding='utf-8', errors='replace')
        names = (calib.name,)
    elif target == 'json':
        jsons[seed % len(jsons)].write_text(content, encoding='utf-8', errors='replace')
        names = (jsons[seed % len(jsons)].name,)
    elif target == 'trc':
        trc.write_text(content, encoding='utf-8', errors='replace')
        names = (trc.name,)
    elif target == 'no trc':
        trc.unlink()
        names = ('pose-3d', '.trc')
    elif target == 'one json less':
        jsons[seed % len(jsons)].unlink()
        names = ('pose-associated', 'frames')
    else:
        shutil.rmtree(jsons[0].parent)
        names = ('detection folders', 'json')
    outcome('demo', ['demo', '--data', root], names=names)


# ------------------------------------------------------------------ output folders
def _commands(synth_folder, process_inputs, out):
    rec, model = process_inputs
    return {
        'synth': ['synth', '--out', out, '--cameras', '2', '--frames', '1', '--width', '32',
                  '--height', '32', '--quiet'],
        'train': ['train', synth_folder, '--out', out, '--steps', '1', '--input-size', '64',
                  '--no-progress', '--threads', '1'],
        'eval': ['eval', model, '--data', synth_folder, '--out', out],
        'process': ['process', rec, '--model', model, '--out', out, '--quiet'],
        'pipeline': ['pipeline', '--workdir', out, '--quiet', '--duration', '1'],
    }


@pytest.mark.parametrize('command', ['synth', 'train', 'eval', 'process', 'pipeline'])
@pytest.mark.parametrize('place', ['a file', 'under a file', 'read-only'])
def test_unwritable_output_folders_are_named(synth_folder, process_inputs, tmp_path, command,
                                             place):
    """An output that is a file, lies under a file, or in a read-only place: one line that
    names the path (was a raw OSError traceback)."""
    blocker = tmp_path / 'blocker'
    blocker.write_text('not a folder')
    out = {'a file': blocker, 'under a file': blocker / 'out',
           'read-only': '/sys/monet_reliability_out'}[place]
    argv = _commands(synth_folder, process_inputs, out)[command]
    outcome(command, argv, names=(str(out), 'blocker'), expect='clear error')
    assert blocker.read_text() == 'not a folder'


def test_disk_full_names_the_path():
    """ENOSPC as the OS raises it (writing to /dev/full) names no file: the one line of
    every command names the output path and says the disk is full."""
    from monet_ros.error_text import os_error_text

    with pytest.raises(OSError) as caught:
        with open('/dev/full', 'wb') as stream:
            stream.write(b'x' * 65536)
            stream.flush()
    assert caught.value.errno == errno.ENOSPC and not caught.value.filename
    text = os_error_text(caught.value, '/data/runs/out')
    assert text == '/data/runs/out: no space left on device (disk full)'
    record('disk full (OSError)', 'clear error')
