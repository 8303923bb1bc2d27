"""`monet process --filter`: the analysis files hold the filtered points, equal to the
MCAP's /monet/keypoints3d_filtered, with |filtered - raw| in mm against the unchanged
frame-by-frame /monet/keypoints3d."""
from helpers.recordings import noise_recording, small_checkpoint
import numpy as np
import pytest

from monet_ros.cli import main as monet
from monet_ros.io import cloud_to_keypoints3d, open_bag
from monet_ros.io.export_tables import read_anipose_csv, read_trc


@pytest.mark.parametrize('method', ['kalman', 'optim'])
def test_process_filter_writes_filtered_points_and_changes(tmp_path, capsys, method):
    import ndx_pose  # noqa: F401
    from pynwb import NWBHDF5IO

    noise_recording(tmp_path / 'rec', cameras=3, frames=6)
    model = small_checkpoint(tmp_path / 'model.pt')
    out = tmp_path / 'out'
    assert monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out', str(out),
                  '--no-track', '--quiet', '--threads', '1', '--skeleton', 'human14',
                  '--confidence-threshold', '0', '--threshold-px', '1000',
                  '--filter', method, '--max-gap-s', '0.1']) == 0
    text = capsys.readouterr().out
    assert f'monet process: filter {method}: ' in text
    bag = open_bag(out)
    raw = np.stack([cloud_to_keypoints3d(m.msg, units='m')['X'] for m in bag.messages(
        ['/monet/keypoints3d'])]).astype(np.float64)
    filtered = [cloud_to_keypoints3d(m.msg, units='m') for m in open_bag(out).messages(
        ['/monet/keypoints3d_filtered'])]
    assert len(filtered) == 6
    csv = read_anipose_csv(out / 'keypoints3d.csv')
    np.testing.assert_allclose(csv['X'], np.stack([f['X'] for f in filtered]), atol=1e-6)
    np.testing.assert_allclose(csv['score'], np.stack([f['confidence'] for f in filtered]),
                               atol=1e-6)
    assert set(csv['extra']) == {'change_mm', 'bridged'}
    change = np.linalg.norm(csv['X'] - raw, axis=-1) * 1000
    np.testing.assert_allclose(csv['extra']['change_mm'], change, atol=0.01, equal_nan=True)
    assert np.isfinite(csv['X']).any()
    np.testing.assert_array_equal(read_trc(out / 'keypoints3d.trc')['X'], csv['X'])
    with NWBHDF5IO(str(out / 'keypoints.nwb'), 'r') as io:
        behavior = io.read().processing['behavior']
        np.testing.assert_array_equal(
            behavior['monet_pose'].pose_estimation_series['neck'].data[:], csv['X'][:, 1])
        np.testing.assert_allclose(behavior['filter_change_mm'].data[:],
                                   csv['extra']['change_mm'], equal_nan=True)
        np.testing.assert_array_equal(behavior['filter_bridged'].data[:],
                                      csv['extra']['bridged'])
