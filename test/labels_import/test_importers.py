"""Importers on files written in each tool's own published layout (DeepLabCut / Lightning
Pose tables via pandas as DeepLabCut writes them, SLEAP analysis HDF5 via h5py with SLEAP's
MATLAB-order datasets, anipose pose-2d H5, the real DANNCE Label3D file): exact values,
frame indices from image names, cameras from video / file names."""
import numpy as np
import pandas as pd
import pytest

from monet_ros.labels import LabelError, resolve_labels
from monet_ros.labels_import import import_labels
from monet_ros.labels_import.dlc import frame_of_image

CAMERAS = ('cam1', 'cam2', 'cam10')
BODYPARTS = ('snout', 'tail')


def dlc_frame(index, values, scorer='Alice', individuals=None, likelihood=None):
    """A DataFrame exactly as DeepLabCut builds CollectedData / prediction tables."""
    coords = ('x', 'y') if likelihood is None else ('x', 'y', 'likelihood')
    if individuals:
        cols = pd.MultiIndex.from_product([[scorer], individuals, BODYPARTS, coords],
                                          names=['scorer', 'individuals', 'bodyparts',
                                                 'coords'])
    else:
        cols = pd.MultiIndex.from_product([[scorer], BODYPARTS, coords],
                                          names=['scorer', 'bodyparts', 'coords'])
    return pd.DataFrame(values, index=index, columns=cols)


def test_image_names_give_frame_indices():
    assert frame_of_image('img0042.png') == 42
    assert frame_of_image('labeled-data/cam1_run3/img00007.png') == 7
    assert frame_of_image('frame_12_cam2.jpg') == 2 and frame_of_image('img.png') is None


@pytest.mark.parametrize('layout', ['csv-3index', 'csv-path', 'h5', 'h5-table'])
def test_deeplabcut_collected_data(tmp_path, layout):
    rng = np.random.default_rng(1)
    values = rng.uniform(0, 500, (3, 4))
    values[1, 2:] = np.nan                              # tail unlabelled in one image
    images = ['img0003.png', 'img0042.png', 'img0107.png']
    project = tmp_path / 'project'
    rows_expected = {}
    for cam, video in (('cam2', 'trial1_cam2'), ('cam10', 'trial1_cam10')):
        folder = project / 'labeled-data' / video
        folder.mkdir(parents=True)
        if layout in ('csv-path', 'h5-table'):
            index = [f'labeled-data/{video}/{im}' for im in images]
        else:
            index = pd.MultiIndex.from_tuples([('labeled-data', video, im) for im in images])
        df = dlc_frame(index, values)
        if layout.startswith('h5'):   # pandas' table format needs a flat index (paths)
            df.to_hdf(folder / 'CollectedData_Alice.h5', key='df_with_missing', mode='w',
                      format='table' if layout == 'h5-table' else 'fixed')
        else:
            df.to_csv(folder / 'CollectedData_Alice.csv')
        for i, frame in enumerate((3, 42, 107)):
            for k, part in enumerate(BODYPARTS):
                if np.isfinite(values[i, 2 * k]):
                    rows_expected[(frame, cam, part)] = tuple(values[i, 2 * k:2 * k + 2])
    result = import_labels('dlc', project, cameras=CAMERAS)
    got = {(r.frame, r.camera, r.keypoint): (r.u, r.v) for r in result.rows}
    assert got == rows_expected                         # exact floats
    assert result.keypoints == BODYPARTS
    if layout == 'csv-3index':
        first = min(result.rows, key=lambda r: (r.camera, r.line))
        assert first.line == 4 and first.source.endswith('CollectedData_Alice.csv')


