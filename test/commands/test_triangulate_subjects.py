"""`monet triangulate --subjects 2`: two synthetic subjects passing each other, their
per-camera instances in an order shuffled in every camera and frame, written as SLEAP
analysis files (2 tracks per camera, SLEAP's layout as the real files in
../shared/data/sleap_anipose_minimal_session hold it), as multi-animal DeepLabCut CSVs
and .h5 files (the `individuals` level), and as a points table with a `subject` column;
the 3D of each identity is its ground-truth subject throughout, in CSV, TRC and NWB."""
import numpy as np
import pandas as pd
import pytest

from monet_ros.cli import main as monet
from monet_ros.geometry import save_rig
from monet_ros.io.export_tables import read_anipose_csv, read_trc
from monet_ros.skeleton import load_skeleton
from monet_ros.synth.rig import RigConfig, make_rig
from monet_ros.synth.subjects import shuffled_instances, subjects_keypoints

FPS = 30.0
T = 60
SK = load_skeleton('human14')


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp('subjects')
    X = subjects_keypoints(SK, 2, np.arange(T) / FPS)           # frames 0..59 hold the pass
    cams = make_rig(RigConfig(num_cameras=4))
    save_rig(root / 'rig.yaml', cams)
    points, owner = shuffled_instances(X, cams, noise_px=0.5, seed=7)
    return root, X, cams, points, owner


def _write_sleap(folder, points):
    """One analysis file per camera: tracks (tracks, 2, nodes, frames) as h5py reads
    SLEAP's files, track k of frame t = instance slot k (shuffled: not an identity)."""
    import h5py
    folder.mkdir()
    V = points.shape[1]
    for v in range(V):
        with h5py.File(folder / f'cam{v}.analysis.h5', 'w') as f:
            f['tracks'] = points[:, v].transpose(1, 3, 2, 0)    # (2, 2, 14, T)
            f['track_occupancy'] = np.ones((T, 2), np.uint8)
            f['point_scores'] = np.full((2, SK.num_keypoints, T), 0.9)
            f['instance_scores'] = np.full((2, T), 0.9)
            f['node_names'] = np.array([k.encode() for k in SK.keypoints])
            f['track_names'] = np.array([b'track_0', b'track_1'])
            f['video_path'] = f'D:/videos\\cam{v}.mp4'
    return sorted(folder.glob('*.h5'))


def _write_dlc(folder, points, h5=False):
    """Multi-animal DeepLabCut predictions (scorer, individuals, bodyparts, coords): CSVs,
    or .h5 files as DeepLabCut writes them (pandas HDFStore, key 'df_with_missing')."""
    folder.mkdir()
    cols = pd.MultiIndex.from_product(
        [['DLC_dlcrnetms5_demo'], ['ind1', 'ind2'], list(SK.keypoints),
         ['x', 'y', 'likelihood']], names=['scorer', 'individuals', 'bodyparts', 'coords'])
    paths = []
    for v in range(points.shape[1]):
        xy = points[:, v]                                        # (T, 2, C, 2)
        data = np.concatenate([xy, np.full(xy.shape[:3] + (1,), 0.9)], axis=-1)
        frame = pd.DataFrame(data.reshape(T, -1), index=pd.RangeIndex(T), columns=cols)
        paths.append(folder / f'cam{v}DLC_dlcrnetms5_demo.{"h5" if h5 else "csv"}')
        if h5:
            frame.to_hdf(paths[-1], key='df_with_missing', format='table', mode='w')
        else:
            frame.to_csv(paths[-1])
    return paths


def _write_table(path, points):
    lines = ['frame,camera,keypoint,u,v,score,subject']
    for t in range(T):
        for v in range(points.shape[1]):
            for n, name in enumerate(('a', 'b')):
                for c, k in enumerate(SK.keypoints):
                    u, w = points[t, v, n, c]
                    lines.append(f'{t},cam{v},{k},{float(u)!r},{float(w)!r},0.9,{name}')
    path.write_text('\n'.join(lines) + '\n')
    return [path]


