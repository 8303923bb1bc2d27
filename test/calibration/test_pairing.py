"""Pairing frames across cameras by time (--timestamps), against a brute-force search."""
from pathlib import Path

import numpy as np
import pytest

from monet_ros.calibration.pairing import pair_by_time, read_timestamps


def brute_force(times, names, tolerance):
    ref = times[names[0]]
    out = []
    for f in np.flatnonzero(np.isfinite(ref)):
        row = [f]
        for name in names[1:]:
            t = times[name]
            gaps = [(abs(t[k] - ref[f]), k) for k in range(len(t)) if np.isfinite(t[k])]
            gap, k = min(gaps)
            row.append(k if gap <= tolerance else -1)
        out.append(row)
    return np.array(out)


def test_nearest_frame_within_tolerance_matches_brute_force():
    rng = np.random.default_rng(5)
    names = ['a', 'b', 'c']
    times = {'a': np.arange(40) / 30.0,
             'b': np.sort(rng.uniform(0, 1.4, 35)),           # another rate, jittered
             'c': np.arange(30) / 30.0 + 0.2}                 # starts later
    times['b'][[3, 9]] = np.nan                               # frames not listed
    tolerance = 0.5 / 30
    got = pair_by_time(times, names, tolerance)
    np.testing.assert_array_equal(got, brute_force(times, names, tolerance))
    assert (got[:6, 2] == -1).all() and (got[6:36, 2] >= 0).all()
    # default tolerance: half the first camera's frame interval
    np.testing.assert_array_equal(pair_by_time(times, names), got)


def write(path, rows, header='camera,frame,time_s'):
    Path(path).write_text(header + '\n' + '\n'.join(rows) + '\n')
    return path


def test_read_timestamps(tmp_path):
    path = write(tmp_path / 't.csv', ['a,0,0.0', 'a,1,0.033', 'b,1,0.5'])
    times = read_timestamps(path, ['a', 'b'], {'a': 3, 'b': 2})
    np.testing.assert_array_equal(times['a'], [0.0, 0.033, np.nan])
    np.testing.assert_array_equal(times['b'], [np.nan, 0.5])


@pytest.mark.parametrize('rows, header, message', [
    (['a,0,0'], 'cam,frame,time', 'header must have camera,frame,time_s'),
    (['x,0,0'], None, "line 2: camera 'x' is not an input camera"),
    (['a,0,0', 'a,5,1'], None, "line 3: frame 5 of camera 'a' is out of range"),
    (['a,0,zero'], None, 'line 2: frame must be an integer and time_s a number'),
    (['a,0,0', 'a,0,1'], None, "line 3: frame 0 of camera 'a' is listed twice"),
    (['a,0,inf'], None, 'line 2: time_s must be finite'),
    (['a,0,0'], None, "no row for camera 'b'"),
])
def test_bad_timestamps_name_file_and_line(tmp_path, rows, header, message):
    path = write(tmp_path / 't.csv', rows, header or 'camera,frame,time_s')
    with pytest.raises(ValueError, match=message) as info:
        read_timestamps(path, ['a', 'b'], {'a': 3, 'b': 3})
    assert str(path) in str(info.value)
