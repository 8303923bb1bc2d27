"""Labels CSV: exact round trip, channel order, errors naming file, line and field."""
import numpy as np
import pytest

from monet_ros.labels import HEADER, LabelError, Labels, label_rows, read_labels, write_labels
from monet_ros.skeleton import load_skeleton


def test_round_trip_is_exact_and_ordered(tmp_path):
    skeleton = load_skeleton('human14')
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.5, 639.5, (3, 4, 14, 2))
    points[0, 1, 5] = np.nan                 # unlabelled keypoint in one view
    points[2, 3] = np.nan                    # a view without labels
    stamps = [30, 10, 20]
    cameras = [f'cam{i}' for i in range(4)]
    path = tmp_path / 'labels.csv'
    count = write_labels(path, label_rows(stamps, cameras, skeleton.keypoints, points))
    assert count == 3 * 4 * 14 - 1 - 14
    lines = path.read_text().splitlines()
    assert lines[0] == ','.join(HEADER) and len(lines) == count + 1
    labels = read_labels(path, skeleton)
    assert labels.keypoints == skeleton.keypoints
    assert labels.stamps == [10, 20, 30] and len(labels) == 3
    assert labels.cameras == cameras and labels.num_points == count
    for i, stamp in enumerate(stamps):
        np.testing.assert_array_equal(labels.points(stamp, cameras), points[i])  # bit-exact
    assert 'cam3' not in labels.frames[20]
    # a reversed camera order and an unknown camera
    got = labels.points(10, ['cam1', 'camX'])
    np.testing.assert_array_equal(got[0], points[1, 1])
    assert np.isnan(got[1]).all()
    # write the Labels object itself: same file
    again = tmp_path / 'again.csv'
    write_labels(again, labels)
    assert sorted(again.read_text().splitlines()) == sorted(lines)


def test_order_from_file_when_no_skeleton(tmp_path):
    path = tmp_path / 'l.csv'
    path.write_text('stamp_ns,camera,keypoint,u,v\n5,c,zeta,1,2\n5,c,alpha,3.5,4\n\n')
    labels = read_labels(path)
    assert labels.keypoints == ('alpha', 'zeta')
    np.testing.assert_array_equal(labels.frames[5]['c'], [[3.5, 4.0], [1.0, 2.0]])
    assert isinstance(labels, Labels)


@pytest.mark.parametrize('body, message', [
    ('', 'empty file'),
    ('stamp,camera,keypoint,u,v\n', ':1: header'),
    ('stamp_ns,camera,keypoint,u,v\n1,cam0,head,1.0\n', ':2: expected 5 fields'),
    ('stamp_ns,camera,keypoint,u,v\n1,cam0,head,1,2\nx1,cam0,neck,1,2\n',
     ':3: field stamp_ns'),
    ('stamp_ns,camera,keypoint,u,v\n-4,cam0,head,1,2\n', ':2: field stamp_ns: must be >= 0'),
    ('stamp_ns,camera,keypoint,u,v\n1,,head,1,2\n', ':2: field camera'),
    ('stamp_ns,camera,keypoint,u,v\n1,cam0,tail,1,2\n', ":2: field keypoint: 'tail'"),
    ('stamp_ns,camera,keypoint,u,v\n1,cam0,head,nan,2\n', ":2: field u: 'nan'"),
    ('stamp_ns,camera,keypoint,u,v\n1,cam0,head,1,2e\n', ":2: field v: '2e'"),
    ('stamp_ns,camera,keypoint,u,v\n1,cam0,head,1,2\n\n1,cam0,head,3,4\n',
     r':4: duplicate label .* \(first on line 2\)'),
])
def test_bad_rows_name_file_line_and_field(tmp_path, body, message):
    path = tmp_path / 'bad.csv'
    path.write_text(body)
    with pytest.raises(LabelError, match=message) as info:
        read_labels(path, load_skeleton('human14'))
    assert str(path) in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(LabelError, match='cannot open'):
        read_labels(tmp_path / 'none.csv')


def test_label_rows_checks_shape():
    with pytest.raises(ValueError, match='expected'):
        list(label_rows([1], ['cam0'], ['a', 'b'], np.zeros((1, 1, 3, 2))))