def _check(out, X, capsys):
    table = read_anipose_csv(out / 'keypoints3d.csv')
    assert table['keypoints'] == SK.keypoints
    assert len(table['fnum']) == 2 * T
    np.testing.assert_array_equal(np.bincount(table['fnum']), np.full(T, 2))
    ids = np.unique(table['subject'])
    assert len(ids) == 2                                         # no new identity
    owners = []
    for i in ids:
        mine = table['subject'] == i
        np.testing.assert_array_equal(table['fnum'][mine], np.arange(T))
        err = np.linalg.norm(table['X'][mine][:, None] - X, axis=-1).mean(-1)   # (T, 2)
        owner = np.argmin(err, axis=1)
        assert (owner == owner[0]).all(), f'identity {i} changes subject'
        assert err[:, owner[0]].max() < 0.02
        owners.append(owner[0])
        trc = read_trc(out / f'keypoints3d_subject{i}.trc')
        np.testing.assert_allclose(trc['X'], table['X'][mine], rtol=1e-12)
    assert sorted(owners) == [0, 1]
    from ndx_pose import MultiCameraPoseEstimation  # noqa: F401 (registers the types)
    from pynwb import NWBHDF5IO
    with NWBHDF5IO(str(out / 'keypoints.nwb'), 'r') as io:
        behavior = io.read().processing['behavior']
        for i in ids:
            pose = behavior[f'monet_pose_subject{i}']
            head = pose.pose_estimation_series[SK.keypoints[0]]
            np.testing.assert_allclose(head.data[:],
                                       table['X'][table['subject'] == i][:, 0], rtol=1e-12)
    text = capsys.readouterr().out
    assert '2 identities' in text and '2 births, 0 deaths' in text
    assert '0 of 480 instances matched in no other camera' in text
    return table


@pytest.mark.parametrize('kind', ['sleap', 'dlc', 'dlc_h5', 'frames'])
def test_two_subjects_round_trip(scene, kind, tmp_path, capsys):
    root, X, _, points, _ = scene
    if kind == 'sleap':
        paths = _write_sleap(tmp_path / 'sleap', points)
    elif kind in ('dlc', 'dlc_h5'):
        paths = _write_dlc(tmp_path / 'dlc', points, h5=kind == 'dlc_h5')
    else:
        paths = _write_table(tmp_path / 'points.csv', points)
    out = tmp_path / 'out'
    code = monet(['triangulate', *map(str, paths), '--rig', str(root / 'rig.yaml'),
                  '--out', str(out), '--subjects', '2', '--fps', str(FPS),
                  '--skeleton', 'human14'])
    assert code == 0
    _check(out, X, capsys)


def test_bad_subject_options_are_one_line(scene, tmp_path, capsys):
    root, _, _, points, _ = scene
    paths = [str(p) for p in _write_table(tmp_path / 'points.csv', points)]
    base = ['triangulate', *paths, '--rig', str(root / 'rig.yaml'), '--fps', '30']
    for extra, words in ((['--subjects', '0'], "'subjects': must be >= 1"),
                         (['--subjects', '2', '--export', 'npz'], 'npz'),
                         # named as typed (it said the association's field 'threshold_px')
                         (['--subjects', '2', '--association-px', 'nan'],
                          '--association-px: '),
                         # a table of several instances per camera without --subjects
                         ([], 'holds 2 instances per camera')):
        code = monet(base + ['--out', str(tmp_path / 'x'), *extra])
        err = capsys.readouterr().err.strip()
        assert code == 2 and words in err and '\n' not in err, err
        assert not (tmp_path / 'x').exists()


