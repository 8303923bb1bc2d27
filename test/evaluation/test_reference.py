"""Reference scoring: 2D labels triangulated to the 3D reference, TRC in mm / Y-up to
metres, exact px / mm figures for known offsets, coverage, names mapped or listed."""
from dataclasses import dataclass

from helpers.ring import random_points, ring_rig
import numpy as np
import pytest

from monet_ros.evaluation.reference import guess_format, load_reference, score
from monet_ros.io.export_tables import write_trc
from monet_ros.labels import LabelError, LabelOptions, label_rows, write_labels

KP = ('a', 'b', 'c')


@dataclass
class Index:
    stamps: np.ndarray
    cameras: list


@pytest.fixture
def scene():
    cams = ring_rig(3, width=640, height=480, focal=500.0)
    stamps = 10**18 + np.arange(5, dtype=np.int64) * 33_333_333
    X = np.stack([random_points(3, seed=s, spread=0.2) for s in range(5)])   # (T, C, 3)
    uv = np.stack([[c.project(X[t]) for c in cams] for t in range(5)])       # (T, V, C, 2)
    return Index(stamps, cams), X, uv


def test_labels_reference_is_triangulated_and_scored_exactly(scene, tmp_path):
    index, X, uv = scene
    labelled = [1, 3]
    path = tmp_path / 'labels.csv'
    write_labels(path, label_rows(index.stamps[labelled], [c.name for c in index.cameras],
                                  KP, uv[labelled]))
    assert guess_format(path) == 'labels'
    ref = load_reference(path, index, KP)
    assert ref.kind == '2d' and ref.unused == ()
    np.testing.assert_allclose(ref.X[labelled], X[labelled], atol=1e-9)
    assert np.isnan(ref.X[[0, 2, 4]]).all()
    # predictions: 2D off by (3, 4) px -> 5 px; 3D off by 10 mm along x, joint c missing
    pred_X = X.copy()
    pred_X[..., 0] += 0.010
    pred_X[:, 2] = np.nan
    pred2 = uv + np.array([3.0, 4.0])
    figures = score(ref, index.stamps, pred_X, pred2, (4.9, 5.1), (9.0, 11.0))
    assert figures['views_2d'] == 2 * 3 * 3
    assert figures['px_median'] == pytest.approx(5.0)
    assert figures['pck2d@4.9px'] == 0.0 and figures['pck2d@5.1px'] == 1.0
    assert figures['mm_median'] == pytest.approx(10.0, abs=1e-6)
    assert figures['coverage'] == pytest.approx(4 / 6)
    assert figures['pck3d@9mm'] == 0.0 and figures['pck3d@11mm'] == 1.0
    # a keypoint the model lacks is listed; renamed ones map
    rows = [(s, c, {'a': 'A'}.get(k, k), u, v) for s, c, k, u, v in
            label_rows(index.stamps[labelled], [c.name for c in index.cameras], KP,
                       uv[labelled])]
    write_labels(tmp_path / 'renamed.csv', rows + [(index.stamps[1], 'cam0', 'z', 1.0, 1.0)])
    ref = load_reference(tmp_path / 'renamed.csv', index, KP,
                         options=LabelOptions(keypoint_map=('A=a',)))
    assert ref.unused == ('z',)
    np.testing.assert_allclose(ref.X[1], X[1], atol=1e-9)


def test_trc_reference_in_mm_and_y_up(scene, tmp_path):
    index, X, _ = scene
    path = write_trc(tmp_path / 'ref.trc', KP, index.stamps, X * 1000.0, axes='yzx',
                     units='mm')
    ref = load_reference(path, index, KP, axes='yzx')
    assert ref.kind == '3d'
    np.testing.assert_allclose(ref.X, X, rtol=1e-12)
    figures = score(ref, index.stamps[:3], X[:3])       # 2 instants never predicted
    assert figures['mm_median'] == 0.0 and figures['coverage'] == pytest.approx(3 / 5)
    with pytest.raises(LabelError, match='no reference keypoint'):
        load_reference(path, index, ('x', 'y'))
    long = write_trc(tmp_path / 'long.trc', KP, 10**18 + np.arange(9) * 33_333_333, X[[0] * 9])
    ref = load_reference(long, index, KP)          # rows after the recording: counted
    assert ref.alignment['rule'] == 'nearest' and ref.alignment['rows'] == 9
    assert ref.alignment['rows_unmatched'] == 4 and ref.alignment['instants'] == 5
    np.testing.assert_allclose(ref.X, X[[0] * 5], rtol=1e-12)


