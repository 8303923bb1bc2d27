"""`monet eval --reference labels.csv --subjects 2` (issue 39 leftover): a real trained
detector (the blob net) over a real recording of two subjects (helpers.subject_blobs),
scored against labels of BOTH subjects (exact projections of the ground truth at four
instants) whose subject numbers are SWAPPED relative to the identities `monet process
--subjects 2` gives them: each reference subject is matched to its own track and gets its
own errors - the 3D figures equal a brute-force computation from `monet process
--subjects 2`'s keypoints3d.csv (subject column) against the labelled points, the 2D are
those of the right subject (a few px; the other subject is ~0.7 m away, tens of px).
Without --subjects the reference is refused in one line naming the file, the field
subject and --subjects."""
import csv
import json

from helpers.blob_net import NAMES, train_blob_net
from helpers.subject_blobs import blob_checkpoint, write_two_subjects
import numpy as np
import pytest

from monet_ros.cli import main as monet
from monet_ros.io.export_tables import read_anipose_csv
from monet_ros.labels import write_labels

T = 12
LABELLED = (0, 3, 8, 11)


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp('eval_two_subjects')
    folder, cams, X = write_two_subjects(root / 'rec', T=T)
    model = blob_checkpoint(train_blob_net(steps=400, sigma=(1.2, 4.0)), root / 'blobs.pt')
    return folder, cams, X, model, root


def test_each_reference_subject_gets_its_own_track_and_errors(scene, tmp_path, capsys):
    folder, cams, X, model, root = scene
    rig = str(folder / 'rig.yaml')
    # the tracks of `monet process --subjects 2` (the run eval makes), from its CSV
    assert monet(['process', str(folder / 'recording'), '--rig', rig, '--model', str(model),
                  '--out', str(tmp_path / 'proc'), '--quiet', '--export', 'csv',
                  '--subjects', '2', '--link-mm', '450']) == 0
    table = read_anipose_csv(tmp_path / 'proc' / 'keypoints3d.csv')
    assert sorted(np.unique(table['subject'])) == [0, 1]
    stamps = np.load(folder / 'ground_truth.npz')['stamps']
    tracks = {}
    for i in (0, 1):
        mine = table['subject'] == i
        P = np.full((T, 3, 3), np.nan)
        P[np.searchsorted(stamps, table['stamps_ns'][mine])] = table['X'][mine]
        tracks[i] = P
    # by hand: the ground-truth subject each track follows
    dist = np.array([[np.nanmean(np.linalg.norm(tracks[i] - X[:, g], axis=-1))
                      for g in (0, 1)] for i in (0, 1)])
    follows = {i: int(np.argmin(dist[i])) for i in (0, 1)}
    assert sorted(follows.values()) == [0, 1]
    # the reference's subject s is the ground-truth subject of track 1 - s (swapped)
    gt_of = {s: follows[1 - s] for s in (0, 1)}
    uv = np.stack([cam.project(X.reshape(-1, 3)).reshape(T, 2, 3, 2) for cam in cams], 2)
    uv = np.where(((uv >= -0.5) & (uv <= 95.5)).all(-1, keepdims=True), uv, np.nan)
    rows = [(int(stamps[t]), cam.name, NAMES[c], *uv[t, gt_of[s], v, c], s)
            for t in LABELLED for v, cam in enumerate(cams) for s in (0, 1)
            for c in range(3) if np.isfinite(uv[t, gt_of[s], v, c, 0])]
    labels = tmp_path / 'labels.csv'
    write_labels(labels, rows)
    args = ['eval', str(model), '--data', str(folder), '--rig', rig, '--reference',
            str(labels), '--px-thresholds', '3,10']
    capsys.readouterr()
    assert monet(args + ['--out', str(tmp_path / 'one')]) == 2
    err = capsys.readouterr().err.strip()
    assert '\n' not in err and str(labels) in err and 'field subject' in err and \
        '--subjects' in err, err
    assert monet(args + ['--out', str(tmp_path / 'report'), '--subjects', '2',
                         '--link-mm', '450']) == 0
    out = capsys.readouterr().out
    assert 'subjects: 2 in the reference (0, 1), the model run with --subjects 2' in out
    with open(tmp_path / 'report' / 'reference.csv') as f:
        got = list(csv.DictReader(f))
    assert json.loads((tmp_path / 'report' / 'reference.json').read_text())[1]['track'] == 1
    assert [(r['subject'], r['track']) for r in got] == [('all', ''), ('0', '1'), ('1', '0')]
    # the printed table: mode, step, subject, track (pooled row, then one per subject)
    assert f'| {model} | blobs | 0 | all |  | ' in out and \
        f'| {model} | blobs | 0 | 0 | 1 | ' in out and f'| {model} | blobs | 0 | 1 | 0 | ' in out
    pooled_mm, pooled_views = [], 0
    for r in got[1:]:
        s, track = int(r['subject']), int(r['track'])
        g = gt_of[s]
        # brute force: the matched track's 3D (the CSV) against the labels' triangulation
        # (exact projections of the ground truth: the ground truth)
        d = np.linalg.norm(tracks[track][list(LABELLED)] - X[list(LABELLED), g], axis=-1)
        mm = d[np.isfinite(d)] * 1000
        assert int(r['joints_3d']) == 12 and int(r['instants_scored']) == 4
        assert float(r['coverage']) == pytest.approx(mm.size / 12)
        assert float(r['mm_median']) == pytest.approx(np.median(mm), abs=1e-3)
        assert float(r['mm_mean']) == pytest.approx(mm.mean(), abs=1e-3)
        assert float(r['match_mm']) < 30
        views = int(np.isfinite(uv[list(LABELLED), g, ..., 0]).sum())
        assert int(r['views_2d']) == views
        # its own subject's 2D: a few px (the other subject's blobs are tens of px away)
        assert float(r['px_median']) < 3 and float(r['pck2d@10px']) > 0.8, r
        pooled_mm += mm.tolist()
        pooled_views += views
    assert int(got[0]['views_2d']) == pooled_views and int(got[0]['joints_3d']) == 24
    assert float(got[0]['mm_median']) == pytest.approx(np.median(pooled_mm), abs=1e-3)


@pytest.mark.parametrize('extra, words', [
    (['--reference', 'ref.csv', '--link-mm', '500'],
     'monet eval: --link-mm applies only with --subjects N (N >= 2); monet eval scores one '
     'subject without it'),
    (['--subjects', '2'], '--subjects and its settings apply only with --reference'),
])
def test_subject_options_without_their_run_are_refused(extra, words, tmp_path, capsys,
                                                       monkeypatch):
    # they would be ignored: refused in one line before any file is read
    monkeypatch.chdir(tmp_path)
    assert monet(['eval', 'm.pt', '--data', 'rec', '--out', 'o', *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert '\n' not in err and words in err, err