def test_lightning_pose_multiview_csv_and_multi_animal(tmp_path):
    values = np.array([[1.5, 2.5, 3.5, 4.5]])
    for view in ('cam1', 'cam2'):
        df = dlc_frame([f'labeled-data/session_{view}/img00009.png'], values, scorer='lp')
        df.to_csv(tmp_path / f'CollectedData_{view}.csv')
    result = import_labels('lightning-pose', tmp_path, cameras=CAMERAS)
    assert sorted((r.camera, r.frame, r.keypoint, r.u, r.v) for r in result.rows) == [
        ('cam1', 9, 'snout', 1.5, 2.5), ('cam1', 9, 'tail', 3.5, 4.5),
        ('cam2', 9, 'snout', 1.5, 2.5), ('cam2', 9, 'tail', 3.5, 4.5)]
    # multi-animal: 4 header rows; each individual a subject (the keypoint the bodypart);
    # monet triangulate's names individual/bodypart kept as instance_keypoints
    ma = dlc_frame(pd.MultiIndex.from_tuples([('labeled-data', 'cam1', 'img5.png')]),
                   np.arange(8.0)[None], individuals=['m1', 'm2'])
    ma.to_csv(tmp_path / 'ma.csv')
    result = import_labels('dlc', tmp_path / 'ma.csv', cameras=CAMERAS)
    assert result.keypoints == ('snout', 'tail') and result.subjects == {'m1': 0, 'm2': 1}
    assert result.instance_keypoints == ('m1/snout', 'm1/tail', 'm2/snout', 'm2/tail')
    assert [(r.keypoint, r.u, r.v, r.subject, r.instance) for r in result.rows][3] == \
        ('tail', 6.0, 7.0, 1, 'm2')
    assert 'subjects: m1=0, m2=1 (DeepLabCut individuals)' in result.note


def test_deeplabcut_errors_name_file_line_and_field(tmp_path):
    df = dlc_frame(['labeled-data/cam1/img1.png'], np.array([[1.0, 2.0, 3.0, 4.0]]))
    path = tmp_path / 'CollectedData_x.csv'
    df.to_csv(path)
    path.write_text(path.read_text().replace('3.0', 'abc'))
    with pytest.raises(LabelError, match=r"CollectedData_x.csv:4: field tail/x: 'abc' is not "
                       'a number'):
        import_labels('dlc', path, cameras=CAMERAS)
    bad = tmp_path / 'noframe.csv'
    dlc_frame(['labeled-data/cam1/image.png'], np.ones((1, 4))).to_csv(bad)
    with pytest.raises(LabelError, match=r'noframe.csv:4: field image: .* has no frame number'):
        import_labels('dlc', bad, cameras=CAMERAS)
    plain = tmp_path / 'plain.csv'
    plain.write_text('a,b\n1,2\n')
    with pytest.raises(LabelError, match=r'plain.csv:1: expected header rows scorer, '
                       'bodyparts, coords'):
        import_labels('dlc', plain)


def write_sleap(path, tracks_fnc2t, nodes, video, scores=None, occupancy=None):
    """An analysis HDF5 as SLEAP writes it: documented shapes, stored transposed."""
    import h5py
    n_frames, _, _, n_tracks = tracks_fnc2t.shape
    occupancy = np.ones((n_tracks, n_frames), np.uint8) if occupancy is None else occupancy
    with h5py.File(path, 'w') as f:
        f['tracks'] = tracks_fnc2t.T                     # frames*nodes*2*tracks, column-major
        f['track_occupancy'] = occupancy.T               # tracks*frames
        f['node_names'] = np.array([n.encode() for n in nodes], dtype='S')
        f['track_names'] = np.array([f'track_{i}'.encode() for i in range(n_tracks)],
                                    dtype='S')
        f['video_path'] = video
        if scores is not None:
            f['point_scores'] = scores.T                 # frames*nodes*tracks


