"""Length units of a rig (no ROS): their names, the factors between them, and the rule that
picks a unit for a calibration file that states none.

A rig has one length unit: its camera translations, the 3D points triangulated with it and
every 3D output are in that unit (as anipose keeps the board's unit). The unit is known
from the file (rig YAML `units`, the [metadata] `units` of a calibration.toml written by
monet), from an option (`--rig-units` of the commands, the nodes' `rig_units` parameter),
or from the stated rule (infer_units):

    the largest distance between two camera centres, in file units: >= INFER_MM_SPREAD
    (50) -> mm, else m. A lab rig is 0.1-20 m across: 100-20000 in mm, 0.1-20 in m. cm is
    never inferred (10-2000 overlaps both): state it. One camera (no spread, no 3D): m,
    without a note.

Parameters named with a unit (`_mm`, `_m_s2`, `_m`) mean that unit whatever the rig's; the
code that uses them converts them into rig units with from_mm / from_m (one factor,
per_metre).
"""
import sys

import numpy as np

UNITS = ('m', 'cm', 'mm')
_PER_METRE = {'m': 1.0, 'cm': 100.0, 'mm': 1000.0}
# NWB TimeSeries.unit spellings (the SI names)
NWB_NAMES = {'m': 'meters', 'cm': 'centimeters', 'mm': 'millimeters'}
# camera-centre spread (file units) from which a calibration without a unit is taken as mm
INFER_MM_SPREAD = 50.0

_noted = set()


def check_units(value, what='units'):
    """`value` ('m', 'cm' or 'mm') as str; ValueError naming `what` otherwise."""
    if not isinstance(value, str) or value not in UNITS:
        raise ValueError(f'{what}: must be one of {", ".join(UNITS)}, got {value!r}')
    return value


def per_metre(units):
    """How many `units` make one metre: 1 (m), 100 (cm), 1000 (mm). ValueError for another."""
    return _PER_METRE[check_units(units)]


def from_m(value, units):
    """A length (or speed, acceleration) in metres -> in `units` (float or array)."""
    return value * per_metre(units)


def from_mm(value, units):
    """A length in millimetres -> in `units`."""
    return value * (per_metre(units) / 1000.0)


def to_mm(value, units):
    """A length in `units` -> in millimetres."""
    return value * (1000.0 / per_metre(units))


def convert(value, from_units, to_units):
    """A length in `from_units` -> in `to_units`."""
    return value * (per_metre(to_units) / per_metre(from_units))


def camera_spread(cameras):
    """Largest distance between two camera centres (file units; 0 for one camera)."""
    centres = np.array([c.center for c in cameras]).reshape(-1, 3)
    if len(centres) < 2:
        return 0.0
    return float(np.linalg.norm(centres[:, None] - centres[None], axis=-1).max())


def infer_units(cameras):
    """(units, reason) by the rule of the module docstring: 'mm' when the camera centres
    spread >= INFER_MM_SPREAD file units, else 'm'; reason is a short text with the spread
    (None for a single camera: nothing to tell, it triangulates nothing)."""
    if len(cameras) < 2:
        return 'm', None
    spread = camera_spread(cameras)
    units = 'mm' if spread >= INFER_MM_SPREAD else 'm'
    return units, f'camera centres up to {spread:.4g} apart'


def note_inferred(path, units, reason):
    """One line on stderr saying which unit a rig file without one was taken in; once per
    file and unit in a process."""
    if (str(path), units) in _noted:
        return
    _noted.add((str(path), units))
    print(f'monet: note: rig {path} states no length unit; {reason}: taken as {units} '
          f'(rule: >= {INFER_MM_SPREAD:g} -> mm, else m; state it with --rig-units '
          'm|mm|cm or the rig_units parameter)', file=sys.stderr, flush=True)


def rig_units(cameras):
    """The length unit shared by `cameras` ('m' for none); ValueError when they differ."""
    found = {getattr(c, 'units', 'm') for c in cameras}
    if len(found) > 1:
        raise ValueError(f'cameras in different length units {sorted(found)}: a rig has one')
    return found.pop() if found else 'm'


def with_units(cameras, units):
    """The cameras with `units` set (the values are not converted)."""
    check_units(units)
    return [c if c.units == units else c.replace(units=units) for c in cameras]


def rescale(cameras, units):
    """The same rig expressed in `units`: translations converted, every camera's unit set."""
    check_units(units)
    return [c.replace(t=convert(np.asarray(c.t), c.units, units), units=units)
            for c in cameras]
