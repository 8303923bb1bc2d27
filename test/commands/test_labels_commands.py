"""Labels against a real recording, end to end: `monet info` lists instants and labelled
frames; `monet train` refuses bad label rows with one line naming file, line and field
(exit 2, no traceback), or skips and counts them with --skip-bad-labels; load_recording
matches stamps a few ns off."""
import csv
import os
import subprocess
import sys

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import numpy as np
import pytest

from monet_ros.labels import LabelError, LabelOptions
from monet_ros.learning.recording import RecordingError, load_recording

SKELETON = 'name: blobs\nkeypoints: [k0, k1, k2]\n'
TRAIN = ['--architecture', 'small', '--input-size', '48', '--width', '16', '--steps', '2',
         '--batch-labelled', '2', '--batch-unlabeled', '1', '--device', 'cpu', '--threads',
         '1', '--no-progress', '--mode', 'supervised', '--eval-fraction', '0']


def monet(repo_root, *args):
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(repo_root), env.get('PYTHONPATH')]))
    return subprocess.run([sys.executable, '-m', 'monet_ros.cli', *map(str, args)],
                          cwd=repo_root, env=env, capture_output=True, text=True, timeout=180)


@pytest.fixture(scope='module')
def folder(tmp_path_factory):
    rec = blob_recording(num_views=3, T=12, C=3, labelled=(2, 9))
    root = tmp_path_factory.mktemp('blobs')
    (root / 'blobs.yaml').write_text(SKELETON)
    return write_blob_folder(rec, root / 'data'), rec, root / 'blobs.yaml'


def rewrite(path, src, change):
    """Copy labels.csv src -> path with change(row dict) applied to each row."""
    with open(src, newline='') as f:
        rows = list(csv.DictReader(f))
    with open(path, 'w', newline='') as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow(change(dict(r)))
    return path


def test_stamps_a_few_ns_off_and_frame_indices_load_exactly(folder, tmp_path):
    data, rec, skeleton = folder
    names = ('k0', 'k1', 'k2')
    off = rewrite(tmp_path / 'off.csv', data / 'labels.csv',
                  lambda r: {**r, 'stamp_ns': str(int(r['stamp_ns']) + 7)})
    got = load_recording(data, labels=off, skeleton=names)
    np.testing.assert_array_equal(got.labels, rec.labels)
    assert got.label_report.kept == np.isfinite(rec.labels[..., 0]).sum()
    # frame-indexed: the same labels by instant index
    index = {int(s): i for i, s in enumerate(rec.stamps)}
    frames = rewrite(tmp_path / 'frames.csv', data / 'labels.csv',
                     lambda r: {'stamp_ns': index[int(r.pop('stamp_ns'))], **r})
    text = frames.read_text().replace('stamp_ns,', 'frame,', 1)
    frames.write_text(text)
    got = load_recording(data, labels=frames, skeleton=names)
    np.testing.assert_array_equal(got.labels, rec.labels)
    # a renamed camera: an error naming it, then mapped
    renamed = rewrite(tmp_path / 'renamed.csv', data / 'labels.csv',
                      lambda r: {**r, 'camera': r['camera'].replace('cam', 'Cam_0')})
    with pytest.raises(LabelError, match=r"renamed.csv:2: field camera: 'Cam_00' is not a "
                       r"camera .* did you mean 'cam0'"):
        load_recording(data, labels=renamed, skeleton=names)
    got = load_recording(data, labels=renamed, skeleton=names, label_options=LabelOptions(
        camera_map=('Cam_00=cam0', 'Cam_01=cam1', 'Cam_02=cam2')))
    np.testing.assert_array_equal(got.labels, rec.labels)
    # every row bad and skipped: a clear error, not an empty training set
    with pytest.raises(RecordingError, match=r'no label matches the recording: 0 of 18 label '
                       r'rows used; skipped 18 \(camera\)'):
        load_recording(data, labels=renamed, skeleton=names,
                       label_options=LabelOptions(skip_bad=True))


