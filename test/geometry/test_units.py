"""A rig knows its length unit: the rig YAML's `units`, the [metadata] units of a TOML monet
wrote, the --rig-units option, else the stated rule (camera-centre spread >= 50 -> mm,
else m) with a one-line note; bad or conflicting units are one clear error naming the file
and field."""
import shutil

from helpers.ring import ring_rig
import numpy as np
import pytest

from monet_ros.geometry import RigError, load_rig, save_anipose_toml, save_rig
from monet_ros.geometry.units import (
    INFER_MM_SPREAD,
    camera_spread,
    convert,
    from_m,
    from_mm,
    infer_units,
    rescale,
    to_mm,
)

SESSION = 'sleap_anipose_minimal_session'


def test_factors_are_those_of_the_si_units():
    assert from_mm(15.0, 'm') == pytest.approx(0.015)
    assert from_mm(15.0, 'cm') == pytest.approx(1.5)
    assert from_mm(15.0, 'mm') == 15.0
    assert from_m(20.0, 'mm') == 20000.0 and from_m(20.0, 'cm') == 2000.0
    assert to_mm(0.25, 'm') == 250.0 and to_mm(2.5, 'cm') == 25.0
    assert convert(541.7, 'mm', 'm') == pytest.approx(0.5417)
    with pytest.raises(ValueError, match="units: must be one of m, cm, mm, got 'inch'"):
        from_mm(1.0, 'inch')


def test_rule_picks_mm_from_the_camera_spread_and_says_so():
    rig = ring_rig(4, radius=2.0)                       # ~4 m across in metres
    spread = camera_spread(rig)
    assert spread == pytest.approx(max(np.linalg.norm(a.center - b.center)
                                       for a in rig for b in rig))
    assert infer_units(rig)[0] == 'm'
    assert infer_units(rescale(rig, 'mm'))[0] == 'mm'  # 4000 across
    assert infer_units(rescale(rig, 'cm'))[0] == 'mm'  # cm is never guessed: state it
    # the threshold itself: a rig exactly INFER_MM_SPREAD across is mm, just under it m
    two = ring_rig(2, radius=INFER_MM_SPREAD / 2)      # opposite, same height
    assert camera_spread(two) == pytest.approx(INFER_MM_SPREAD)
    assert infer_units(ring_rig(2, radius=INFER_MM_SPREAD / 2 * 0.99))[0] == 'm'
    assert infer_units(ring_rig(2, radius=INFER_MM_SPREAD / 2 * 1.01))[0] == 'mm'
    assert infer_units(rig[:1]) == ('m', None)            # one camera: nothing to note


def test_sleap_anipose_toml_is_taken_as_mm_with_a_note(shared_data, tmp_path, capsys):
    path = tmp_path / 'calibration.toml'              # a copy: the note is once per file
    shutil.copy(shared_data / SESSION / 'calibration.toml', path)
    rig = load_rig(path)
    assert {c.units for c in rig} == {'mm'}
    # independent: the back and mid cameras (the calibrated ones) ~ 290 mm apart
    assert np.linalg.norm(rig[0].center - rig[1].center) > INFER_MM_SPREAD
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and 'taken as mm' in err[0] \
        and '--rig-units' in err[0]
    # stated: no note, the stated unit (the values are not converted)
    stated = load_rig(path, units='m')
    assert {c.units for c in stated} == {'m'}
    np.testing.assert_array_equal(stated[0].t, rig[0].t)
    assert capsys.readouterr().err == ''


@pytest.mark.parametrize('units', ['m', 'cm', 'mm'])
def test_rig_yaml_and_toml_carry_the_unit(units, tmp_path, capsys):
    rig = rescale(ring_rig(3), units)
    save_rig(tmp_path / 'rig.yaml', rig)
    save_anipose_toml(tmp_path / 'calibration.toml', rig)
    for name in ('rig.yaml', 'calibration.toml'):
        back = load_rig(tmp_path / name)
        assert [c.units for c in back] == [units] * 3
        np.testing.assert_allclose([c.t for c in back], [c.t for c in rig])
    assert f"units: '{units}'" in (tmp_path / 'rig.yaml').read_text()
    assert f'units = "{units}"' in (tmp_path / 'calibration.toml').read_text()
    assert capsys.readouterr().err == ''               # stated: nothing inferred


def test_rescale_keeps_the_geometry():
    rig = ring_rig(3)
    X = np.array([[0.1, -0.2, 1.1], [0.3, 0.2, 0.8]])
    for units, k in (('mm', 1000.0), ('cm', 100.0)):
        scaled = rescale(rig, units)
        for a, b in zip(rig, scaled):
            np.testing.assert_allclose(b.t, a.t * k)
            np.testing.assert_allclose(b.project(X * k), a.project(X), atol=1e-9)


def test_bad_and_conflicting_units_name_the_file_and_field(tmp_path):
    save_rig(tmp_path / 'rig.yaml', rescale(ring_rig(3), 'mm'))
    with pytest.raises(RigError) as error:
        load_rig(tmp_path / 'rig.yaml', units='m')
    assert str(error.value) == (f"{tmp_path / 'rig.yaml'}: field 'units': the file states "
                                "'mm' but 'm' was given (--rig-units / rig_units): leave the "
                                'option out or fix the file')
    text = (tmp_path / 'rig.yaml').read_text().replace("units: 'mm'", 'units: feet')
    (tmp_path / 'bad.yaml').write_text(text)
    with pytest.raises(RigError, match=r"bad.yaml: field 'units': must be one of m, cm, mm, "
                       r"got 'feet'"):
        load_rig(tmp_path / 'bad.yaml')
    with pytest.raises(RigError, match=r"field 'units': must be one of m, cm, mm, got 'km'"):
        load_rig(tmp_path / 'rig.yaml', units='km')