def test_sleap_analysis_hdf5(tmp_path):
    rng = np.random.default_rng(2)
    tracks = rng.uniform(0, 300, (6, 2, 2, 1))            # 6 frames, 2 nodes, xy, 1 track
    tracks[4, 1] = np.nan                                 # node missing in frame 4
    occupancy = np.ones((1, 6), np.uint8)
    occupancy[0, 5] = 0                                   # no instance in frame 5
    scores = np.full((6, 2, 1), 0.9)
    scores[2, 0, 0] = 0.1
    write_sleap(tmp_path / 'labels.v001.analysis.h5', tracks, ['head', 'thorax'],
                '/data/session/cam2.mp4', scores, occupancy)
    result = import_labels('sleap', tmp_path / 'labels.v001.analysis.h5', cameras=CAMERAS)
    got = {(r.frame, r.keypoint): (r.u, r.v) for r in result.rows}
    expected = {(f, n): tuple(tracks[f, k, :, 0]) for f in range(5) for k, n in
                enumerate(['head', 'thorax']) if not (f == 4 and k == 1)}
    assert got == expected and {r.camera for r in result.rows} == {'cam2'}
    result = import_labels('sleap', tmp_path / 'labels.v001.analysis.h5', cameras=CAMERAS,
                           min_score=0.5)
    assert len(result.rows) == len(expected) - 1 and '1 points below --min-score' in result.note
    with pytest.raises(LabelError, match='field tracks: missing; not a SLEAP analysis file'):
        import h5py
        with h5py.File(tmp_path / 'other.h5', 'w') as f:
            f['x'] = 1
        import_labels('sleap', tmp_path / 'other.h5')


def test_anipose_pose_2d_with_likelihood(tmp_path):
    pose = tmp_path / 'pose-2d'
    pose.mkdir()
    values = np.array([[10.0, 20.0, 0.95, 30.0, 40.0, 0.2],
                       [11.0, 21.0, 0.99, np.nan, np.nan, 0.0]])
    for cam in ('cam1', 'cam10'):
        dlc_frame(pd.RangeIndex(2), values, scorer='DLC_resnet50',
                  likelihood=True).to_hdf(pose / f'trial-{cam}.h5', key='df_with_missing',
                                          mode='w')
    result = import_labels('anipose', pose, cameras=CAMERAS, min_score=0.5)
    got = sorted((r.camera, r.frame, r.keypoint, r.u, r.v) for r in result.rows)
    assert got == [(c, f, 'snout', 10.0 + f, 20.0 + f) for c in ('cam1', 'cam10')
                   for f in (0, 1)]
    assert '2 points below --min-score 0.5' in result.note


def test_dannce_label3d_real_file(shared_data):
    from monet_ros.geometry import load_rig
    path = shared_data / 'dannce_markerless_mouse_1' / 'label3d_dannce.mat'
    cameras = load_rig(path, image_size=(1152, 1024))
    names = [c.name for c in cameras]
    result = import_labels('dannce', path, cameras=names)
    assert result.keypoints == tuple(f'kp{k}' for k in range(22))
    # the labels are exact reprojections of the file's 3D labels (MANIFEST): checks the
    # (u, v) pair order, the keypoint order and the camera assignment
    import scipy.io as sio
    mat = sio.loadmat(path)
    got = {(r.camera, r.frame, r.keypoint): (r.u, r.v) for r in result.rows}
    assert len(got) == len(result.rows)
    count = 0
    for v, cam in enumerate(cameras):
        cell = mat['labelData'][v, 0][0, 0]
        X = np.asarray(cell['data_3d'], float).reshape(-1, 22, 3)
        frames = np.asarray(cell['data_frame']).ravel()
        projected = cam.project(X.reshape(-1, 3)).reshape(-1, 22, 2)
        for i, k in zip(*np.nonzero(np.isfinite(X).all(-1))):
            np.testing.assert_allclose(got[(cam.name, int(frames[i]), f'kp{k}')],
                                       projected[i, k], atol=1e-6)
            count += 1
    assert count == len(result.rows) > 6 * 81 * 22 * 0.9
    frames = np.asarray(mat['labelData'][0, 0][0, 0]['data_frame']).ravel()
    # resolved against a recording with those cameras and frames, every row is kept
    stamps = np.arange(int(frames.max()) + 1, dtype=np.int64) * 10_000_000
    labels, report = resolve_labels(result.rows, stamps, cameras, result.keypoints)
    assert report.kept == len(result.rows) and len(labels) == 81


