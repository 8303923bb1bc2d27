"""NWB + ndx-pose export read back with pynwb: 3D series, per-camera 2D detections and
calibrated cameras, exact values and timestamps."""
from helpers.ring import ring_rig
import numpy as np

from monet_ros.io.export_nwb import write_nwb


def test_nwb_round_trip(tmp_path):
    import ndx_pose  # noqa: F401  (registers the extension for reading)
    from pynwb import NWBHDF5IO

    cams = ring_rig(3)
    rng = np.random.default_rng(0)
    T, C = 5, 2
    stamps = 1_700_000_000_000_000_000 + np.arange(T) * 33_333_333
    X = rng.normal(size=(T, C, 3))
    X[2, 1] = np.nan
    score = rng.uniform(size=(T, C))
    points2d = rng.uniform(0, 100, (T, 3, C, 2))
    points2d[4, 2] = np.nan
    conf2d = rng.uniform(size=(T, 3, C))
    path = write_nwb(tmp_path / 'k.nwb', ('head', 'tail'), stamps, X, score, cams, points2d,
                     conf2d, edges=[[0, 1]])
    with NWBHDF5IO(str(path), 'r') as io:
        nwb = io.read()
        assert nwb.session_start_time.timestamp() == 1_700_000_000
        behavior = nwb.processing['behavior']
        pose = behavior['monet_pose']
        assert list(pose.pose_estimation_series) == ['head', 'tail']
        for c, name in enumerate(('head', 'tail')):
            series = pose.pose_estimation_series[name]
            np.testing.assert_array_equal(series.data[:], X[:, c])
            np.testing.assert_array_equal(series.confidence[:], score[:, c])
            np.testing.assert_allclose(series.timestamps[:], (stamps - stamps[0]) / 1e9)
            assert series.unit == 'meters'
        assert sorted(pose.pose_estimations) == ['cam0_2d', 'cam1_2d', 'cam2_2d']
        for v, cam in enumerate(cams):
            pe = pose.pose_estimations[f'{cam.name}_2d']
            np.testing.assert_array_equal(pe.device.intrinsic_matrix[:], cam.K)
            np.testing.assert_array_equal(pe.device.rotation_matrix[:], cam.R)
            np.testing.assert_array_equal(pe.device.translation_vector[:], cam.t)
            for c, name in enumerate(('head', 'tail')):
                s = pe.pose_estimation_series[name]
                np.testing.assert_array_equal(s.data[:], points2d[:, v, c])
                np.testing.assert_array_equal(s.confidence[:], conf2d[:, v, c])
        skeleton = behavior['Skeletons'].skeletons['skeleton']
        assert list(skeleton.nodes[:]) == ['head', 'tail']
        np.testing.assert_array_equal(skeleton.edges[:], [[0, 1]])
    assert not list(tmp_path.glob('*.tmp*'))