def test_real_pose2sim_trc_and_its_projections_agree(shared_data, tmp_path):
    """Pose2Sim's .trc (Y-up, metres) on the derived 4-camera bag: projected into 3
    instants as frame-indexed labels with the calibration's camera names, the labels'
    triangulation returns the .trc points (real distortion, real geometry)."""
    from monet_ros.io.export_tables import read_trc
    from monet_ros.learning.recording_index import recording_index

    index = recording_index(shared_data / 'derived_pose2sim_4cam_mcap'
                            / 'pose2sim_balancing_4cam')
    trc_path = next((shared_data / 'pose2sim_demo_balancing').rglob('*.trc'))
    names = read_trc(trc_path)['keypoints']
    ref3d = load_reference(trc_path, index, names, axes='yzx')
    assert ref3d.kind == '3d' and np.isfinite(ref3d.X).all(-1).mean() > 0.99
    lines = ['frame,camera,keypoint,u,v']
    for t in (10, 50, 90):
        for cam in index.cameras:
            for k, (u, v) in zip(names, cam.project(ref3d.X[t])):
                lines.append(f'{t},{cam.name.replace("cam", "cam_")},{k},{float(u)!r},'
                             f'{float(v)!r}')
    (tmp_path / 'frames.csv').write_text('\n'.join(lines) + '\n')
    with pytest.raises(LabelError, match=r"field camera: 'cam_01' .* did you mean 'cam01'"):
        load_reference(tmp_path / 'frames.csv', index, names)
    ref2d = load_reference(tmp_path / 'frames.csv', index, names, options=LabelOptions(
        camera_map=tuple((f'cam_0{i}', f'cam0{i}') for i in range(1, 5))))
    np.testing.assert_allclose(ref2d.X[[10, 50, 90]], ref3d.X[[10, 50, 90]], atol=1e-6)
    figures = score(ref2d, index.stamps, ref3d.X, ref2d.points2d)
    assert figures['mm_median'] < 1e-3 and figures['px_median'] == 0.0
    assert figures['views_2d'] == 3 * 4 * 21 and figures['coverage'] == 1.0


def _trajectory(t):
    """(len(t), 3, 3) metres: three joints moving smoothly (not linearly) in time t (s)."""
    t = np.asarray(t, float)[:, None, None]
    base = np.array([[0.0, 0.0, 1.0], [0.1, -0.2, 1.2], [-0.3, 0.1, 0.9]])
    return base + 0.5 * np.sin(2 * np.pi * 1.7 * t + np.arange(3)[:, None]) * \
        np.array([1.0, 0.5, 0.2])


