"""References of several subjects (issue 39 leftover): labels with a `subject` column read
as one Reference per subject (load_references; load_reference refuses them in one line
naming the file, the field subject and --subjects), and a several-subject prediction
scored per reference subject (score_subjects) against the track matched to it
(subjects.metrics.assign_subjects) - although the track ids are not the labels' subject
numbers - with figures equal to a brute-force numpy computation."""
from dataclasses import dataclass

from helpers.ring import ring_rig
from helpers.subject_blobs import PERIOD, T0, two_subjects
import numpy as np
import pytest

from monet_ros.evaluation.reference import load_reference, load_references, score_subjects
from monet_ros.labels import LabelError, write_labels
from monet_ros.subjects.metrics import assign_subjects

NAMES = ('a', 'b', 'c')
T = 10
LABELLED = (1, 3, 6, 8)
GT_OF = {0: 1, 1: 0}          # reference subject -> ground-truth subject (swapped)


@dataclass
class Index:
    stamps: np.ndarray
    cameras: list


def _project(cams, X):
    """(..., V, C, 2) px of X (..., C, 3), NaN outside the 320x240 images."""
    uv = np.stack([cam.project(X.reshape(-1, 3)).reshape(X.shape[:-1] + (2,))
                   for cam in cams], -3)
    inside = ((uv >= -0.5) & (uv[..., :1] <= 319.5) & (uv[..., 1:] <= 239.5)).all(-1)
    return np.where(inside[..., None], uv, np.nan)


@pytest.fixture
def scene(tmp_path):
    cams = ring_rig(4, radius=3.0, width=320, height=240, focal=250.0)
    X = two_subjects(T)                                   # (T, 2, 3, 3) m
    stamps = T0 + PERIOD * np.arange(T, dtype=np.int64)
    uv = np.stack([_project(cams, X[:, g]) for g in range(2)], 1)      # (T, 2, V, C, 2)
    uv[3, 1, 2, 0] = np.nan                                # one view unlabelled
    rows = [(int(stamps[t]), cam.name, NAMES[c], *uv[t, GT_OF[s], v, c], s)
            for t in LABELLED for v, cam in enumerate(cams) for s in (0, 1)
            for c in range(3) if np.isfinite(uv[t, GT_OF[s], v, c, 0])]
    write_labels(tmp_path / 'labels.csv', rows)
    return Index(stamps, cams), X, uv, tmp_path / 'labels.csv'


def test_labels_of_two_subjects_are_two_references_and_refused_as_one(scene):
    index, X, uv, path = scene
    refs = load_references(path, index, NAMES)
    assert [r.subject for r in refs] == [0, 1] and refs[0].units == 'm'
    for r in refs:
        g = GT_OF[r.subject]
        assert r.points2d.shape == (T, 4, 3, 2)
        np.testing.assert_array_equal(r.points2d[list(LABELLED)], uv[list(LABELLED), g])
        assert np.isnan(r.points2d[[0, 2, 4, 5, 7, 9]]).all()
        np.testing.assert_allclose(r.X[list(LABELLED)], X[list(LABELLED), g], atol=1e-9)
    with pytest.raises(LabelError) as error:
        load_reference(path, index, NAMES)
    text = str(error.value)
    assert '\n' not in text and text.startswith(f'{path}: field subject: ')
    assert 'subjects 0, 1' in text and '--subjects' in text


