"""`monet triangulate` on the real Pose2Sim demo (4 calibrated cameras, OpenPose 2D with
likelihoods): DeepLabCut prediction CSVs (written by pandas as DeepLabCut does), SLEAP
analysis H5 files and a frame-indexed table of the same points give the same 3D, equal to
geometry.triangulate of the same points on the views the robust rule kept; bad input is
one line and exit 2."""
import numpy as np
import pandas as pd
import pytest

from monet_ros.cli import main as monet
from monet_ros.geometry import load_rig, triangulate, triangulate_robust
from monet_ros.geometry.pose2sim import BODY_25B_IDS, read_openpose_folder
from monet_ros.io.export_tables import read_anipose_csv, read_trc

TRIAL = 'pose2sim_demo_balancing/S00_P00_SingleParticipant/S00_P00_T01_BalancingTrial'
CALIB = 'pose2sim_demo_balancing/S00_Calibration/Calib_qualisys.toml'
NAMES = list(BODY_25B_IDS)
MAP = ['--camera-map', 'cam01=cam_01,cam02=cam_02,cam03=cam_03,cam04=cam_04']
FRAMES = 40


@pytest.fixture(scope='module')
def pose2sim(shared_data):
    """(rig path, cameras, det (V, T, C, 3) u, v, likelihood, NaN where no person)."""
    folders = sorted((shared_data / TRIAL / 'pose-associated').glob('cam*_json'))
    det = np.stack([read_openpose_folder(f) for f in folders])[:, :FRAMES]
    det = det[:, :, [BODY_25B_IDS[n] for n in NAMES]]
    return shared_data / CALIB, load_rig(shared_data / CALIB), det


def write_dlc(folder, det, frames=None):
    """One DeepLabCut prediction CSV per camera, <cam>DLC_resnet50_demo.csv."""
    folder.mkdir(exist_ok=True)
    cols = pd.MultiIndex.from_product([['DLC_resnet50_demo'], NAMES, ['x', 'y', 'likelihood']],
                                      names=['scorer', 'bodyparts', 'coords'])
    paths = []
    for v in range(det.shape[0]):
        n = det.shape[1] if frames is None else frames[v]
        frame = pd.DataFrame(det[v, :n].reshape(n, -1), index=pd.RangeIndex(n), columns=cols)
        paths.append(folder / f'cam0{v + 1}DLC_resnet50_demo.csv')
        frame.to_csv(paths[-1])
    return paths


def write_table(path, det, cameras=('cam01', 'cam02', 'cam03', 'cam04'), header=None):
    lines = [header or 'frame,camera,keypoint,u,v,score']
    for v, cam in enumerate(cameras):
        for t in range(det.shape[1]):
            for c, name in enumerate(NAMES):
                u, w, s = det[v, t, c]
                lines.append(f'{t},{cam},{name},{float(u)!r},{float(w)!r},{float(s)!r}')
    path.write_text('\n'.join(lines) + '\n')
    return path


def expected_3d(cameras, det, inliers, threshold=0.3):
    """geometry.triangulate of the points on the inlier views (likelihood weights), and
    triangulate_robust's answer on all of them."""
    V, T, C = det.shape[:3]
    points = det[..., :2].reshape(V, T * C, 2)
    w = np.where(det[..., 2] >= threshold, det[..., 2], 0.0).reshape(V, T * C)
    w = np.nan_to_num(w)
    plain = triangulate(points, cameras, w * inliers.transpose(1, 0, 2).reshape(V, T * C))
    robust, _ = triangulate_robust(points, cameras, w, threshold_px=15.0)
    return plain.reshape(T, C, 3), robust.reshape(T, C, 3)