def test_reference_at_another_rate_is_matched_by_time(tmp_path):
    """A 25 Hz TRC (mm) on a 30 Hz recording: each instant gets the reference linearly
    interpolated at its own time (np.interp, independently), the row after the recording
    is counted, never pairs by index; 'refuse' says both rates; an anipose CSV with stamps
    or with fnum + its fps is put on the same times; same-rate rows with jittered stamps
    take the nearest."""
    from monet_ros.io.export_tables import write_anipose_csv
    cams = ring_rig(3, width=640, height=480, focal=500.0)
    stamps = 10**18 + 123 + np.round(np.arange(12) * 1e9 / 30).astype(np.int64)
    index = Index(stamps, cams)
    t_ref = np.arange(11) / 25.0                                   # 0 .. 0.4 s
    X_ref = _trajectory(t_ref)
    ref_stamps = 10**18 + np.round(t_ref * 1e9).astype(np.int64)
    path = write_trc(tmp_path / 'ref25.trc', KP, ref_stamps, X_ref * 1000.0, units='mm')
    ref = load_reference(path, index, KP)
    t_rec = (stamps - stamps[0]) / 1e9
    expected = np.stack([[[np.interp(t_rec, t_ref, X_ref[:, c, d])[i] for d in range(3)]
                          for c in range(3)] for i in range(12)])
    np.testing.assert_allclose(ref.X, expected, rtol=1e-9, atol=1e-12)
    assert ref.alignment['rule'] == 'linear'
    assert ref.alignment['reference_hz'] == pytest.approx(25.0)
    assert ref.alignment['recording_hz'] == pytest.approx(30.0, rel=1e-6)
    assert ref.alignment['rows'] == 11 and ref.alignment['rows_unmatched'] == 1  # 0.4 s
    assert ref.alignment['instants'] == 12
    # scored against the truth at the recording's times, the error is interpolation only
    figures = score(ref, stamps, _trajectory(t_rec))
    assert figures['mm_median'] < 25.0 and figures['coverage'] == 1.0
    with pytest.raises(LabelError, match=r'ref25.trc: the reference is at 25 Hz, the '
                       r'recording at 30 Hz: rows cannot be paired'):
        load_reference(path, index, KP, rate_policy='refuse')
    # anipose CSV with stamps (absolute) at 25 Hz: the same values
    nan = np.full(X_ref.shape[:2], np.nan)
    write_anipose_csv(tmp_path / 'ref25.csv', KP, stamps[0] + ref_stamps - 10**18, X_ref,
                      nan, nan, nan)
    np.testing.assert_allclose(load_reference(tmp_path / 'ref25.csv', index, KP).X, expected,
                               rtol=1e-9, atol=1e-12)
    # ... without stamps (anipose's own layout): fnum at --reference-fps 25
    lines = (tmp_path / 'ref25.csv').read_text().splitlines()
    (tmp_path / 'fnum.csv').write_text('\n'.join(line.rsplit(',', 1)[0] for line in lines))
    np.testing.assert_allclose(load_reference(tmp_path / 'fnum.csv', index, KP,
                                              reference_fps=25.0).X, expected, rtol=1e-9,
                               atol=1e-12)
    # same rate, stamps jittered by up to 2 ms: the nearest row, exactly
    jitter = stamps + np.array([0, 2, -2, 1, -1, 2, 0, -2, 1, 2, -1, 2]) * 1_000_000
    X30 = _trajectory(t_rec)
    write_anipose_csv(tmp_path / 'ref30.csv', KP, jitter[:10], X30[:10], nan[:10], nan[:10],
                      nan[:10])
    same = load_reference(tmp_path / 'ref30.csv', index, KP)
    assert same.alignment['rule'] == 'nearest' and same.alignment['instants'] == 10
    np.testing.assert_array_equal(same.X[:10], X30[:10])
    assert np.isnan(same.X[10:]).all()


def test_real_pose2sim_trc_with_body25b_is_projected_for_2d(shared_data):
    """`keypoint_map=('body25b',)` alone puts Pose2Sim's 21 markers on human14 (14 used,
    7 listed); the 2D reference is its projection: OpenCV's projectPoints of the same 3D
    points with the recording's cameras (independent), NaN only outside the images."""
    from helpers.scenes import cv2_project

    from monet_ros.io.export_tables import read_trc
    from monet_ros.learning.recording_index import recording_index
    from monet_ros.skeleton import load_skeleton

    index = recording_index(shared_data / 'derived_pose2sim_4cam_mcap'
                            / 'pose2sim_balancing_4cam')
    trc_path = next((shared_data / 'pose2sim_demo_balancing').rglob('*.trc'))
    keypoints = load_skeleton('human14').keypoints
    ref = load_reference(trc_path, index, keypoints, axes='yzx',
                         options=LabelOptions(keypoint_map=('body25b',)))
    assert ref.unused == ('RBigToe', 'RSmallToe', 'RHeel', 'LBigToe', 'LSmallToe', 'LHeel',
                          'Nose')
    trc = read_trc(trc_path, axes='yzx')
    np.testing.assert_array_equal(ref.X[:, keypoints.index('r_hip')],
                                  trc['X'][:, trc['keypoints'].index('RHip')])
    np.testing.assert_array_equal(ref.X[:, keypoints.index('head')],
                                  trc['X'][:, trc['keypoints'].index('Head')])
    assert ref.alignment['rule'] == 'nearest' and ref.alignment['instants'] == 100
    for v, cam in enumerate(index.cameras):
        uv = cv2_project(cam, ref.X.reshape(-1, 3)).reshape(100, 14, 2)
        seen = np.isfinite(ref.points2d[:, v]).all(-1)
        inside = np.isfinite(uv).all(-1) & (uv >= -0.5).all(-1) & \
            (uv[..., 0] <= cam.width - 0.5) & (uv[..., 1] <= cam.height - 0.5)
        np.testing.assert_array_equal(seen, inside)
        assert seen.mean() > 0.95
        np.testing.assert_allclose(ref.points2d[:, v][seen], uv[seen], atol=1e-6)
