"""Instance tables split by instance: the points table's `subject` column, the split of
'<instance>/<keypoint>' names, and the arrays against a brute-force loop."""
import numpy as np
import pytest

from monet_ros.labels import LabelError
from monet_ros.labels_import.points2d import read_points2d
from monet_ros.subjects.offline import instance_arrays, split_instances


def test_subject_column_names_instances(tmp_path):
    path = tmp_path / 'points.csv'
    path.write_text('frame,camera,keypoint,u,v,score,subject\n'
                    '0,cam0,head,1.5,2.5,0.9,a\n'
                    '0,cam0,head,3.5,4.5,0.8,b\n'
                    '1,cam1,tail,5.0,6.0,,a\n')
    pts = read_points2d(path, ['cam0', 'cam1'])
    assert pts.keypoints == ('a/head', 'b/head', 'a/tail')
    np.testing.assert_array_equal(pts.points[0, 0, :2], [[1.5, 2.5], [3.5, 4.5]])
    assert pts.score[1, 1, 2] == 1.0 and pts.unscored == 1
    path.write_text('frame,camera,keypoint,u,v,subject\n0,cam0,head,1,2,\n')
    with pytest.raises(LabelError, match=r'points.csv:2: field subject'):
        read_points2d(path, ['cam0'])


def test_split_and_arrays_match_a_loop():
    names = ('t0/head', 't0/tail', 't1/tail', 't2/head', 't1/head')
    instances, nodes, index = split_instances(names)
    assert instances == ('t0', 't1', 't2') and nodes == ('head', 'tail')
    rng = np.random.default_rng(0)
    points = rng.normal(size=(3, 2, len(names), 2))
    score = rng.random((3, 2, len(names)))
    p, s = instance_arrays(points, score, index)
    assert p.shape == (3, 2, 3, 2, 2)
    for i, inst in enumerate(instances):
        for k, node in enumerate(nodes):
            name = f'{inst}/{node}'
            if name in names:
                np.testing.assert_array_equal(p[:, :, i, k], points[:, :, names.index(name)])
                np.testing.assert_array_equal(s[:, :, i, k], score[:, :, names.index(name)])
            else:
                assert np.isnan(p[:, :, i, k]).all() and np.isnan(s[:, :, i, k]).all()
    # a skeleton fixes the order; an unknown node is named
    assert split_instances(names, ('tail', 'head'))[1] == ('tail', 'head')
    with pytest.raises(ValueError, match="keypoint 'tail' .*t0/tail"):
        split_instances(names, ('head',))
    # a single instance without '/' names
    assert split_instances(('head', 'tail'))[0] == ('',)


def test_the_identity_summary_counts_in_words():
    """One identity reads '1 identity (4)', none '0 identities' (no empty list), and every
    count agrees in number with its noun."""
    from monet_ros.subjects.offline import SubjectRows

    def rows(subject, births, deaths):
        subject = np.asarray(subject, int)
        empty = np.zeros((len(subject), 1))
        return SubjectRows(frame=np.arange(len(subject)), subject=subject, X=empty[..., None],
                           error=empty, ncams=empty, score=empty, births=births,
                           deaths=deaths, instances=0, unmatched=0, extra=0, untracked=0,
                           seconds=0.0)
    assert rows([4], 1, 0).identities_text() == \
        '1 identity (4), 1 subject-frame, 1 birth, 0 deaths'
    assert rows([], 0, 0).identities_text() == \
        '0 identities, 0 subject-frames, 0 births, 0 deaths'
    assert rows([0, 1, 1], 2, 1).identities_text() == \
        '2 identities (0, 1), 3 subject-frames, 2 births, 1 death'
