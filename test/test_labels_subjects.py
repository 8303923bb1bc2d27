"""The labels file's optional `subject` column (issue 39 item 6): an integer id >= 0 of the
labelled animal within an instant, default 0; files without it load and are written exactly
as before; the one validator checks it (file, line, field)."""
import numpy as np
import pytest

from monet_ros.labels import (
    LabelError,
    LabelOptions,
    LabelRow,
    read_label_rows,
    read_labels,
    resolve_labels,
    write_labels,
)

STAMPS = np.array([1000, 2000, 3000], np.int64)
CAMERAS = [('cam0', 100, 80), ('cam1', 100, 80)]
KEYPOINTS = ('head', 'tail')


def test_single_subject_tables_are_written_and_read_as_before(tmp_path):
    plain = tmp_path / 'plain.csv'
    plain.write_text('stamp_ns,camera,keypoint,u,v\n1000,cam0,head,1.5,2.5\n'
                     '1000,cam1,tail,3.0,4.0\n')
    zero = tmp_path / 'zero.csv'
    zero.write_text('stamp_ns,camera,keypoint,u,v,subject\n1000,cam0,head,1.5,2.5,0\n'
                    '1000,cam1,tail,3.0,4.0,0\n')
    a, b = read_labels(plain, KEYPOINTS), read_labels(zero, KEYPOINTS)
    assert a.subjects == b.subjects == [0] and b.others == {}
    assert list(a.rows()) == list(b.rows()) == [(1000, 'cam0', 'head', 1.5, 2.5),
                                                (1000, 'cam1', 'tail', 3.0, 4.0)]
    out = tmp_path / 'out.csv'
    write_labels(out, b)                       # all subject 0: no subject column
    assert out.read_text() == plain.read_text()


def test_two_subjects_round_trip(tmp_path):
    rows = [(1000, 'cam0', 'head', 1.5, 2.5, 0), (1000, 'cam0', 'head', 50.25, 60.0, 1),
            (1000, 'cam1', 'head', 7.0, 8.0, 1), (2000, 'cam1', 'tail', 9.0, 10.0, 2)]
    path = tmp_path / 'two.csv'
    assert write_labels(path, rows) == 4
    assert path.read_text().splitlines()[:2] == ['stamp_ns,camera,keypoint,u,v,subject',
                                                 '1000,cam0,head,1.5,2.5,0']
    labels = read_labels(path, KEYPOINTS)
    assert labels.subjects == [0, 1, 2] and labels.stamps == [1000, 2000]
    assert labels.num_points == 4 and len(labels) == 2
    assert labels.instant_subjects(1000) == [0, 1] and labels.instant_subjects(2000) == [2]
    np.testing.assert_array_equal(labels.points(1000, ['cam0', 'cam1'], subject=1),
                                  [[[50.25, 60.0], [np.nan, np.nan]],
                                   [[7.0, 8.0], [np.nan, np.nan]]])
    assert np.isnan(labels.points(2000, ['cam1'])).all()      # subject 0 has none there
    assert sorted(labels.subject_rows()) == sorted(rows)
    again = tmp_path / 'again.csv'
    write_labels(again, labels)
    assert again.read_text() == path.read_text()
    # the frame-indexed variant, through the one validator
    frames = tmp_path / 'frames.csv'
    frames.write_text('frame,camera,keypoint,u,v,subject\n0,cam0,head,1,2,0\n'
                      '0,cam0,head,30,40,1\n2,cam1,tail,5,6,1\n')
    table, report = resolve_labels(read_label_rows(frames), STAMPS, CAMERAS, KEYPOINTS)
    assert report.kept == 3 and table.subjects == [0, 1]
    assert table.points(3000, ['cam1'], 1)[0, 1].tolist() == [5.0, 6.0]


@pytest.mark.parametrize('cell,reason', [('-1', '-1 is not an integer >= 0'),
                                         ('a', "'a' is not an integer >= 0"),
                                         ('1.5', "'1.5' is not an integer >= 0"),
                                         ('', "'' is not an integer >= 0"),
                                         ('99999999999999999999', 'is above 2147483647')])
def test_a_bad_subject_cell_names_file_line_and_field(tmp_path, cell, reason):
    path = tmp_path / 'bad.csv'
    path.write_text(f'stamp_ns,camera,keypoint,u,v,subject\n1000,cam0,head,1,2,0\n'
                    f'1000,cam0,head,1,2,{cell}\n')
    rows = read_label_rows(path)
    with pytest.raises(LabelError, match=rf'^{path}:3: field subject: .*{reason}'):
        resolve_labels(rows, STAMPS, CAMERAS, KEYPOINTS)
    # --skip-bad-labels: the row is dropped and counted, the rest kept
    table, report = resolve_labels(rows, STAMPS, CAMERAS, KEYPOINTS,
                                   LabelOptions(skip_bad=True))
    assert report.skipped == {'subject': 1} and report.kept == 1 and table.subjects == [0]


def test_the_validator_checks_subjects_and_duplicates_per_subject():
    def row(line, subject, keypoint='head', u=1.0):
        return LabelRow('x.csv', line, 1000, None, 'cam0', keypoint, u, 2.0, subject=subject)
    table, _ = resolve_labels([row(2, 0), row(3, 1)], STAMPS, CAMERAS, KEYPOINTS)
    assert table.subjects == [0, 1]          # one keypoint, two subjects: not a duplicate
    with pytest.raises(LabelError, match=r'^x.csv:3: field keypoint: head of cam0 at instant '
                       r'0 \(subject 1\) is labelled twice \(first on line 2\)'):
        resolve_labels([row(2, 1), row(3, 1)], STAMPS, CAMERAS, KEYPOINTS)
    for bad in (-1, 1.5, True, '1'):
        with pytest.raises(LabelError, match=r'^x.csv:3: field subject: .* is not an integer '
                           '>= 0'):
            resolve_labels([row(2, 0), row(3, bad)], STAMPS, CAMERAS, KEYPOINTS)
    table, report = resolve_labels([row(2, 0), row(3, -2)], STAMPS, CAMERAS, KEYPOINTS,
                                   LabelOptions(skip_bad=True))
    assert report.skipped == {'subject': 1} and table.subjects == [0]
    with pytest.raises(ValueError, match='subject -1'):
        write_labels('/nonexistent/x.csv', [(1000, 'cam0', 'head', 1.0, 2.0, -1)])


@pytest.mark.parametrize('points', [False, True])
def test_a_wrong_header_names_the_subject_headers_too(tmp_path, points):
    """A header with a misnamed column lists every header that reads, the `subject` ones
    included (it named the two without a subject column only, so a newcomer's
    `...,score,subj` or `...,subject,score` was told the column does not exist)."""
    path = tmp_path / 'bad.csv'
    path.write_text('frame,camera,keypoint,u,v,score,subj\n0,cam0,head,1.0,2.0,0.9,a\n')
    with pytest.raises(LabelError) as error:
        read_label_rows(path, points=points)
    text = str(error.value)
    assert '\n' not in text and text.startswith(f'{path}:1: header is ')
    expected = ('frame,camera,keypoint,u,v,score,subject', 'frame,camera,keypoint,u,v,subject') \
        if points else ('stamp_ns,camera,keypoint,u,v,subject',
                        'frame,camera,keypoint,u,v,subject')
    for header in expected + ('frame,camera,keypoint,u,v',):
        assert f"'{header}'" in text, text
