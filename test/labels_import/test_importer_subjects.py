"""Several animals per camera file become subjects (issue 39 item 6): SLEAP analysis HDF5
tracks (h5py, SLEAP's MATLAB-order datasets) and multi-animal DeepLabCut individuals (CSV,
and H5 through pandas' to_hdf with key df_with_missing, as DeepLabCut writes it) of a
real two-subject recording (helpers.subject_blobs) go through `monet labels import` to a
labels table with a subject column whose points are exactly the ground-truth projections of
each subject, with one id per track / individual name in every camera (even where a file
lists the tracks in another order), the mapping reported; `monet triangulate` still reads
the same files as '<instance>/<keypoint>' per camera, and `monet eval --reference` reads
the tracks as one reference per subject (evaluation.reference.load_references)."""
from helpers.subject_blobs import write_two_subjects
import numpy as np
import pandas as pd
import pytest

from monet_ros.cli import main as monet
from monet_ros.labels import read_labels
from monet_ros.labels_import import import_labels
from monet_ros.labels_import.points2d import read_points2d
from monet_ros.learning.recording import load_recording

T = 8
NAMES = ('a', 'b', 'c')
TRACKS = ('mouse_a', 'mouse_b')


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp('importer_subjects')
    folder, cams, X = write_two_subjects(root / 'rec', T=T, width=96, height=96)
    uv = np.stack([cam.project(X.reshape(-1, 3)).reshape(T, 2, 3, 2) for cam in cams], 1)
    inside = ((uv >= -0.5) & (uv <= 95.5)).all(-1)
    uv = np.where(inside[..., None], uv, np.nan)          # (T, V, S, C, 2)
    return folder, cams, uv, root


def write_sleap(path, uv_tsc2, track_names, video):
    """An analysis HDF5 as SLEAP writes it (documented shapes, stored transposed): tracks
    (frames, nodes, 2, tracks), track_occupancy (tracks, frames)."""
    import h5py
    tracks = uv_tsc2.transpose(0, 2, 3, 1)               # (frames, nodes, 2, tracks)
    occupancy = np.isfinite(uv_tsc2[..., 0]).any(-1).T.astype(np.uint8)   # (tracks, frames)
    with h5py.File(path, 'w') as f:
        f['tracks'] = tracks.T
        f['track_occupancy'] = occupancy.T
        f['node_names'] = np.array([n.encode() for n in NAMES], dtype='S')
        f['track_names'] = np.array([n.encode() for n in track_names], dtype='S')
        f['video_path'] = video


def check_table(path, folder, uv):
    table = read_labels(path, NAMES)
    assert table.subjects == [0, 1]
    rec = load_recording(folder, labels=path, skeleton=list(NAMES))
    np.testing.assert_array_equal(rec.labels, uv[:, :, 0])        # exact floats
    assert rec.num_subjects == 2 and list(rec.other_subjects) == [1] * T
    np.testing.assert_array_equal(rec.other_labels, uv[rec.other_instants, :, 1])


