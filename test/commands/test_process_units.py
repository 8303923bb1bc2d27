"""`monet process` with a rig in mm: the MCAP holds ROS messages, so /monet/keypoints3d and
/monet/keypoints3d_filtered are in metres (REP 103), equal to those of the same rig in m,
while the analysis files (CSV, TRC) stay in the rig's unit, mm, and say so. The tracked
crop follows the same numbers in both units."""
from helpers.recordings import noise_recording, small_checkpoint
import numpy as np

from monet_ros.cli import main as monet
from monet_ros.geometry import save_rig
from monet_ros.geometry.units import rescale
from monet_ros.io import cloud_to_keypoints3d, open_bag
from monet_ros.io.export_tables import read_anipose_csv, read_csv_units, read_trc


def process(tmp_path, rig, units, model):
    path = tmp_path / f'rig_{units}.yaml'
    save_rig(path, rescale(rig, units))
    out = tmp_path / units
    assert monet(['process', str(tmp_path / 'rec'), '--rig', str(path), '--model', str(model),
                  '--out', str(out), '--quiet', '--threads', '1', '--skeleton', 'human14',
                  '--confidence-threshold', '0', '--threshold-px', '1000',
                  '--filter', 'kalman', '--max-gap-s', '0.1', '--export', 'csv,trc']) == 0
    bag = open_bag(out)
    mcap = {topic: np.stack([cloud_to_keypoints3d(m.msg, units='m')['X']
                             for m in bag.messages([topic])]).astype(np.float64)
            for topic in ('/monet/keypoints3d', '/monet/keypoints3d_filtered')}
    return mcap, out


def test_process_on_a_mm_rig_writes_metres_to_its_mcap_and_mm_to_its_files(tmp_path):
    rig, _ = noise_recording(tmp_path / 'rec', cameras=3, frames=6)
    model = small_checkpoint(tmp_path / 'model.pt')
    mcap_m, out_m = process(tmp_path, rig, 'm', model)
    mcap_mm, out_mm = process(tmp_path, rig, 'mm', model)
    csv_m = read_anipose_csv(out_m / 'keypoints3d.csv')
    csv_mm = read_anipose_csv(out_mm / 'keypoints3d.csv')
    assert read_csv_units(out_mm / 'keypoints3d.csv') == 'mm'
    assert read_trc(out_mm / 'keypoints3d.trc')['units'] == 'mm'
    assert np.isfinite(csv_mm['X']).any()
    # the files in mm: the metre run's x 1000 (the tracked crops followed the same numbers)
    np.testing.assert_allclose(csv_mm['X'], csv_m['X'] * 1000.0, rtol=1e-6, atol=1e-3)
    for topic in mcap_m:
        # the MCAP in m whatever the rig's unit: equal to the metre run's ...
        np.testing.assert_allclose(mcap_mm[topic], mcap_m[topic], rtol=1e-6, atol=1e-6,
                                   equal_nan=True)
        # ... and a 1000th of the mm files (float32 metres: a few um)
        assert np.nanmax(np.abs(mcap_mm[topic])) < 10.0        # metres, not mm
    np.testing.assert_allclose(mcap_mm['/monet/keypoints3d_filtered'] * 1000.0, csv_mm['X'],
                               rtol=1e-6, atol=1e-3, equal_nan=True)
