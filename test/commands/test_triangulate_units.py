"""`monet triangulate` on the real sleap-anipose session (4 cameras, a mouse; its anipose
calibration.toml is in mm and says nothing of it) with the same rig in mm, m and cm: the
same 3D after converting by the stated unit, the same Kalman filtering (nothing gated: the
filter's mm and m/s^2 settings are converted into the rig's unit), and every output
states the unit (TRC Units, NWB unit, the CSV's sidecar, the printed summary). Before,
the mm rig was filtered as if in metres: 1201 of 1800 points gated out."""
import json
import re

import numpy as np
import pytest

from monet_ros.cli import main as monet
from monet_ros.geometry import load_rig, save_anipose_toml
from monet_ros.geometry.units import rescale
from monet_ros.io.export_tables import read_anipose_csv, read_trc

SESSION = 'sleap_anipose_minimal_session'
FACTOR = {'mm': 1.0, 'cm': 0.1, 'm': 1e-3}          # file value per mm


@pytest.fixture(scope='module')
def session(shared_data):
    folder = shared_data / SESSION
    return folder, sorted(folder.glob('*/minimal_*_proofread.analysis.h5'))


def toml_without_units(path, cameras):
    """An anipose calibration.toml of `cameras` that states no unit (as anipose writes)."""
    save_anipose_toml(path, cameras)
    text = path.read_text()
    path.write_text(re.sub(r'(?m)^units = .*\n', '', text))
    assert 'units' not in path.read_text()
    return path


def triangulate(capsys, h5, rig, out, *options, export='csv,trc'):
    code = monet(['triangulate', *map(str, h5), '--rig', str(rig), '--out', str(out),
                  '--fps', '30', '--filter', 'kalman', '--export', export, '--quiet',
                  *options])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return captured.out, captured.err


def filter_line(out):
    """The Kalman summary without its wall time."""
    line = next(t for t in out.splitlines() if 'filter kalman:' in t)
    return line.rsplit(';', 1)[0]


def test_same_data_in_mm_m_and_cm_gives_the_same_results(session, tmp_path, capsys):
    folder, h5 = session
    rig_mm = load_rig(folder / 'calibration.toml')
    assert {c.units for c in rig_mm} == {'mm'}           # by the rule (test_units.py)
    capsys.readouterr()
    runs = {}
    # mm: the file as it is
    runs['mm'] = triangulate(capsys, h5, folder / 'calibration.toml', tmp_path / 'mm')[0]
    # m and cm: the same rig converted, the unit stated with --rig-units
    for units in ('m', 'cm'):
        rig = toml_without_units(tmp_path / f'calibration_{units}.toml',
                                 rescale(rig_mm, units))
        runs[units] = triangulate(capsys, h5, rig, tmp_path / units, '--rig-units',
                                  units)[0]
    base = read_trc(tmp_path / 'mm' / 'keypoints3d.trc')
    base_csv = read_anipose_csv(tmp_path / 'mm' / 'keypoints3d.csv')
    finite = np.isfinite(base['X'])
    assert finite.all(-1).sum() == 1800                 # every point triangulated + kept
    for units, out in runs.items():
        assert f"1800 of 1800 points triangulated (3D in {units}, the rig's unit)" in out
        trc = read_trc(tmp_path / units / 'keypoints3d.trc')
        assert trc['units'] == units
        np.testing.assert_allclose(trc['X'] / FACTOR[units], base['X'], rtol=1e-9,
                                   atol=1e-9)
        table = read_anipose_csv(tmp_path / units / 'keypoints3d.csv')
        np.testing.assert_allclose(table['X'] / FACTOR[units], base_csv['X'], rtol=1e-9,
                                   atol=1e-9)
        np.testing.assert_allclose(table['extra']['change_mm'],
                                   base_csv['extra']['change_mm'], atol=1e-6)
        side = json.loads((tmp_path / units / 'keypoints3d.units.json').read_text())
        assert side['file'] == 'keypoints3d.csv' and side['length_unit'] == units
        # the filter: nothing gated, the same counts and the same change in mm
        assert filter_line(out) == filter_line(runs['mm'])
        assert ': 1800 points out of 1800 triangulated; 0 bridged over gaps, 0 gated out' \
            in out
    # values a mouse arena has: tens to hundreds of mm from the rig origin
    assert 10 < np.nanmax(np.abs(base['X'])) < 2000