def test_each_reference_subject_is_scored_against_its_own_track(scene):
    index, X, uv, path = scene
    refs = load_references(path, index, NAMES)
    rng = np.random.default_rng(5)
    # tracks 7 (ground-truth subject 0) and 3 (ground-truth subject 1): the reference's
    # subject 0 is track 3's, its subject 1 track 7's; track 3 misses instant 6
    track_of = {0: 7, 1: 3}
    stamps, ids, P, p2 = [], [], [], []
    for t in range(T):
        for g in (0, 1):
            if g == 1 and t == 6:
                continue
            x = X[t, g] + rng.normal(0, 0.01, (3, 3))
            x[2] = np.nan if (g, t) == (0, 8) else x[2]      # one joint not triangulated
            stamps.append(index.stamps[t])
            ids.append(track_of[g])
            P.append(x)
            p2.append(_project(index.cameras, X[t, g]) + rng.normal(0, 3.0, (4, 3, 2)))
    order = rng.permutation(len(ids))
    stamps, ids, P, p2 = (np.array(a)[order] for a in (stamps, ids, P, p2))
    instants = np.ones(T, bool)
    instants[1] = False                                      # not scored
    got = score_subjects(refs, stamps, ids, P, p2, (5.0, 10.0), (10.0, 20.0),
                         instants=instants)
    per = got['subjects']
    assert [p['subject'] for p in per] == [0, 1] and [p['track'] for p in per] == [3, 7]
    scored = [3, 6, 8]
    mm_all, px_all, n3 = [], [], 0
    for p in per:
        g = GT_OF[p['subject']]
        mine = ids == track_of[g]
        mm, px = [], []
        for t in scored:
            ref_X = X[t, g]                                  # labels exact: their triangulation
            i = np.flatnonzero(mine & (stamps == index.stamps[t]))
            n3 += 3
            d2 = np.linalg.norm(p2[i[0]] - uv[t, g], axis=-1) if len(i) else \
                np.full((4, 3), np.inf)
            px += d2[np.isfinite(uv[t, g, ..., 0])].tolist()
            if len(i):
                d3 = np.linalg.norm(P[i[0]] - ref_X, axis=-1) * 1000
                mm += d3[np.isfinite(d3)].tolist()
        mm, px = np.array(mm), np.array(px)
        assert p['views_2d'] == len(px) and p['joints_3d'] == 9
        assert p['coverage'] == pytest.approx(len(mm) / 9)
        assert p['mm_median'] == pytest.approx(np.median(mm), abs=1e-5)
        assert p['mm_mean'] == pytest.approx(mm.mean(), abs=1e-5)
        assert p['px_median'] == pytest.approx(np.median(px), rel=1e-9)
        assert p['pck2d@10px'] == pytest.approx(np.mean(px <= 10))
        assert p['pck3d@20mm'] == pytest.approx(np.mean(mm <= 20), abs=1e-12)
        assert p['instants_scored'] == 3 and 5 < p['match_mm'] < 30
        mm_all += mm.tolist()
        px_all += px.tolist()
    # the reference's subject 0 (track 3) lacks instant 6: its 3 joints there are missed
    assert per[0]['coverage'] == pytest.approx(6 / 9) and per[1]['coverage'] == \
        pytest.approx(8 / 9)
    assert got['joints_3d'] == n3 == 18 and got['instants_scored'] == 3
    assert got['coverage'] == pytest.approx(len(mm_all) / 18)
    assert got['mm_median'] == pytest.approx(np.median(mm_all), abs=1e-5)
    assert got['views_2d'] == len(px_all)
    assert got['px_median'] == pytest.approx(np.median(px_all), rel=1e-9)


def test_a_subject_no_track_shares_an_instant_with_gets_none():
    gt = np.full((3, 3, 1, 3), np.nan)
    gt[:, 0, 0] = [0.0, 0.0, 1.0]
    gt[:, 1, 0] = [1.0, 0.0, 1.0]
    gt[2, 2, 0] = [5.0, 0.0, 1.0]           # only at frame 2
    pred = np.full((3, 2, 1, 3), np.nan)
    pred[:2, 0, 0] = [1.1, 0.0, 1.0]        # track 4 near subject 1, frames 0-1
    pred[:2, 1, 0] = [0.0, 0.2, 1.0]        # track 9 near subject 0, frames 0-1
    ids = np.where(np.isfinite(pred).all(-1).any(-1), [[4, 9]], -1)
    track, distance = assign_subjects(gt, pred, ids)
    np.testing.assert_array_equal(track, [9, 4, -1])
    np.testing.assert_allclose(distance[:2], [0.2, 0.1])
    assert np.isnan(distance[2])