def run(args, capsys):
    code = monet(['triangulate', *map(str, args)])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_dlc_csv_and_points_table_give_the_triangulation_of_the_same_points(
        pose2sim, tmp_path, capsys):
    rig, cameras, det = pose2sim
    dlc = write_dlc(tmp_path / 'dlc', det)
    code, text, _ = run([*dlc, '--rig', rig, *MAP, '--out', tmp_path / 'a',
                         '--confidence-threshold', '0.3', '--export', 'csv,trc,nwb,npz',
                         '--fps', 60], capsys)
    assert code == 0, text
    a = read_anipose_csv(tmp_path / 'a' / 'keypoints3d.csv')
    assert a['keypoints'] == tuple(NAMES) and a['X'].shape == (FRAMES, 21, 3)
    assert 'extra' in a and not a['extra']              # no filter columns without a filter
    npz = np.load(tmp_path / 'a' / 'detections2d.npz')
    assert npz['cameras'].tolist() == ['cam_01', 'cam_02', 'cam_03', 'cam_04']
    plain, robust = expected_3d(cameras, det, npz['inliers'])
    np.testing.assert_allclose(a['X'], plain, atol=1e-9, equal_nan=True)
    np.testing.assert_allclose(a['X'], robust, atol=1e-9, equal_nan=True)
    ok = np.isfinite(a['X']).all(-1)
    assert ok.sum() > 0.98 * ok.size
    np.testing.assert_array_equal(a['ncams'][ok], npz['inliers'].sum(1)[ok])
    trc = read_trc(tmp_path / 'a' / 'keypoints3d.trc')
    np.testing.assert_array_equal(trc['X'], a['X'])
    assert trc['rate'] == 60.0
    # every skipped view is counted: missing cells and low scores
    present = np.isfinite(det[..., 0])
    low = present & ~(np.nan_to_num(det[..., 2], nan=-1) >= 0.3)
    assert (f'{(~present).sum()} of {det[..., 0].size} missing (no detection), '
            f'{low.sum()} below --confidence-threshold 0.3') in text
    assert f'{int(ok.sum())} of {ok.size} points triangulated' in text
    # the same points as a frame-indexed table: the same file content
    table = write_table(tmp_path / 'points.csv', det)
    code, text, _ = run([table, '--rig', rig, *MAP, '--out', tmp_path / 'b',
                         '--confidence-threshold', '0.3', '--fps', 60], capsys)
    assert code == 0, text
    # the summary counts the table's rows and names its format (not 'N frames rows')
    assert f'keypoints from {det[..., 0].size} rows of the frames format;' in text, text
    b = read_anipose_csv(tmp_path / 'b' / 'keypoints3d.csv')
    np.testing.assert_array_equal(b['X'], a['X'])
    np.testing.assert_array_equal(b['score'], a['score'])


def test_sleap_analysis_files_give_the_same_3d(pose2sim, tmp_path, capsys):
    import h5py
    rig, cameras, det = pose2sim
    table = write_table(tmp_path / 'points.csv', det)
    assert run([table, '--rig', rig, *MAP, '--out', tmp_path / 'ref', '--fps', 60],
               capsys)[0] == 0
    paths = []
    for v in range(4):            # SLEAP's analysis layout: documented shapes, transposed
        tracks = det[v, :, :, :2][..., None]                      # (frames, nodes, 2, 1)
        paths.append(tmp_path / f'cam0{v + 1}.analysis.h5')
        with h5py.File(paths[-1], 'w') as f:
            f['tracks'] = tracks.T
            f['track_occupancy'] = np.ones((1, FRAMES), np.uint8).T
            f['node_names'] = np.array([n.encode() for n in NAMES], dtype='S')
            f['point_scores'] = np.nan_to_num(det[v, :, :, 2])[..., None].T
            f['video_path'] = f'/videos/cam0{v + 1}.mp4'
    code, text, _ = run([*paths, '--rig', rig, *MAP, '--out', tmp_path / 's', '--fps', 60],
                        capsys)
    assert code == 0, text
    assert 'rows of the sleap format' in text
    s = read_anipose_csv(tmp_path / 's' / 'keypoints3d.csv')
    ref = read_anipose_csv(tmp_path / 'ref' / 'keypoints3d.csv')
    np.testing.assert_array_equal(s['X'], ref['X'])