def test_tracker_options_decide_the_identities(scene, tmp_path, capsys):
    """--gate-mm, --max-speed-m-s, --max-missed-s and --min-keypoints reach the tracker:
    the outcome follows from the tracking rule (subjects.tracking) alone. A 0.001 mm gate
    that never grows (max speed 0) takes no subject of the next frame (the median
    displacement of a subject's joints is at least 10 mm per frame), so each identity
    lives one frame: its track dies at the first frame k with k / fps > --max-missed-s,
    when the subjects are born again (before, N = 2 tracks are alive and the subjects are
    untracked)."""
    root, X, _, points, _ = scene
    step = np.linalg.norm(np.median(np.diff(X, axis=0), axis=2), axis=-1)   # (T - 1, 2)
    assert step.min() > 0.01                        # m per frame, >> the gate
    paths = [str(p) for p in _write_table(tmp_path / 'points.csv', points)]
    base = ['triangulate', *paths, '--rig', str(root / 'rig.yaml'), '--fps', str(FPS),
            '--skeleton', 'human14', '--subjects', '2']
    out = tmp_path / 'gate'
    assert monet(base + ['--out', str(out), '--gate-mm', '0.001', '--max-speed-m-s', '0',
                         '--max-missed-s', '0.45']) == 0
    period = next(k for k in range(1, T) if k / FPS > 0.45)           # 14 frames
    born = np.arange(0, T, period)                                   # 0, 14, 28, 42, 56
    n = len(born)
    table = read_anipose_csv(out / 'keypoints3d.csv')
    np.testing.assert_array_equal(table['fnum'], np.repeat(born, 2))
    np.testing.assert_array_equal(table['subject'], np.arange(2 * n))   # never reused
    text = capsys.readouterr().out
    assert f'{2 * n} births, {2 * (n - 1)} deaths' in text
    assert f'{2 * (T - n)} untracked' in text
    # a subject of 14 keypoints never starts a track with --min-keypoints 15
    out = tmp_path / 'few'
    assert monet(base + ['--out', str(out), '--min-keypoints', str(SK.num_keypoints + 1)]) == 0
    text = capsys.readouterr().out
    assert '0 identities, 0 subject-frames, 0 births' in text
    assert f'{2 * T} untracked' in text
    assert len(read_anipose_csv(out / 'keypoints3d.csv')['fnum']) == 0


def test_missing_and_low_score_detections_are_counted(scene, tmp_path, capsys):
    """Nothing dropped silently with --subjects either: NaN rows, detections below
    --confidence-threshold and the keypoints a subject-frame could not triangulate are
    counted in the summary, as without --subjects (a keypoint missing everywhere, here
    the head, is named with every subject-frame)."""
    root, _, _, points, _ = scene
    points = points.copy()
    points[:, :, :, 0] = np.nan                        # head: never detected
    path = _write_table(tmp_path / 'points.csv', points)[0]
    lines = path.read_text().splitlines()
    low = [i for i in range(1, len(lines)) if ',neck,' in lines[i]][:7]
    for i in low:                                      # 7 neck detections scored 0.05
        lines[i] = lines[i].replace(',0.9,', ',0.05,')
    path.write_text('\n'.join(lines) + '\n')
    nan_rows = sum(',nan,' in line for line in lines)
    assert nan_rows == T * 4 * 2
    code = monet(['triangulate', str(path), '--rig', str(root / 'rig.yaml'), '--out',
                  str(tmp_path / 'out'), '--subjects', '2', '--fps', str(FPS),
                  '--skeleton', 'human14'])
    assert code == 0
    text = capsys.readouterr().out
    assert f'{nan_rows} rows NaN (no detection)' in text, text
    assert '7 below --confidence-threshold 0.1' in text, text
    assert f'keypoints not triangulated per keypoint over {2 * T} subject-frames: ' \
        f'head {2 * T}' in text, text


def test_instances_without_subjects_name_the_option_with_a_skeleton(scene, tmp_path,
                                                                      capsys):
    """A table of several instances per camera without --subjects says to give
    --subjects also when --skeleton is given (it said that 'ind1/head' is not a keypoint
    of the skeleton)."""
    root, _, _, points, _ = scene
    for kind in ('dlc', 'frames'):
        if kind == 'dlc':
            paths = _write_dlc(tmp_path / 'dlc', points)
        else:
            paths = _write_table(tmp_path / 'points.csv', points)
        code = monet(['triangulate', *map(str, paths), '--rig', str(root / 'rig.yaml'),
                      '--out', str(tmp_path / 'x'), '--fps', '30', '--skeleton', 'human14'])
        err = capsys.readouterr().err.strip()
        assert code == 2 and '\n' not in err, err
        assert 'instances per camera' in err and 'give --subjects N' in err, err
        assert not (tmp_path / 'x').exists()


