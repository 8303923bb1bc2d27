"""`monet process` writes, beside its MCAP, the anipose CSV, the TRC, the NWB (ndx-pose)
and the 2D detections with their crop cameras - all equal to the /monet/keypoints3d it
published, on one time base (TRC Time = NWB timestamps, first instant 0.0) - and prints
dropout, inlier views and that reprojection error is agreement."""
from helpers.recordings import noise_recording, small_checkpoint
import numpy as np

from monet_ros.cli import main as monet
from monet_ros.io import cloud_to_keypoints3d, open_bag
from monet_ros.io.export_tables import read_anipose_csv, read_trc


def test_process_writes_analysis_files_equal_to_its_mcap(tmp_path, capsys):
    import ndx_pose  # noqa: F401
    from pynwb import NWBHDF5IO

    rig, stamps = noise_recording(tmp_path / 'rec', cameras=3, frames=4)
    model = small_checkpoint(tmp_path / 'model.pt')
    out = tmp_path / 'out'
    assert monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out', str(out),
                  '--no-track', '--quiet', '--threads', '1', '--skeleton', 'human14',
                  '--confidence-threshold', '0', '--threshold-px', '1000']) == 0
    text = capsys.readouterr().out
    assert 'per-joint dropout (not triangulated): head ' in text
    assert 'mean inlier views per joint: head ' in text
    assert 'reprojection error measures agreement between the views used, not accuracy' in text
    clouds = [cloud_to_keypoints3d(m.msg, units='m') for m in open_bag(out).messages(
        ['/monet/keypoints3d'])]
    X_mcap = np.stack([c['X'] for c in clouds]).astype(np.float64)
    csv = read_anipose_csv(out / 'keypoints3d.csv')
    assert len(csv['keypoints']) == 14 and csv['keypoints'][0] == 'head'
    np.testing.assert_array_equal(csv['stamps_ns'], stamps)
    np.testing.assert_array_equal(csv['fnum'], np.arange(4))
    np.testing.assert_allclose(csv['X'], X_mcap, rtol=1e-6, atol=1e-6)   # MCAP is float32
    np.testing.assert_array_equal(csv['ncams'], np.stack([c['num_views'] for c in clouds]))
    assert np.isfinite(csv['X']).any()
    trc = read_trc(out / 'keypoints3d.trc')
    np.testing.assert_array_equal(trc['X'], csv['X'])
    det = np.load(out / 'detections2d.npz')
    assert det['cameras'].tolist() == [c.name for c in rig]
    assert det['points2d'].shape == (4, 3, 14, 2) and det['K_heat'].shape == (4, 3, 3, 3)
    # the error column is the mean pixel distance between the 3D point's projection and the
    # stored 2D detections of the inlier views (an independent recomputation)
    for t in range(4):
        for c in range(14):
            if not np.isfinite(csv['X'][t, c]).all():
                continue
            views = np.flatnonzero(det['inliers'][t, :, c])
            dist = [np.linalg.norm(rig[v].project(csv['X'][t, c][None])[0]
                                   - det['points2d'][t, v, c]) for v in views]
            assert abs(np.mean(dist) - csv['error'][t, c]) < 1e-6
            assert len(views) == csv['ncams'][t, c]
    # one time base (item 11): TRC Time = NWB timestamps = (stamp - first stamp) / 1e9 s,
    # the first instant 0.0; NWB's session_start_time + timestamp = the stamp (to 1 us)
    since_first = (np.asarray(stamps) - stamps[0]) / 1e9
    np.testing.assert_array_equal(trc['times'], since_first)
    assert trc['times'][0] == 0.0
    with NWBHDF5IO(str(out / 'keypoints.nwb'), 'r') as io:
        nwb = io.read()
        pose = nwb.processing['behavior']['monet_pose']
        for series in (pose.pose_estimation_series['head'],
                       pose.pose_estimations['cam0_2d'].pose_estimation_series['head']):
            np.testing.assert_array_equal(series.timestamps[:], trc['times'])
        start_us = round(nwb.session_start_time.timestamp() * 1e6)
        assert start_us == stamps[0] // 1000
        np.testing.assert_array_equal(pose.pose_estimation_series['head'].data[:],
                                      csv['X'][:, 0])
        np.testing.assert_array_equal(
            pose.pose_estimations['cam1_2d'].pose_estimation_series['neck'].data[:],
            det['points2d'][:, 1, 1])


def test_a_skeleton_file_without_bones_exports_every_format(tmp_path, capsys):
    """README's skeleton format makes bones optional: such a skeleton still writes the NWB
    (its Skeleton has no edges), with the file's keypoint names."""
    from pynwb import NWBHDF5IO

    from monet_ros.skeleton import load_skeleton
    names = list(load_skeleton('human14').keypoints)
    skeleton = tmp_path / 'nobones.yaml'
    skeleton.write_text(f'name: nobones\nkeypoints: [{", ".join(names)}]\n')
    noise_recording(tmp_path / 'rec', cameras=2, frames=2)
    model = small_checkpoint(tmp_path / 'model.pt')
    out = tmp_path / 'out'
    assert monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out', str(out),
                  '--no-track', '--quiet', '--threads', '1', '--skeleton', str(skeleton),
                  '--export', 'nwb']) == 0, capsys.readouterr().err
    with NWBHDF5IO(str(out / 'keypoints.nwb'), 'r') as io:
        nwb = io.read()
        bones = nwb.processing['behavior']['Skeletons'].skeletons['skeleton']
        assert list(bones.nodes[:]) == names and len(bones.edges[:]) == 0


def test_export_option_is_checked(tmp_path, capsys):
    noise_recording(tmp_path / 'rec', cameras=2, frames=1)
    model = small_checkpoint(tmp_path / 'model.pt')
    args = ['process', str(tmp_path / 'rec'), '--model', str(model), '--quiet']
    assert monet(args + ['--out', str(tmp_path / 'a'), '--export', 'csv,xls']) == 2
    assert "--export: unknown format 'xls'" in capsys.readouterr().err
    assert monet(args + ['--out', str(tmp_path / 'b'), '--export', 'none']) == 0
    assert sorted(p.suffix for p in (tmp_path / 'b').iterdir()) == ['.mcap', '.yaml']