def test_anipose_pose_2d_folder_gives_the_same_3d(pose2sim, tmp_path, capsys):
    rig, cameras, det = pose2sim
    table = write_table(tmp_path / 'points.csv', det)
    assert run([table, '--rig', rig, *MAP, '--out', tmp_path / 'ref', '--fps', 60],
               capsys)[0] == 0
    pose = tmp_path / 'pose-2d'
    pose.mkdir()
    cols = pd.MultiIndex.from_product([['DLC_resnet50_demo'], NAMES, ['x', 'y', 'likelihood']],
                                      names=['scorer', 'bodyparts', 'coords'])
    for v in range(4):                  # anipose's pose-2d: DeepLabCut's H5 per camera
        pd.DataFrame(det[v].reshape(FRAMES, -1), index=pd.RangeIndex(FRAMES),
                     columns=cols).to_hdf(pose / f'trial-cam0{v + 1}.h5',
                                          key='df_with_missing', mode='w')
    code, text, _ = run([pose, '--rig', rig, *MAP, '--out', tmp_path / 'a', '--fps', 60],
                        capsys)
    assert code == 0, text
    assert 'rows of the anipose format' in text
    np.testing.assert_array_equal(read_anipose_csv(tmp_path / 'a' / 'keypoints3d.csv')['X'],
                                  read_anipose_csv(tmp_path / 'ref' / 'keypoints3d.csv')['X'])


def test_filter_adds_change_and_bridged_columns(pose2sim, tmp_path, capsys):
    rig, cameras, det = pose2sim
    table = write_table(tmp_path / 'points.csv', det)
    base = [table, '--rig', rig, *MAP, '--fps', 60]
    assert run([*base, '--out', tmp_path / 'raw'], capsys)[0] == 0
    code, text, _ = run([*base, '--out', tmp_path / 'k', '--filter', 'kalman'], capsys)
    assert code == 0 and 'filter kalman: ' in text
    raw = read_anipose_csv(tmp_path / 'raw' / 'keypoints3d.csv')
    k = read_anipose_csv(tmp_path / 'k' / 'keypoints3d.csv')
    assert set(k['extra']) == {'change_mm', 'bridged'}
    change = np.linalg.norm(k['X'] - raw['X'], axis=-1) * 1000
    np.testing.assert_allclose(k['extra']['change_mm'], change, rtol=1e-12, equal_nan=True)
    bridged = np.isfinite(k['X']).all(-1) & ~np.isfinite(raw['X']).all(-1)
    np.testing.assert_array_equal(k['extra']['bridged'] == 1, bridged)
    assert bridged.any()                        # the Nose frames Pose2Sim could not do
    assert np.nanmedian(change) < 30.0          # a smoother, not a different trajectory


def one_line_error(code, err, *needles):
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in err, err
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_bad_input_is_one_line_and_exit_2(pose2sim, tmp_path, capsys):
    rig, cameras, det = pose2sim
    # a camera the rig does not have
    table = write_table(tmp_path / 'unknown.csv', det, cameras=('cam01', 'cam02', 'cam03',
                                                                 'cam09'))
    code, _, err = run([table, '--rig', rig, *MAP, '--out', tmp_path / 'o1'], capsys)
    one_line_error(code, err, "field camera: 'cam09' is not a camera of the rig")
    # a wrong column set
    wrong = write_table(tmp_path / 'wrong.csv', det, header='frame,camera,keypoint,x,y,score')
    code, _, err = run([wrong, '--rig', rig, *MAP, '--out', tmp_path / 'o2'], capsys)
    one_line_error(code, err, 'wrong.csv:1: header is', 'frame,camera,keypoint,u,v')
    # per-camera files of different lengths
    dlc = write_dlc(tmp_path / 'dlc', det, frames=[FRAMES, FRAMES, FRAMES - 5, FRAMES])
    code, _, err = run([*dlc, '--rig', rig, *MAP, '--out', tmp_path / 'o3'], capsys)
    one_line_error(code, err, f'cam03DLC_resnet50_demo.csv: {FRAMES - 5} frames but',
                   f'{FRAMES} frames')
    # a filter without the frame rate
    ok = write_table(tmp_path / 'ok.csv', det)
    code, _, err = run([ok, '--rig', rig, *MAP, '--out', tmp_path / 'o4', '--filter', 'optim'],
                       capsys)
    one_line_error(code, err, '--fps')
    # a keypoint the skeleton does not have
    code, _, err = run([ok, '--rig', rig, *MAP, '--out', tmp_path / 'o5',
                        '--skeleton', 'human14'], capsys)
    one_line_error(code, err, "field keypoint: 'Nose' is not a keypoint of the skeleton")
    for k in range(1, 6):
        assert not (tmp_path / f'o{k}').exists()
