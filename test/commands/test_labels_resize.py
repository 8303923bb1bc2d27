"""The lab flow on real files: `monet import videos --resize 0.5` of the sleap-anipose
session, then its SLEAP labels (made on the full-size videos) through `monet labels import`:
the recording records the videos' size, the import scales the labels to the recording's
images and says so; labels at the wrong scale are refused whole (never half kept by
--skip-bad-labels), naming the option that brings them."""
import csv

import cv2
import h5py
from helpers.commands import run_monet_process
import numpy as np
import pytest
import yaml

CAMERAS = ('back', 'mid', 'side', 'top')


def monet(repo_root, *args, cwd):
    return run_monet_process(repo_root, *args, cwd=cwd)


def sleap_points(path):
    """(N, 2) finite (x, y) of a SLEAP analysis file, read with h5py (tracks: (tracks, 2,
    nodes, frames), video pixels)."""
    with h5py.File(path, 'r') as f:
        tracks = f['tracks'][()]
    xy = tracks.transpose(0, 3, 2, 1).reshape(-1, 2)
    return xy[np.isfinite(xy).all(axis=1)]


def table(path):
    with open(path, newline='') as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope='module')
def lab(shared_data, tmp_path_factory, repo_root):
    data = shared_data / 'sleap_anipose_minimal_session'
    base = tmp_path_factory.mktemp('lab')
    session = base / 'session'
    session.mkdir()
    for cam in CAMERAS:                       # one video per camera, the real files
        (session / f'{cam}.mp4').symlink_to(data / cam / f'minimal_{cam}.mp4')
    done = monet(repo_root, 'import', 'videos', session, '--calibration',
                 data / 'calibration.toml', '--out', base / 'rec', '--resize', '0.5',
                 '--quiet', cwd=base)
    assert done.returncode == 0, done.stderr
    h5 = [data / cam / f'minimal_{cam}_proofread.analysis.h5' for cam in CAMERAS]
    return data, base, base / 'rec', h5


def test_the_recording_records_the_videos_size(lab):
    data, _, rec, _ = lab
    record = yaml.safe_load((rec / 'monet_import.yaml').read_text())
    assert record['resize'] == 0.5
    for cam in CAMERAS:
        video = cv2.VideoCapture(str(data / cam / f'minimal_{cam}.mp4'))
        size = [int(video.get(cv2.CAP_PROP_FRAME_WIDTH)),
                int(video.get(cv2.CAP_PROP_FRAME_HEIGHT))]
        video.release()
        assert record['cameras'][cam]['source_size'] == size == [1280, 1024]
        assert record['cameras'][cam]['size'] == [640, 512]


def test_video_labels_are_scaled_to_the_recording_and_said(lab, repo_root):
    data, base, rec, h5 = lab
    done = monet(repo_root, 'labels', 'import', 'sleap', *h5, '--rec', rec, '--out',
                 base / 'labels.csv', cwd=base)
    assert done.returncode == 0, done.stderr
    assert "labels scaled from the videos' pixels to the recording's (back 1280x1024 -> " \
        '640x512' in done.stdout and 'imported with --resize 0.5' in done.stdout
    rows = table(base / 'labels.csv')
    expected = {cam: (sleap_points(path) + 0.5) * 0.5 - 0.5 for cam, path in zip(CAMERAS, h5)}
    assert len(rows) == sum(len(p) for p in expected.values()) == 6576
    for cam in CAMERAS:                      # cv2.resize's mapping of pixel centres
        got = np.array([(float(r['u']), float(r['v'])) for r in rows if r['camera'] == cam])
        for axis in (0, 1):
            np.testing.assert_allclose(np.sort(got[:, axis]), np.sort(expected[cam][:, axis]),
                                       atol=1e-4)


def test_labels_at_the_wrong_scale_are_refused_whole(lab, repo_root):
    data, base, rec, h5 = lab
    out = base / 'wrong.csv'
    done = monet(repo_root, 'labels', 'import', 'sleap', *h5, '--rec', rec, '--out', out,
                 '--label-scale', '1', '--skip-bad-labels', cwd=base)
    assert done.returncode == 2 and not out.exists()
    line, = done.stderr.splitlines()
    assert line.startswith('monet labels import: 6221 of 6576 label rows lie outside the '
                           'images (first: ')
    assert 'refused whole' in line
    assert line.endswith('this recording was imported with --resize 0.5: --label-scale 0.5 '
                         'for labels of its videos')
    # monet's own stamp-keyed table at the videos' size: taken in the recording's pixels
    # (said), so refused whole; --label-scale 0.5 brings it
    done = monet(repo_root, 'labels', 'import', 'sleap', *h5, '--rec', rec, '--out',
                 base / 'right.csv', cwd=base)
    assert done.returncode == 0, done.stderr
    scaled = table(base / 'right.csv')
    full = base / 'full.csv'
    with open(full, 'w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=list(scaled[0]))
        writer.writeheader()
        for r in scaled:
            writer.writerow({**r, 'u': (float(r['u']) + 0.5) * 2 - 0.5,
                             'v': (float(r['v']) + 0.5) * 2 - 0.5})
    done = monet(repo_root, 'labels', 'import', 'stamps', full, '--rec', rec, '--out', out,
                 '--skip-bad-labels', cwd=base)
    assert done.returncode == 2 and 'refused whole' in done.stderr
    done = monet(repo_root, 'labels', 'import', 'stamps', full, '--rec', rec, '--out', out,
                 '--label-scale', '0.5', cwd=base)
    assert done.returncode == 0, done.stderr
    assert 'label pixels scaled by 0.5 (--label-scale)' in done.stdout
    def keyed(rows):
        return {(r['stamp_ns'], r['camera'], r['keypoint']): (float(r['u']), float(r['v']))
                for r in rows}
    again, want = keyed(table(out)), keyed(scaled)
    assert again.keys() == want.keys()
    np.testing.assert_allclose([again[k] for k in want], list(want.values()), atol=1e-4)