def test_nwb_states_the_rig_unit(session, tmp_path, capsys):
    from ndx_pose import PoseEstimationSeries  # noqa: F401 - registers the NWB types
    from pynwb import NWBHDF5IO

    folder, h5 = session
    rig = toml_without_units(tmp_path / 'calibration_cm.toml',
                             rescale(load_rig(folder / 'calibration.toml'), 'cm'))
    triangulate(capsys, h5, rig, tmp_path / 'cm', '--rig-units', 'cm', export='nwb')
    with NWBHDF5IO(str(tmp_path / 'cm' / 'keypoints.nwb'), 'r') as io:
        pose = io.read().processing['behavior']['monet_pose']
        units = {s.unit for s in pose.pose_estimation_series.values()}
    assert units == {'centimeters'}


def test_a_rig_in_metres_is_recognised_by_the_rule(session, tmp_path, capsys):
    folder, h5 = session
    rig = toml_without_units(tmp_path / 'calibration.toml',
                             rescale(load_rig(folder / 'calibration.toml'), 'm'))
    capsys.readouterr()
    out, err = triangulate(capsys, h5, rig, tmp_path / 'out')
    assert re.search(r'monet: note: rig .*calibration.toml states no length unit; camera '
                     r'centres up to 0.2899 apart: taken as m', err)
    assert read_trc(tmp_path / 'out' / 'keypoints3d.trc')['units'] == 'm'
    assert "(3D in m, the rig's unit)" in out


def test_rig_units_against_the_file_is_one_line_exit_2(session, tmp_path, capsys):
    folder, h5 = session
    rig = tmp_path / 'calibration.toml'
    save_anipose_toml(rig, rescale(load_rig(folder / 'calibration.toml'), 'm'))
    capsys.readouterr()
    code = monet(['triangulate', *map(str, h5), '--rig', str(rig), '--out',
                  str(tmp_path / 'out'), '--rig-units', 'mm'])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"{rig}: field 'units': the file states 'm' but 'mm' was given" in err
    assert not (tmp_path / 'out').exists()


def test_optim_filter_is_the_same_in_mm_and_m(session, tmp_path, capsys):
    folder, h5 = session
    rig_m = toml_without_units(tmp_path / 'calibration_m.toml',
                               rescale(load_rig(folder / 'calibration.toml'), 'm'))
    capsys.readouterr()
    outs = {}
    for units, rig in (('mm', folder / 'calibration.toml'), ('m', rig_m)):
        code = monet(['triangulate', *map(str, h5), '--rig', str(rig), '--rig-units', units,
                      '--out', str(tmp_path / units), '--fps', '30', '--filter', 'optim',
                      '--export', 'csv', '--quiet'])
        outs[units] = capsys.readouterr().out
        assert code == 0
    mm = read_anipose_csv(tmp_path / 'mm' / 'keypoints3d.csv')
    m = read_anipose_csv(tmp_path / 'm' / 'keypoints3d.csv')
    np.testing.assert_array_equal(np.isfinite(mm['X']), np.isfinite(m['X']))
    # equal to the solver's tolerance (least_squares stops at ftol 1e-6; the two runs'
    # iterates differ by rounding): 0.1 mm, against ~1 mm of filtering
    np.testing.assert_allclose(mm['X'] / 1000.0, m['X'], atol=1e-4)
    np.testing.assert_allclose(mm['extra']['change_mm'], m['extra']['change_mm'], atol=0.1)
    # the optimisation moved the points by what 2D noise allows, not by metres
    assert np.nanmedian(mm['extra']['change_mm']) < 5.0
