"""2D tables as arrays for `monet triangulate`: the frame-indexed points table (optional
score, empty / NaN u, v = missing, empty / NaN score = no score), DeepLabCut predictions
with likelihood, duplicates."""
import numpy as np
import pytest

from monet_ros.labels import LabelError, read_label_rows
from monet_ros.labels_import.points2d import detect_format, read_points2d


def test_points_table_with_and_without_scores(tmp_path):
    scored = tmp_path / 'scored.csv'
    scored.write_text('frame,camera,keypoint,u,v,score\n'
                      '3,a,head,10.5,20.25,0.9\n'
                      '4,b,head,,,\n'
                      '5,b,tail,1,2,nan\n')
    p = read_points2d(scored, ['a', 'b', 'c'])
    assert p.fmt == 'frames' and p.keypoints == ('head', 'tail')
    np.testing.assert_array_equal(p.frames, [3, 4, 5])
    assert p.points.shape == (3, 3, 2, 2) and p.rows == 3 and p.nan_rows == 1
    np.testing.assert_array_equal(p.points[0, 0, 0], [10.5, 20.25])
    assert p.score[0, 0, 0] == 0.9
    # a point with an empty / NaN score cell has no score: kept with score 1, counted
    assert p.score[2, 1, 1] == 1.0 and p.unscored == 1
    assert p.notes == ('1 of 2 detections have no score (no score column, or an empty / '
                       'NaN likelihood or score cell): score 1 used',)
    assert np.isnan(p.points[1, 1, 0]).all() and np.isnan(p.points[:, 2]).all()
    plain = tmp_path / 'plain.csv'
    plain.write_text('frame,camera,keypoint,u,v\n0,a,head,1,2\n0,b,head,3,4\n')
    p = read_points2d(plain, ['a', 'b'], keypoints=['tail', 'head'])
    assert p.keypoints == ('tail', 'head') and np.all(p.score[:, :, 1] == 1.0)
    assert np.isnan(p.points[:, :, 0]).all()
    # a labels file stays strict: no score column, no empty coordinates
    with pytest.raises(LabelError, match='scored.csv:1: header is'):
        read_label_rows(scored)


def test_duplicates_and_formats_are_named(tmp_path):
    twice = tmp_path / 'twice.csv'
    twice.write_text('frame,camera,keypoint,u,v\n0,a,head,1,2\n0,a,head,3,4\n')
    with pytest.raises(LabelError, match='twice.csv:3: frame 0 camera a keypoint head is '
                       'given twice'):
        read_points2d(twice, ['a', 'b'])
    other = tmp_path / 'other.csv'
    other.write_text('x,y\n1,2\n')
    with pytest.raises(LabelError, match="other.csv:1: first field 'x': neither"):
        detect_format([other])
    with pytest.raises(LabelError, match='no such file'):
        read_points2d(tmp_path / 'missing.csv', ['a'])
    empty = tmp_path / 'empty.csv'
    empty.write_text('')
    with pytest.raises(LabelError, match=r'empty\.csv: the file is empty \(no header line\)'):
        read_points2d(empty, ['a'])
    blank = tmp_path / 'blank.csv'
    blank.write_text('\nframe,camera,keypoint,u,v\n')
    with pytest.raises(LabelError, match=r'blank\.csv:1: the header line is blank'):
        read_points2d(blank, ['a'])


def test_a_frame_span_too_large_for_memory_is_refused_naming_the_row(tmp_path):
    """One mistyped frame number far beyond the others would make the arrays span every
    frame between: refused before any allocation, naming the row (not an out-of-memory
    kill); a span that fits is read."""
    far = tmp_path / 'far.csv'
    far.write_text('frame,camera,keypoint,u,v\n0,a,head,1,2\n1,a,head,1,2\n'
                   '1000000000000,b,head,3,4\n2,b,head,3,4\n')
    with pytest.raises(LabelError, match=r'far\.csv:4: field frame: 1000000000000 makes the '
                       r'frames span 0\.\.1000000000000 \(1000000000001 frames, 4 with '
                       r'detections\), about 2\.56e\+05 GB to triangulate, more than the'):
        read_points2d(far, ['a', 'b'])
    near = tmp_path / 'near.csv'
    near.write_text('frame,camera,keypoint,u,v\n0,a,head,1,2\n99,b,head,3,4\n')
    assert read_points2d(near, ['a', 'b']).points.shape == (100, 2, 1, 2)


def test_the_span_check_compares_the_arrays_with_the_memory_available(tmp_path):
    from monet_ros.labels_import.points2d import BYTES_PER_ENTRY, _check_span
    table = tmp_path / 'rows.csv'
    table.write_text('frame,camera,keypoint,u,v\n0,a,head,1,2\n1,a,head,1,2\n9,a,head,1,2\n')
    rows = read_label_rows(table, points=True)
    frame = np.array([0, 1, 9])
    need = 10 * 3 * 5 * BYTES_PER_ENTRY          # T x V x C x bytes per entry
    _check_span(rows, frame, 10, 3, 5, available=need)      # fits exactly
    with pytest.raises(LabelError, match=r'rows\.csv:4: field frame: 9 makes the frames span '
                       r'0\.\.9'):
        _check_span(rows, frame, 10, 3, 5, available=need - 1)