def test_train_names_bad_rows_and_skips_them_on_request(folder, repo_root, tmp_path):
    data, rec, skeleton = folder
    ms = rewrite(tmp_path / 'ms.csv', data / 'labels.csv',
                 lambda r: {**r, 'stamp_ns': str(int(r['stamp_ns']) // 1_000_000)})
    proc = monet(repo_root, 'train', data, '--labels', ms, '--skeleton', skeleton, '--out',
                 tmp_path / 'a', *TRAIN)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in proc.stderr
    assert f'{ms}:2: field stamp_ns:' in lines[0] and 'looks like milliseconds' in lines[0]
    # one far-off point among good ones: error, then skipped and counted with the flag
    with open(data / 'labels.csv') as f:
        good = f.read()
    far = tmp_path / 'far.csv'
    far.write_text(good + f'{rec.stamps[5]},cam1,k0,40,100000\n')
    proc = monet(repo_root, 'train', data, '--labels', far, '--skeleton', skeleton, '--out',
                 tmp_path / 'b', *TRAIN)
    assert proc.returncode == 2 and 'Traceback' not in proc.stderr
    assert f'{far}:20: field v: 100000.0 lies outside the image of cam1' in proc.stderr
    proc = monet(repo_root, 'train', data, '--labels', far, '--skeleton', skeleton, '--out',
                 tmp_path / 'c', '--skip-bad-labels', *TRAIN)
    assert proc.returncode == 0, proc.stderr
    assert 'labels: 18 of 19 label rows used; skipped 1 (bounds)' in proc.stderr


def test_info_lists_instants_stamps_and_labelled_frames(folder, repo_root):
    data, rec, skeleton = folder
    proc = monet(repo_root, 'info', data, '--labels', data / 'labels.csv', '--skeleton',
                 skeleton)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert 'instants: 12 (frames 0-11), 12 complete, 0 missing a view' in out
    assert f'stamps: first {rec.stamps[0]} ns, last {rec.stamps[-1]} ns, rate 30.303 Hz' in out
    assert 'labelled instants (2): 2, 9' in out
    assert '/cam0/image_raw  sensor_msgs/msg/Image  12 messages' in out
    assert '  cam2: 6 labelled keypoints' in out
    proc = monet(repo_root, 'info', data / 'nothing')
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1


def test_info_without_skeleton_names_the_keypoints_train_would_refuse(folder, repo_root,
                                                                      tmp_path):
    """`monet info --labels` takes the file's keypoints; `monet train` (default skeleton
    human14) refuses those it lacks: info says which, and train refuses the first of them."""
    data, rec, skeleton = folder
    proc = monet(repo_root, 'info', data, '--labels', data / 'labels.csv')
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stdout.splitlines() if line.startswith('skeleton: ')]
    assert lines == ["skeleton: 3 of the file's 3 keypoints are not in human14, monet "
                     "train's default skeleton, which refuses their rows: k0, k1, k2 (give "
                     'monet train --skeleton with them, or --keypoint-map SRC=DST)'], lines
    proc = monet(repo_root, 'train', data, '--labels', data / 'labels.csv', '--out',
                 tmp_path / 'o', *TRAIN)
    assert proc.returncode == 2 and 'Traceback' not in proc.stderr
    assert "'k0' is not a keypoint of the skeleton" in proc.stderr, proc.stderr
    # with the keypoints mapped onto human14's names: nothing to refuse
    mapped = ['--keypoint-map', 'k0=head', '--keypoint-map', 'k1=neck', '--keypoint-map',
              'k2=r_hip']
    proc = monet(repo_root, 'info', data, '--labels', data / 'labels.csv', *mapped)
    assert proc.returncode == 0, proc.stderr
    assert ("skeleton: every keypoint of the file is in human14, monet train's default"
            in proc.stdout), proc.stdout


def test_labels_import_dlc_project_round_trips_to_the_recordings_labels(folder, tmp_path,
                                                                        capsys):
    import pandas as pd

    from monet_ros.cli import main
    from monet_ros.labels import read_labels

    data, rec, skeleton = folder
    labelled = rec.labelled_instants
    for v, cam in enumerate(rec.cameras):
        video = tmp_path / 'dlc' / 'labeled-data' / f'session1_{cam.name}'
        video.mkdir(parents=True)
        cols = pd.MultiIndex.from_product([['me'], list(rec.keypoints), ['x', 'y']],
                                          names=['scorer', 'bodyparts', 'coords'])
        index = pd.MultiIndex.from_tuples([('labeled-data', video.name, f'img{t:04d}.png')
                                           for t in labelled])
        pd.DataFrame(rec.labels[labelled, v].reshape(len(labelled), -1), index=index,
                     columns=cols).to_csv(video / 'CollectedData_me.csv')
    out = tmp_path / 'labels.csv'
    assert main(['labels', 'import', 'dlc', str(tmp_path / 'dlc'), '--rec', str(data),
                 '--out', str(out), '--skeleton', str(skeleton)]) == 0
    assert 'monet labels import: 18 labels at 2 instants x 3 cameras' in capsys.readouterr().out
    got, want = read_labels(out, rec.keypoints), read_labels(data / 'labels.csv', rec.keypoints)
    assert got.stamps == want.stamps
    for s in want.stamps:
        np.testing.assert_array_equal(got.points(s, ['cam0', 'cam1', 'cam2']),
                                      want.points(s, ['cam0', 'cam1', 'cam2']))
    # a frame beyond the recording: one line naming the file, line and field
    extra = tmp_path / 'dlc' / 'labeled-data' / 'session1_cam1' / 'CollectedData_me.csv'
    extra.write_text(extra.read_text() + 'labeled-data,session1_cam1,img0040.png'
                     + ',1' * 6 + '\n')
    assert main(['labels', 'import', 'dlc', str(tmp_path / 'dlc'), '--rec', str(data),
                 '--out', str(out), '--skeleton', str(skeleton)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(f'{extra}:6: field frame: 40 is not an instant of the recording '
                        '(0 .. 11) (--skip-bad-labels drops and counts such rows)')


def test_train_leave_instants_out_check(tmp_path, repo_root):
    import json

    from monet_ros.labels import read_labels

    rec = blob_recording(num_views=3, T=12, C=3, labelled=(2, 5, 9))
    data = write_blob_folder(rec, tmp_path / 'data')
    (tmp_path / 'blobs.yaml').write_text(SKELETON)
    out = tmp_path / 'run'
    proc = monet(repo_root, 'train', data, '--skeleton', tmp_path / 'blobs.yaml', '--out', out,
                 '--holdout-labelled', '1', *TRAIN)
    assert proc.returncode == 0, proc.stderr
    # instant 5 is left out: 2 labelled instants train, its labels are written aside
    assert ', 2 labelled, ' in proc.stderr
    held = read_labels(out / 'heldout_labels.csv', ('k0', 'k1', 'k2'))
    assert held.stamps == [int(rec.stamps[5])]
    np.testing.assert_array_equal(held.points(rec.stamps[5], ['cam0', 'cam1', 'cam2']),
                                  rec.labels[5])
    assert 'held-out labelled instants [5]: 2D median' in proc.stderr
    assert ', PCK@10px' in proc.stderr and '(as monet process runs the model)' in proc.stderr
    assert 'inf px' not in proc.stderr            # a median of misses is said in words
    summary = json.loads(proc.stdout, parse_constant=lambda token: pytest.fail(token))
    assert summary['holdout']['instants'] == [5] and summary['holdout']['views_2d'] == 9
    assert summary['holdout']['joints_3d'] == 3
    proc = monet(repo_root, 'train', data, '--skeleton', tmp_path / 'blobs.yaml', '--out',
                 tmp_path / 'x', '--holdout-labelled', '3', *TRAIN)
    assert proc.returncode == 2
    assert '--holdout-labelled 3 needs at least 4 labelled instants, the recording has 3' in \
        proc.stderr


def test_one_labels_file_shared_by_several_recordings(folder, tmp_path):
    """The learner's bags share one labels file: rows of the other recording are counted
    as such, the rest must still pass the validator."""
    from monet_ros.learning.recording import Recording

    data, rec, _ = folder
    later = Recording('later', rec.cameras, rec.stamps + 10**12, rec.frames, rec.keypoints,
                      rec.labels, rec.gt3d)
    data2 = write_blob_folder(later, tmp_path / 'data2')
    both = tmp_path / 'both.csv'
    both.write_text((data / 'labels.csv').read_text()
                    + ''.join((data2 / 'labels.csv').read_text().splitlines(True)[1:]))
    names = ('k0', 'k1', 'k2')
    for folder_, expected in ((data, rec), (data2, later)):
        got = load_recording(folder_, labels=both, skeleton=names, shared_labels=True)
        np.testing.assert_array_equal(got.labels, expected.labels)
        assert got.label_report.skipped == {'other recordings': 18}
    with pytest.raises(LabelError, match='outside the recording'):
        load_recording(data, labels=both, skeleton=names)
