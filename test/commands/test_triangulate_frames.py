"""`monet triangulate` keeps the source's frame numbers and time: the real sleap-anipose
session's SLEAP analysis files (edited copies: a subject first seen at frame 10, one camera
losing the animal in its last 10 frames), DeepLabCut CSVs with empty likelihood cells and
points tables that start late; every export (keypoints3d.csv fnum, TRC Frame# / Time /
DataRate, NWB timestamps and source_frame, npz fnum) is checked against the frame numbers
of the files themselves."""
import shutil

import numpy as np
import pandas as pd
import pytest

from monet_ros.cli import main as monet
from monet_ros.io.export_tables import read_anipose_csv, read_trc

SESSION = 'sleap_anipose_minimal_session'
CAMS = ('back', 'mid', 'side', 'top')
FPS = 30.0


def run(args, capsys):
    code = monet(['triangulate', *map(str, args)])
    out = capsys.readouterr()
    return code, out.out, out.err


def copy_session(shared_data, folder):
    """Copies of the 4 real analysis files (one per camera folder, as sleap-anipose lays
    them out) -> (paths, calibration path)."""
    root = shared_data / SESSION
    paths = []
    for cam in CAMS:
        (folder / cam).mkdir(parents=True)
        paths.append(folder / cam / f'minimal_{cam}_proofread.analysis.h5')
        shutil.copy(root / cam / paths[-1].name, paths[-1])
    return paths, root / 'calibration.toml'


def hide_frames(path, frames):
    """Edit a SLEAP analysis file in place: the animal is absent in `frames` (NaN points,
    no occupancy), the file keeps its frame count."""
    import h5py
    with h5py.File(path, 'r+') as f:
        tracks = f['tracks'][()]
        tracks[..., frames] = np.nan               # read (tracks, 2, nodes, frames)
        f['tracks'][...] = tracks
        occupancy = f['track_occupancy'][()]
        occupancy[frames] = 0                      # read (frames, tracks)
        f['track_occupancy'][...] = occupancy


def seen_frames(path):
    """Frame indices with any finite point, read from the file itself."""
    import h5py
    with h5py.File(path, 'r') as f:
        return np.flatnonzero(np.isfinite(f['tracks'][()]).all(1).any((0, 1)))


def read_nwb(path):
    import ndx_pose  # noqa: F401  (registers the extension for reading)
    from pynwb import NWBHDF5IO
    with NWBHDF5IO(str(path), 'r') as io:
        nwb = io.read()
        behavior = nwb.processing['behavior']
        series = next(iter(behavior['monet_pose'].pose_estimation_series.values()))
        return (np.asarray(series.timestamps[:]), np.asarray(behavior['source_frame'].data[:]),
                nwb.session_start_time.timestamp())


@pytest.fixture(scope='module')
def reference(shared_data, tmp_path_factory):
    """The untouched session triangulated: its CSV (frames 0..119)."""
    folder = tmp_path_factory.mktemp('ref')
    paths, calib = copy_session(shared_data, folder / 'in')
    assert monet(['triangulate', *map(str, paths), '--rig', str(calib), '--out',
                  str(folder / 'out'), '--fps', str(FPS), '--quiet']) == 0
    return read_anipose_csv(folder / 'out' / 'keypoints3d.csv')