def test_sleap_tracks_become_subjects(scene, tmp_path, capsys):
    folder, cams, uv, _ = scene
    sleap = tmp_path / 'sleap'
    sleap.mkdir()
    for v, cam in enumerate(cams):
        order = (1, 0) if v == 2 else (0, 1)             # cam2 lists mouse_b first
        write_sleap(sleap / f'{cam.name}.analysis.h5', uv[:, v][:, list(order)],
                    [TRACKS[i] for i in order], f'/data/{cam.name}.mp4')
    result = import_labels('sleap', sleap, cameras=[c.name for c in cams])
    assert result.subjects == {'mouse_a': 0, 'mouse_b': 1} and result.keypoints == NAMES
    assert 'subjects: mouse_a=0, mouse_b=1 (SLEAP tracks)' in result.note
    out = tmp_path / 'labels.csv'
    assert monet(['labels', 'import', 'sleap', str(sleap), '--rec', str(folder / 'recording'),
                  '--rig', str(folder / 'rig.yaml'), '--out', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'subjects: mouse_a=0, mouse_b=1 (SLEAP tracks)' in text
    assert out.read_text().splitlines()[0] == 'stamp_ns,camera,keypoint,u,v,subject'
    check_table(out, folder, uv)
    # a reference for `monet eval --reference --subjects N`: one per track, its points
    from monet_ros.evaluation.reference import load_references
    from monet_ros.learning.recording_index import recording_index
    refs = load_references(sleap, recording_index(folder), NAMES, fmt='sleap')
    assert [r.subject for r in refs] == [0, 1]
    for s, r in enumerate(refs):
        np.testing.assert_array_equal(r.points2d, uv[:, :, s])
    # monet triangulate's reader: '<track>/<node>' per camera, as before
    points = read_points2d(sleap, [c.name for c in cams])
    assert points.keypoints == tuple(f'{t}/{n}' for t in TRACKS for n in NAMES)
    k = points.keypoints.index('mouse_b/c')
    np.testing.assert_array_equal(points.points[:, 2, k], uv[:, 2, 1, 2])


@pytest.mark.parametrize('suffix', ['csv', 'h5'])
def test_deeplabcut_individuals_become_subjects(scene, tmp_path, suffix, capsys):
    folder, cams, uv, _ = scene
    project = tmp_path / 'project'
    for v, cam in enumerate(cams):
        order = (1, 0) if v == 1 else (0, 1)             # cam1 lists mouse_b first
        cols = pd.MultiIndex.from_product(
            [['alice'], [TRACKS[i] for i in order], list(NAMES), ['x', 'y']],
            names=['scorer', 'individuals', 'bodyparts', 'coords'])
        values = uv[:, v][:, list(order)].reshape(T, -1)  # (frames, individual x part x xy)
        index = pd.MultiIndex.from_tuples([('labeled-data', f'session_{cam.name}',
                                            f'img{t:04d}.png') for t in range(T)])
        frame = pd.DataFrame(values, index=index, columns=cols)
        where = project / 'labeled-data' / f'session_{cam.name}'
        where.mkdir(parents=True)
        if suffix == 'csv':
            frame.to_csv(where / 'CollectedData_alice.csv')
        else:
            frame.index = [f'labeled-data/session_{cam.name}/img{t:04d}.png'
                           for t in range(T)]
            frame.to_hdf(where / 'CollectedData_alice.h5', key='df_with_missing',
                         format='table', mode='w')
    out = tmp_path / 'labels.csv'
    assert monet(['labels', 'import', 'dlc', str(project), '--rec', str(folder / 'recording'),
                  '--rig', str(folder / 'rig.yaml'), '--out', str(out)]) == 0
    assert 'subjects: mouse_a=0, mouse_b=1 (DeepLabCut individuals)' in \
        capsys.readouterr().out
    check_table(out, folder, uv)


def test_one_track_stays_one_subject_without_a_subject_column(scene, tmp_path):
    folder, cams, uv, _ = scene
    sleap = tmp_path / 'one'
    sleap.mkdir()
    for v, cam in enumerate(cams):
        write_sleap(sleap / f'{cam.name}.analysis.h5', uv[:, v, :1], ['mouse_a'],
                    f'/data/{cam.name}.mp4')
    result = import_labels('sleap', sleap, cameras=[c.name for c in cams])
    assert result.subjects == {} and result.keypoints == NAMES and result.note == ''
    assert {r.subject for r in result.rows} == {0}
    out = tmp_path / 'labels.csv'
    assert monet(['labels', 'import', 'sleap', str(sleap), '--rec', str(folder / 'recording'),
                  '--rig', str(folder / 'rig.yaml'), '--out', str(out)]) == 0
    assert out.read_text().splitlines()[0] == 'stamp_ns,camera,keypoint,u,v'


def test_info_counts_every_subject_and_eval_refuses_them(scene, tmp_path, capsys):
    from monet_ros.evaluation.reference import load_reference
    from monet_ros.labels import LabelError, write_labels
    from monet_ros.learning.recording_index import recording_index

    folder, cams, uv, _ = scene
    index = recording_index(folder)
    rows = [(int(index.stamps[t]), cam.name, NAMES[c], *uv[t, v, s, c], s)
            for t in (1, 4) for v, cam in enumerate(cams) for s in (0, 1) for c in range(3)
            if np.isfinite(uv[t, v, s, c, 0])]
    path = tmp_path / 'labels.csv'
    write_labels(path, rows)
    assert monet(['info', str(folder), '--labels', str(path)]) == 0
    text = capsys.readouterr().out
    assert 'subjects: 0, 1' in text
    for cam in cams:
        n = sum(r[1] == cam.name for r in rows)
        assert f'  {cam.name}: {n} labelled keypoints' in text
    with pytest.raises(LabelError, match=r'labels.csv: field subject: the reference labels '
                       r'hold subjects 0, 1; score them against a model run with several '
                       r'subjects \(--subjects N\)'):
        load_reference(path, index, NAMES)