def _spoil(points, seed):
    """A copy of points (T, V, N, C, 2) with ~5% of the points NaN and ~2% inf (in u or
    v), as trackers leave them."""
    rng = np.random.default_rng(seed)
    points = points.copy()
    draw = rng.random(points.shape[:-1])
    axis = rng.integers(0, 2, draw.shape)
    for value, hit in ((np.nan, draw < 0.05), (np.inf, (draw >= 0.05) & (draw < 0.07))):
        points[..., 0][hit & (axis == 0)] = value
        points[..., 1][hit & (axis == 1)] = value
    return points


@pytest.mark.parametrize('kind', ['sleap', 'dlc', 'dlc_h5'])
def test_missing_points_of_every_reader_are_counted(scene, kind, tmp_path, capsys):
    """NaN and inf points of SLEAP analysis files and multi-animal DeepLabCut tables are
    counted with --subjects as the NaN rows of a points table are: the readers dropped them
    before the count saw them (0 rows NaN), while without --subjects the grid counted them
    as missing views."""
    root, _, _, points, _ = scene
    points = _spoil(points, seed=3)
    missing = int((~np.isfinite(points).all(-1)).sum())          # brute force, (T, V, N, C)
    assert missing > 100
    if kind == 'sleap':
        paths = _write_sleap(tmp_path / 'sleap', points)
    else:
        paths = _write_dlc(tmp_path / 'dlc', points, h5=kind == 'dlc_h5')
    code = monet(['triangulate', *map(str, paths), '--rig', str(root / 'rig.yaml'),
                  '--out', str(tmp_path / 'out'), '--subjects', '2', '--fps', str(FPS),
                  '--skeleton', 'human14'])
    assert code == 0
    text = capsys.readouterr().out
    assert f'skipped 2D: {missing} rows NaN (no detection), 0 below' in text, text


def test_missing_points_of_slp_files_are_counted(shared_data, tmp_path, capsys):
    """The same for SLEAP .slp files: the real session's files, some predicted points made
    NaN / inf / invisible, counted against the files' own points (every instance is
    predicted: none is replaced by a user's)."""
    import shutil

    import h5py
    session = shared_data / 'sleap_anipose_minimal_session'
    rng = np.random.default_rng(5)
    paths, missing = [], 0
    for cam in ('back', 'mid', 'side', 'top'):
        (tmp_path / cam).mkdir()
        paths.append(tmp_path / cam / f'minimal_{cam}_proofread.slp')
        shutil.copy(session / cam / paths[-1].name, paths[-1])
        with h5py.File(paths[-1], 'r+') as f:
            inst, pred = f['instances'][()], f['pred_points'][()]
            assert (inst['instance_type'] == 1).all()
            draw = rng.random(len(pred))
            pred['x'][draw < 0.04] = np.nan
            pred['y'][(draw >= 0.04) & (draw < 0.06)] = np.inf
            pred['visible'][(draw >= 0.06) & (draw < 0.08)] = False
            f['pred_points'][...] = pred
            for i in inst:                              # brute force over the instances
                pts = pred[i['point_id_start']:i['point_id_end']]
                missing += int((~(pts['visible'].astype(bool) & np.isfinite(pts['x'])
                                  & np.isfinite(pts['y']))).sum())
    assert missing > 100
    code = monet(['triangulate', *map(str, paths), '--rig',
                  str(session / 'calibration.toml'), '--out', str(tmp_path / 'out'),
                  '--subjects', '1', '--fps', str(FPS)])
    assert code == 0
    text = capsys.readouterr().out
    assert f'skipped 2D: {missing} rows NaN (no detection), ' in text, text
