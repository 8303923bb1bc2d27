"""The exports keep a source's frame numbers and time when given them (2D tables): CSV fnum,
TRC Frame# = fnum + 1 and Time from the time origin, DataRate as given even for one frame;
without them the numbers are counted from the stamps as before; bad fnum is named."""
import numpy as np
import pytest

from monet_ros.io.export_tables import (
    ExportError,
    export_times,
    read_anipose_csv,
    read_trc,
    source_frames,
    write_anipose_csv,
    write_trc,
)

KP = ('a', 'b')
FPS = 25.0


def test_source_frames_and_times_from_the_origin(tmp_path):
    fnum = np.array([50, 51, 52, 54])
    stamps = np.round(fnum * 1e9 / FPS).astype(np.int64)
    X = np.arange(24, dtype=float).reshape(4, 2, 3)
    ones = np.ones((4, 2))
    csv = write_anipose_csv(tmp_path / 'k.csv', KP, stamps, X, ones, ones, ones, fnum=fnum)
    np.testing.assert_array_equal(read_anipose_csv(csv)['fnum'], fnum)
    trc = read_trc(write_trc(tmp_path / 'k.trc', KP, stamps, X, fnum=fnum, origin_ns=0,
                             rate_hz=FPS))
    np.testing.assert_array_equal(trc['frames'], fnum + 1)
    np.testing.assert_allclose(trc['times'], fnum / FPS, rtol=0, atol=1e-12)
    assert trc['rate'] == FPS
    np.testing.assert_allclose(export_times(stamps, 0), fnum / FPS, rtol=0, atol=1e-12)
    # without them: counted from the first stamp, as `monet process` writes
    np.testing.assert_array_equal(source_frames(stamps), [0, 1, 2, 4])
    assert export_times(stamps)[0] == 0.0
    # one frame: its number, its time and the given rate
    one = read_trc(write_trc(tmp_path / 'one.trc', KP, stamps[:1], X[:1], fnum=fnum[:1],
                             origin_ns=0, rate_hz=FPS))
    assert one['frames'].tolist() == [51] and one['times'][0] == pytest.approx(2.0)
    assert one['rate'] == FPS


def test_bad_frame_numbers_are_named(tmp_path):
    stamps = np.arange(3, dtype=np.int64)
    with pytest.raises(ExportError, match='fnum: expected 3 integer frame numbers'):
        source_frames(stamps, [0, 1])
    with pytest.raises(ExportError, match='fnum: expected 3 integer frame numbers'):
        source_frames(stamps, [0.0, 1.5, 2.0])