def test_multi_animal_unique_bodyparts_are_no_subject(tmp_path):
    """maDLC's individual 'single' holds the unique bodyparts (arena landmarks): plain names,
    subject 0, not an id of their own."""
    cols = pd.MultiIndex.from_tuples(
        [('a', m, p, c) for m in ('m1', 'm2') for p in BODYPARTS for c in ('x', 'y')]
        + [('a', 'single', 'corner', c) for c in ('x', 'y')],
        names=['scorer', 'individuals', 'bodyparts', 'coords'])
    frame = pd.DataFrame(np.arange(10.0)[None],
                         index=pd.MultiIndex.from_tuples([('labeled-data', 'cam1', 'img5.png')]),
                         columns=cols)
    frame.to_csv(tmp_path / 'ma.csv')
    result = import_labels('dlc', tmp_path / 'ma.csv', cameras=CAMERAS)
    assert result.subjects == {'m1': 0, 'm2': 1}
    assert result.keypoints == ('snout', 'tail', 'corner')
    assert [(r.keypoint, r.subject, r.instance, r.u) for r in result.rows][-1] == \
        ('corner', 0, '', 8.0)


@pytest.mark.parametrize('field', ['tracks', 'point_scores', 'track_occupancy',
                                   'track_names'])
def test_sleap_analysis_field_of_the_wrong_kind_names_file_and_field(tmp_path, field):
    """A SLEAP analysis file whose field holds the wrong kind of data (strings for
    numbers; more track names than tracks) is one LabelError naming the file and field:
    it was numpy's own text naming neither ('could not convert string to float'), and
    track names of another count were replaced by track_0, track_1, ... without a word
    (the ids of a labelled animal then follow another name)."""
    import h5py
    rng = np.random.default_rng(3)
    path = tmp_path / 'cam2.analysis.h5'
    write_sleap(path, rng.uniform(0, 300, (6, 2, 2, 2)), ['head', 'thorax'],
                '/data/cam2.mp4', np.full((6, 2, 2), 0.9))
    with h5py.File(path, 'r+') as f:
        shape = f[field].shape
        del f[field]
        f[field] = np.full((3,) if field == 'track_names' else shape, b'x')
    with pytest.raises(LabelError, match=f'cam2.analysis.h5: field {field}: '):
        import_labels('sleap', path, cameras=CAMERAS)


@pytest.mark.parametrize('suffix', ['csv'])    # pandas writes no .h5 of repeated columns
def test_deeplabcut_bodypart_given_twice_names_file_and_field(tmp_path, suffix):
    """A DeepLabCut table holding one (bodypart, coord) column twice (e.g. a multi-animal
    table whose `individuals` header row was lost: head, neck, ... repeated per animal) is
    one LabelError naming the file and field: the later column silently replaced the
    earlier one (one animal's points dropped without a word)."""
    cols = pd.MultiIndex.from_tuples(
        [('DLC', part, c) for _ in range(2) for part in BODYPARTS for c in ('x', 'y')],
        names=['scorer', 'bodyparts', 'coords'])
    frame = pd.DataFrame(np.arange(3 * len(cols), dtype=float).reshape(3, -1),
                         index=pd.RangeIndex(3), columns=cols)
    path = tmp_path / f'cam1DLC_resnet50.{suffix}'
    frame.to_csv(path)
    with pytest.raises(LabelError, match=f'cam1DLC_resnet50.{suffix}: field '
                       f'{BODYPARTS[0]}/x: given twice'):
        import_labels('dlc', path, cameras=CAMERAS)
