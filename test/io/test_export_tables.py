"""anipose CSV and TRC: exact round trips, the real Pose2Sim .trc read and rewritten, gaps
kept in frame numbers, errors naming the file and line."""
import numpy as np
import pytest

from monet_ros.io.export_tables import (
    ExportError,
    frame_numbers,
    read_anipose_csv,
    read_trc,
    write_anipose_csv,
    write_trc,
)

KP = ('nose', 'l_hip', 'r_hip')
STAMPS = 10**18 + np.array([0, 1, 2, 4]) * 16_666_667        # 60 Hz, instant 3 missing


def arrays(seed=0):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(4, 3, 3))
    X[1, 2] = np.nan
    error = rng.uniform(0, 5, (4, 3))
    ncams = rng.integers(2, 5, (4, 3)).astype(float)
    score = rng.uniform(0, 1, (4, 3))
    error[1, 2] = ncams[1, 2] = score[1, 2] = np.nan
    return X, error, ncams, score


def test_frame_numbers_keep_gaps():
    np.testing.assert_array_equal(frame_numbers(STAMPS), [0, 1, 2, 4])


def test_anipose_csv_round_trip_is_exact(tmp_path):
    X, error, ncams, score = arrays()
    path = write_anipose_csv(tmp_path / 'p.csv', KP, STAMPS, X, error, ncams, score)
    header = path.read_text().splitlines()[0].split(',')
    assert header[:6] == ['nose_x', 'nose_y', 'nose_z', 'nose_error', 'nose_ncams',
                          'nose_score'] and header[-2:] == ['fnum', 'stamp_ns']
    got = read_anipose_csv(path)
    assert got['keypoints'] == KP
    np.testing.assert_array_equal(got['X'], X)                    # bit-exact, NaN kept
    np.testing.assert_array_equal(got['error'], error)
    np.testing.assert_array_equal(got['ncams'], ncams)
    np.testing.assert_array_equal(got['score'], score)
    np.testing.assert_array_equal(got['fnum'], [0, 1, 2, 4])
    np.testing.assert_array_equal(got['stamps_ns'], STAMPS)
    # an anipose file of its own (pandas, with the extra M_/center_ columns) reads too
    import pandas as pd
    df = pd.DataFrame({'nose_x': [1.0], 'nose_y': [2.0], 'nose_z': [3.0], 'nose_error': [0.5],
                       'nose_ncams': [3], 'nose_score': [0.9], 'M_00': [1.0],
                       'center_0': [0.0], 'fnum': [7]})
    df.to_csv(tmp_path / 'anipose.csv', index=False)
    got = read_anipose_csv(tmp_path / 'anipose.csv')
    assert got['keypoints'] == ('nose',) and got['fnum'].tolist() == [7]
    np.testing.assert_array_equal(got['X'], [[[1.0, 2.0, 3.0]]])
    (tmp_path / 'bad.csv').write_text('nose_x,nose_y,nose_z\n1,2,abc\n')
    with pytest.raises(ExportError, match=r"bad.csv:2: column nose_z: 'abc' is not a number"):
        read_anipose_csv(tmp_path / 'bad.csv')


@pytest.mark.parametrize('axes', ['xyz', 'yzx'])
def test_trc_round_trip_is_exact(tmp_path, axes):
    X, *_ = arrays(1)
    path = write_trc(tmp_path / 'p.trc', KP, STAMPS, X, axes=axes)
    lines = path.read_text().splitlines()
    assert lines[0] == 'PathFileType\t4\t(X/Y/Z)\tp.trc'
    assert lines[2].split('\t')[:5] == ['60', '60', '4', '3', 'm']
    assert lines[3] == 'Frame#\tTime\tnose\t\t\tl_hip\t\t\tr_hip\t\t'
    got = read_trc(path, axes=axes)
    assert got['keypoints'] == KP and got['rate'] == 60.0
    np.testing.assert_array_equal(got['frames'], [1, 2, 3, 5])
    # Time = seconds from the first instant's stamp (the NWB timestamps' base)
    np.testing.assert_array_equal(got['times'], (STAMPS - STAMPS[0]) / 1e9)
    np.testing.assert_array_equal(got['X'], X)
    if axes == 'yzx':                       # stored Y-up: trc = world(Y, Z, X)
        np.testing.assert_array_equal(read_trc(path)['X'], X[..., [1, 2, 0]])


def test_real_pose2sim_trc_reads_and_rewrites_identically(shared_data, tmp_path):
    path = next((shared_data / 'pose2sim_demo_balancing').rglob('*.trc'))
    trc = read_trc(path)
    assert trc['X'].shape == (100, 21, 3) and trc['rate'] == 60.0 and trc['units'] == 'm'
    assert trc['keypoints'][:3] == ('RHip', 'RKnee', 'RAnkle')
    assert trc['frames'][0] == 1 and trc['times'][0] == pytest.approx(1 / 60)
    first = path.read_text().splitlines()[5].split('\t')
    assert trc['X'][0, 0, 0] == float(first[2])
    stamps = 10**18 + (trc['frames'] - 1) * round(1e9 / 60)
    ours = write_trc(tmp_path / path.name, trc['keypoints'], stamps, trc['X'])
    back = read_trc(ours)
    np.testing.assert_array_equal(back['X'], trc['X'])
    np.testing.assert_array_equal(back['frames'], trc['frames'])
    # Pose2Sim's Time is Frame# / DataRate (one period after ours, which starts at 0.0)
    np.testing.assert_allclose(back['times'] + 1 / 60, trc['times'], rtol=1e-6)
    assert back['times'][0] == 0.0
    # same header lines as Pose2Sim's own file, apart from the file name
    theirs = path.read_text().splitlines()
    mine = ours.read_text().splitlines()
    assert mine[1] == theirs[1] and mine[3] == theirs[3] and mine[4] == theirs[4]
    assert mine[2].split('\t')[:5] == theirs[2].split('\t')[:5]


def test_trc_errors_name_file_and_line(tmp_path):
    (tmp_path / 'x.trc').write_text('hello\n')
    with pytest.raises(ExportError, match=r'x.trc:1: not a TRC file'):
        read_trc(tmp_path / 'x.trc')
