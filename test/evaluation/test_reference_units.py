"""3D errors against a reference are millimetres whatever the rig's unit: the same scene
with the rig in m, cm or mm, a labels reference (triangulated in the rig's unit) or a TRC
reference in any Units, and predictions 10 mm off give 10 mm (before, a mm rig printed
10000 mm: a hard-coded x1000)."""
from dataclasses import dataclass

from helpers.ring import random_points, ring_rig
import numpy as np
import pytest

from monet_ros.evaluation.reference import load_reference, score
from monet_ros.geometry.units import per_metre, rescale
from monet_ros.io.export_tables import write_trc
from monet_ros.labels import label_rows, write_labels

KP = ('a', 'b', 'c')


@dataclass
class Index:
    stamps: np.ndarray
    cameras: list


def scene(units):
    """Index with the ring rig in `units`, the true points (T, C, 3) in metres, their
    projections (T, V, C, 2)."""
    cams = ring_rig(3, width=640, height=480, focal=500.0)
    stamps = 10**18 + np.arange(5, dtype=np.int64) * 33_333_333
    X = np.stack([random_points(3, seed=s, spread=0.2) for s in range(5)])
    uv = np.stack([[c.project(X[t]) for c in cams] for t in range(5)])
    return Index(stamps, rescale(cams, units)), X, uv


@pytest.mark.parametrize('units', ['m', 'cm', 'mm'])
def test_labels_reference_errors_are_mm_in_every_unit(units, tmp_path):
    index, X, uv = scene(units)
    k = per_metre(units)
    path = tmp_path / 'labels.csv'
    write_labels(path, label_rows(index.stamps[[1, 3]], [c.name for c in index.cameras], KP,
                                  uv[[1, 3]]))
    ref = load_reference(path, index, KP)
    assert ref.units == units
    np.testing.assert_allclose(ref.X[[1, 3]], X[[1, 3]] * k, rtol=1e-9)
    pred = X * k
    pred[..., 2] += 0.010 * k                          # 10 mm up, in the rig's unit
    figures = score(ref, index.stamps, pred, uv, (5.0,), (9.0, 11.0))
    assert figures['mm_median'] == pytest.approx(10.0, abs=1e-6)
    assert figures['mm_p90'] == pytest.approx(10.0, abs=1e-6)
    assert figures['pck3d@9mm'] == 0.0 and figures['pck3d@11mm'] == 1.0


@pytest.mark.parametrize('rig_units', ['m', 'mm'])
@pytest.mark.parametrize('trc_units', ['m', 'cm', 'mm'])
def test_trc_reference_is_converted_to_the_rig_unit(rig_units, trc_units, tmp_path):
    index, X, uv = scene(rig_units)
    path = tmp_path / 'ref.trc'
    write_trc(path, KP, index.stamps, X * per_metre(trc_units), units=trc_units)
    ref = load_reference(path, index, KP)
    np.testing.assert_allclose(ref.X, X * per_metre(rig_units), rtol=1e-9)
    np.testing.assert_allclose(ref.points2d, uv, atol=1e-6)   # projected with the rig
    pred = X * per_metre(rig_units)
    pred[:, 0, 0] += 0.025 * per_metre(rig_units)             # joint a 25 mm off
    figures = score(ref, index.stamps, pred, uv, (5.0,), (20.0, 30.0))
    assert figures['mm_mean'] == pytest.approx(25.0 / 3)
    assert figures['pck3d@20mm'] == pytest.approx(2 / 3)


def test_anipose_csv_reference_takes_its_sidecar_unit(tmp_path):
    from monet_ros.io.export_tables import write_anipose_csv
    index, X, uv = scene('m')
    T, C = X.shape[:2]
    zeros = np.zeros((T, C))
    csv = tmp_path / 'keypoints3d.csv'
    write_anipose_csv(csv, KP, index.stamps, X * 1000.0, zeros, zeros, zeros, units='mm')
    ref = load_reference(csv, index, KP)
    np.testing.assert_allclose(ref.X, X, rtol=1e-9)
    # without the sidecar the CSV is in the rig's unit, as anipose writes it
    (tmp_path / 'keypoints3d.units.json').unlink()
    np.testing.assert_allclose(load_reference(csv, index, KP).X, X * 1000.0, rtol=1e-9)