def test_sleap_subject_first_seen_at_frame_10_keeps_its_frame_numbers_in_every_export(
        shared_data, reference, tmp_path, capsys):
    paths, calib = copy_session(shared_data, tmp_path / 'in')
    for p in paths:
        hide_frames(p, np.arange(10))
    first = min(seen_frames(p)[0] for p in paths)
    assert first == 10
    code, text, err = run([*paths, '--rig', calib, '--out', tmp_path / 'out', '--fps', FPS,
                           '--export', 'csv,trc,nwb,npz', '--quiet'], capsys)
    assert code == 0, err
    assert '110 frames (from frame 10)' in text and 'source frames 10..119' in text
    expect = np.arange(10, 120)
    csv = read_anipose_csv(tmp_path / 'out' / 'keypoints3d.csv')
    np.testing.assert_array_equal(csv['fnum'], expect)
    # the rows are the reference's rows of the same video frames
    np.testing.assert_array_equal(csv['X'], reference['X'][expect])
    np.testing.assert_array_equal(reference['fnum'], np.arange(120))
    trc = read_trc(tmp_path / 'out' / 'keypoints3d.trc')
    np.testing.assert_array_equal(trc['frames'], expect + 1)
    np.testing.assert_allclose(trc['times'], expect / FPS, rtol=0, atol=1e-9)
    assert trc['rate'] == FPS
    header = (tmp_path / 'out' / 'keypoints3d.trc').read_text().splitlines()[2].split('\t')
    assert header[6] == '11'                      # OrigDataStartFrame = first Frame#
    times, source_frame, start = read_nwb(tmp_path / 'out' / 'keypoints.nwb')
    np.testing.assert_allclose(times, expect / FPS, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(source_frame, expect)
    assert start == 0.0
    npz = np.load(tmp_path / 'out' / 'detections2d.npz')
    np.testing.assert_array_equal(npz['fnum'], expect)


def test_sleap_camera_missing_the_animal_in_its_last_frames_is_not_a_shorter_file(
        shared_data, reference, tmp_path, capsys):
    paths, calib = copy_session(shared_data, tmp_path / 'in')
    hide_frames(paths[1], np.arange(110, 120))          # mid loses the animal
    assert seen_frames(paths[1])[-1] == 109
    code, text, err = run([*paths, '--rig', calib, '--out', tmp_path / 'out', '--fps', FPS,
                           '--export', 'csv,npz', '--quiet'], capsys)
    assert code == 0, err
    assert '120 frames (from frame 0) x 4 cameras' in text
    csv = read_anipose_csv(tmp_path / 'out' / 'keypoints3d.csv')
    np.testing.assert_array_equal(csv['fnum'], np.arange(120))
    npz = np.load(tmp_path / 'out' / 'detections2d.npz')
    assert np.isnan(npz['points2d'][110:, 1]).all()
    np.testing.assert_array_equal(csv['X'][:110], reference['X'][:110])
    # a file that really is shorter (its frame axis) is still refused, naming both files
    import h5py
    with h5py.File(paths[2], 'r+') as f:
        for key in ('tracks', 'point_scores'):
            data = f[key][()][..., :100]
            del f[key]
            f[key] = data
        for key in ('track_occupancy',):
            data = f[key][()][:100]
            del f[key]
            f[key] = data
    code, _, err = run([*paths, '--rig', calib, '--out', tmp_path / 'short'], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert 'minimal_side_proofread.analysis.h5: 100 frames but' in err and '120 frames' in err
    assert not (tmp_path / 'short').exists()


def sleap_points(path):
    """(frames, nodes, 3) u, v, score and node names of a real analysis file."""
    import h5py
    with h5py.File(path, 'r') as f:
        tracks = f['tracks'][()][0].transpose(2, 1, 0)            # (frames, nodes, 2)
        scores = f['point_scores'][()][0].T                       # (frames, nodes)
        names = [n.decode() for n in f['node_names'][()]]
    return np.concatenate([tracks, scores[..., None]], -1), names


def write_dlc_csv(path, det, names):
    cols = pd.MultiIndex.from_product([['DLC_resnet50_mouse'], names,
                                       ['x', 'y', 'likelihood']],
                                      names=['scorer', 'bodyparts', 'coords'])
    pd.DataFrame(det.reshape(len(det), -1), index=pd.RangeIndex(len(det)),
                 columns=cols).to_csv(path)
    return path


def test_dlc_csv_with_empty_likelihood_cells_keeps_its_points(shared_data, tmp_path,
                                                               capsys):
    root = shared_data / SESSION
    dets = {}
    for cam in CAMS:
        dets[cam], names = sleap_points(root / cam / f'minimal_{cam}_proofread.analysis.h5')
    present = {cam: np.isfinite(d[..., :2]).all(-1) for cam, d in dets.items()}
    blank = {cam: np.zeros(present[cam].shape, bool) for cam in CAMS}
    blank['top'][:] = True                                    # a whole camera
    blank['mid'][::3, ::2] = True                             # scattered cells
    empty, ones = tmp_path / 'empty', tmp_path / 'ones'
    empty.mkdir()
    ones.mkdir()
    for cam in CAMS:
        d = dets[cam].copy()
        d[..., 2][blank[cam]] = np.nan                        # pandas writes NaN as ''
        write_dlc_csv(empty / f'{cam}DLC_resnet50_mouse.csv', d, names)
        d[..., 2][blank[cam]] = 1.0                           # the same, score 1 written
        write_dlc_csv(ones / f'{cam}DLC_resnet50_mouse.csv', d, names)
    line = (empty / 'topDLC_resnet50_mouse.csv').read_text().splitlines()[3].split(',')
    assert line[3] == '' and line[1] != ''                    # really empty cells
    code, text, err = run([*sorted(empty.glob('*.csv')), '--rig', root / 'calibration.toml',
                           '--out', tmp_path / 'a', '--fps', FPS, '--quiet'], capsys)
    assert code == 0, err
    assert 'x 4 cameras (back, mid, side, top)' in text
    unscored = sum(int((blank[c] & present[c]).sum()) for c in CAMS)
    total = sum(int(present[c].sum()) for c in CAMS)
    assert f'{unscored} of {total} detections have no score' in err
    assert 'cameras without 2D detections' not in err
    code, _, err = run([*sorted(ones.glob('*.csv')), '--rig', root / 'calibration.toml',
                        '--out', tmp_path / 'b', '--fps', FPS, '--quiet'], capsys)
    assert code == 0, err
    a = read_anipose_csv(tmp_path / 'a' / 'keypoints3d.csv')
    b = read_anipose_csv(tmp_path / 'b' / 'keypoints3d.csv')
    np.testing.assert_array_equal(a['X'], b['X'])
    np.testing.assert_array_equal(a['ncams'], b['ncams'])


def write_points_table(path, frames, det, names, cams=CAMS):
    lines = ['frame,camera,keypoint,u,v,score']
    for v, cam in enumerate(cams):
        for t, frame in enumerate(frames):
            for c, name in enumerate(names):
                u, w, s = det[v][t, c]
                if np.isfinite(u) and np.isfinite(w):
                    lines.append(f'{frame},{cam},{name},{float(u)!r},{float(w)!r},{float(s)!r}')
    path.write_text('\n'.join(lines) + '\n')
    return path


@pytest.mark.parametrize('frames', [np.arange(1, 31), np.array([50])],
                         ids=['numbered-from-1', 'one-frame-50'])
def test_points_table_keeps_its_frame_numbers(shared_data, tmp_path, capsys, frames):
    root = shared_data / SESSION
    det = []
    for cam in CAMS:
        d, names = sleap_points(root / cam / f'minimal_{cam}_proofread.analysis.h5')
        det.append(d[frames])
    table = write_points_table(tmp_path / 'points.csv', frames, det, names)
    code, text, err = run([table, '--rig', root / 'calibration.toml', '--out',
                           tmp_path / 'out', '--fps', FPS, '--export', 'csv,trc,nwb',
                           '--quiet'], capsys)
    assert code == 0, err
    assert f'{len(frames)} frames (from frame {frames[0]})' in text
    csv = read_anipose_csv(tmp_path / 'out' / 'keypoints3d.csv')
    np.testing.assert_array_equal(csv['fnum'], frames)
    trc = read_trc(tmp_path / 'out' / 'keypoints3d.trc')
    np.testing.assert_array_equal(trc['frames'], frames + 1)
    np.testing.assert_allclose(trc['times'], frames / FPS, rtol=0, atol=1e-9)
    assert trc['rate'] == FPS                     # the given rate, even for one frame
    times, source_frame, _ = read_nwb(tmp_path / 'out' / 'keypoints.nwb')
    np.testing.assert_allclose(times, frames / FPS, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(source_frame, frames)
