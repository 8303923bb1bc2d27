"""`monet process --subjects 2`: a real trained detector (the blob net, trained once for
the module, blobs of several sizes) over a recording of two subjects of three coloured
blobs walking past each other (helpers.subject_blobs: 4 cameras, 12 frames, 96x96): both
subjects are found (full-frame discovery in the first frame, per-subject crops after),
each keeps one identity throughout (Hungarian match to the ground truth per frame,
subjects.metrics: 0 switches, IDF1 1) and its 3D is within 10 mm of the ground truth on
average and 30 mm in every frame (measured: ~3-5 mm, ~20 mm in the frame where they
pass); the outputs are `monet triangulate --subjects`' (CSV with a subject column, TRC
and NWB per subject). --subjects 1 is the one-subject path, byte for byte."""
from helpers.blob_net import train_blob_net
from helpers.subject_blobs import blob_checkpoint, write_two_subjects
import numpy as np
import pytest

from monet_ros.cli import main as monet
from monet_ros.io import cloud_to_keypoints3d, open_bag
from monet_ros.io.export_tables import read_anipose_csv, read_trc
from monet_ros.subjects.metrics import identity_scores

T = 12
COMMON = ['--quiet', '--threads', '1', '--precision', 'float32']


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp('two_blob_subjects')
    folder, cams, X = write_two_subjects(root / 'rec', T=T)
    model = blob_checkpoint(train_blob_net(steps=400, sigma=(1.2, 4.0)), root / 'blobs.pt')
    return folder, X, model


def _process(scene, out, *extra):
    folder, _, model = scene
    return monet(['process', str(folder / 'recording'), '--rig', str(folder / 'rig.yaml'),
                  '--model', str(model), '--out', str(out), *COMMON, *extra])


def test_two_subjects_are_found_and_keep_their_identity(scene, tmp_path, capsys):
    _, X, _ = scene
    out = tmp_path / 'out'
    assert _process(scene, out, '--subjects', '2', '--link-mm', '450') == 0
    text = capsys.readouterr().out
    assert '2 identities (0, 1), 24 subject-frames, 2 births, 0 deaths' in text
    assert 'frames by subjects tracked: 2: 12' in text
    assert '1 full-frame discovery runs finding 2 subjects from 6 3D keypoint' in text
    table = read_anipose_csv(out / 'keypoints3d.csv')
    # every keypoint a subject-frame lacks is counted (none went unsaid before)
    lost = np.isnan(table['X']).any(-1).sum(0)
    lost = ', '.join(f'{k} {n}' for k, n in zip(table['keypoints'], lost) if n) or 'none'
    assert f'keypoints not triangulated per keypoint over 24 subject-frames: {lost}' \
        in text, text
    ids = np.unique(table['subject'])
    pred = np.full((T, 2, 3, 3), np.nan)
    pred_ids = np.full((T, 2), -1)
    for slot, i in enumerate(ids):
        mine = table['subject'] == i
        np.testing.assert_array_equal(table['fnum'][mine], np.arange(T))
        pred[:, slot], pred_ids[:, slot] = table['X'][mine], i
        trc = read_trc(out / f'keypoints3d_subject{i}.trc')
        np.testing.assert_allclose(trc['X'], table['X'][mine], rtol=1e-12)
    scores = identity_scores(X, pred, pred_ids, threshold=0.1)
    assert scores.switches == 0 and scores.idf1 == 1.0 and scores.matched == 2 * T
    assert (scores.error < 0.010).all(), scores.error
    # every frame: each ground-truth subject's identity within 30 mm
    owner = [np.argmin(np.linalg.norm(pred[0, :, None] - X[0, None], axis=-1).mean(-1)[:, g])
             for g in range(2)]
    per_frame = np.linalg.norm(pred[:, owner] - X, axis=-1).mean(-1)          # (T, 2)
    assert per_frame.max() < 0.030, per_frame
    # the MCAP holds what the live fusion publishes: /monet/keypoints3d with a subject field
    clouds = {t for t in open_bag(out).topics if t.endswith('/keypoints3d')}
    assert clouds == {'/monet/keypoints3d'}
    msgs = list(open_bag(out).messages(['/monet/keypoints3d']))
    assert len(msgs) == T
    for t in (0, T - 1):
        got = cloud_to_keypoints3d(msgs[t].msg, units='m')
        for slot, i in enumerate(ids):
            mine = got['subject'] == i
            np.testing.assert_array_equal(got['keypoint'][mine], np.arange(pred.shape[2]))
            np.testing.assert_allclose(got['X'][mine], pred[t, slot], atol=1e-6)
    from ndx_pose import MultiCameraPoseEstimation  # noqa: F401 (registers the types)
    from pynwb import NWBHDF5IO
    with NWBHDF5IO(str(out / 'keypoints.nwb'), 'r') as io:
        behavior = io.read().processing['behavior']
        for slot, i in enumerate(ids):
            series = behavior[f'monet_pose_subject{i}'].pose_estimation_series['a']
            np.testing.assert_allclose(series.data[:], pred[:, slot, 0], rtol=1e-12)


def test_two_subjects_filtered_per_identity(scene, tmp_path, capsys):
    """--subjects 2 --filter kalman: each identity's rows go through its own Kalman
    smoother: the CSV equals temporal.kalman_smooth run on that identity's unfiltered rows
    alone (the same identities and frames, the subject column kept), and the MCAP adds
    /monet/keypoints3d_filtered with the subject field, holding those points."""
    from monet_ros.temporal import FilterConfig, kalman_smooth
    _, X, _ = scene
    raw_out, out = tmp_path / 'raw', tmp_path / 'filtered'
    assert _process(scene, raw_out, '--subjects', '2', '--link-mm', '450') == 0
    assert _process(scene, out, '--subjects', '2', '--link-mm', '450', '--filter',
                    'kalman') == 0
    text = capsys.readouterr().out
    assert 'filter kalman per subject (2 identities' in text
    raw, table = read_anipose_csv(raw_out / 'keypoints3d.csv'), \
        read_anipose_csv(out / 'keypoints3d.csv')
    np.testing.assert_array_equal(table['subject'], raw['subject'])
    np.testing.assert_array_equal(table['fnum'], raw['fnum'])
    assert sorted(table['extra']) == ['bridged', 'change_mm']
    stamps = np.array([m.stamp_ns for m in open_bag(out).messages(['/monet/keypoints3d'])])
    clouds = list(open_bag(out).messages(['/monet/keypoints3d_filtered']))
    assert len(clouds) == T
    for i in np.unique(raw['subject']):
        mine = raw['subject'] == i
        # independent: the smoother over this identity's rows alone (frames 0..T-1)
        noise = 1.0 + (np.nan_to_num(raw['error'][mine]) / FilterConfig().reprojection_px) ** 2
        alone = kalman_smooth(raw['X'][mine], stamps[raw['fnum'][mine]],
                              FilterConfig(method='kalman'), noise, 'm')
        np.testing.assert_allclose(table['X'][mine], alone.X, atol=1e-9)
        assert np.abs(table['X'][mine] - raw['X'][mine]).max() > 1e-4       # it filtered
        trc = read_trc(out / f'keypoints3d_subject{i}.trc')
        np.testing.assert_allclose(trc['X'], table['X'][mine], rtol=1e-12)
        for t in (0, T - 1):
            got = cloud_to_keypoints3d(clouds[t].msg, units='m')
            assert sorted(np.unique(got['subject'])) == sorted(np.unique(raw['subject']))
            np.testing.assert_allclose(got['X'][got['subject'] == i],
                                       table['X'][mine][t], atol=1e-6)


def test_synth_recording_without_subjects_found_still_writes_and_counts(tmp_path, capsys):
    """A `monet synth --subjects 2` recording (its own rig from /tf_static + camera_info,
    human14) through an untrained net: nothing is found, every frame is counted, the
    analysis files are written (no rows)."""
    from helpers.recordings import small_checkpoint
    rec = tmp_path / 'rec'
    assert monet(['synth', '--out', str(rec), '--cameras', '3', '--frames', '3', '--width',
                  '160', '--height', '120', '--subjects', '2', '--quiet']) == 0
    out = tmp_path / 'out'
    assert monet(['process', str(rec / 'recording'), '--model',
                  str(small_checkpoint(tmp_path / 'h14.pt')), '--out', str(out), '--subjects',
                  '2', '--skeleton', 'human14', *COMMON]) == 0
    text = capsys.readouterr().out
    assert 'monet process: 3 frames (9 views, 0 missing)' in text
    assert '0 identities, 0 subject-frames' in text and 'frames by subjects tracked: 0: 3' \
        in text and '3 full-frame discovery runs finding 0 subjects' in text
    assert read_anipose_csv(out / 'keypoints3d.csv')['X'].shape[0] == 0
    assert (out / 'keypoints.nwb').is_file()


def test_one_subject_is_the_one_subject_path(scene, tmp_path, capsys):
    outs = [tmp_path / 'default', tmp_path / 'one']
    assert _process(scene, outs[0]) == 0
    assert _process(scene, outs[1], '--subjects', '1') == 0
    for name in ('keypoints3d.csv', 'keypoints3d.trc', 'detections2d.npz'):
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), name
    clouds = [[bytes(m.msg.data) for m in open_bag(o).messages(['/monet/keypoints3d'])]
              for o in outs]
    assert len(clouds[0]) == T and clouds[0] == clouds[1]


def test_bad_subject_options_are_one_line(scene, tmp_path, capsys):
    for extra, words in ((['--subjects', '0'], "'subjects'"),
                         (['--subjects', '2', '--no-track'], '--no-track'),
                         (['--subjects', '2', '--heatmaps'], '--heatmaps'),
                         (['--subjects', '2', '--export', 'npz'], 'npz'),
                         (['--subjects', '2', '--link-mm', '0'], "'link_mm'"),
                         (['--subjects', '2', '--gate-mm', '-1'], "'gate_mm'"),
                         # named as typed (it said 'threshold_px', the field of the
                         # association: a newcomer looked at --threshold-px)
                         (['--subjects', '2', '--association-px', '0'],
                          '--association-px: ')):
        code = _process(scene, tmp_path / 'x', *extra)
        err = capsys.readouterr().err.strip().splitlines()
        err = [line for line in err if 'precision' not in line]
        assert code == 2 and len(err) == 1 and words in err[0], (extra, err)
        assert not (tmp_path / 'x').exists()


def test_a_truncated_recording_is_reported_as_with_one_subject(scene, tmp_path, capsys):
    """A recording cut short (no footer, a record running past the end) is read as far as
    it goes and the reader's report is printed, with --subjects 2 as with one subject."""
    import shutil

    folder, _, _ = scene
    cut = tmp_path / 'cut'
    shutil.copytree(folder / 'recording', cut)
    mcap = next(cut.glob('*.mcap'))
    data = mcap.read_bytes()
    mcap.write_bytes(data[:-200])              # the footer and the end of the summary lost
    reports = []
    for extra in ([], ['--subjects', '2', '--link-mm', '450']):
        code = monet(['process', str(cut), '--rig', str(folder / 'rig.yaml'), '--model',
                      str(scene[2]), '--out', str(tmp_path / f'out{len(extra)}'), *COMMON,
                      *extra])
        err = capsys.readouterr().err
        lines = [line for line in err.splitlines()
                 if line.startswith(f'monet process: reading {cut}: ')]
        assert code == 0 and len(lines) == 1, (extra, err)
        reports.append(lines[0])
    assert reports[0] == reports[1]
    assert 'footer' in reports[0] or 'truncated' in reports[0], reports[0]


def test_tracker_options_reach_the_tracker(scene, tmp_path, capsys):
    """The tracker's options reach `monet process --subjects`' core: with --min-keypoints
    4 a subject of the blobs' 3 keypoints is neither a discovered hypothesis
    (subjects.detection, step e) nor a track (subjects.tracking, step 5), so no identity
    ever starts; the options themselves: test_tracker_options.py."""
    _, X, _ = scene
    assert X.shape[2] == 3
    out = tmp_path / 'few'
    assert _process(scene, out, '--subjects', '2', '--link-mm', '450',
                    '--min-keypoints', '4') == 0
    text = capsys.readouterr().out
    assert '0 identities, 0 subject-frames, 0 births, 0 deaths' in text, text
    assert f'{T} full-frame discovery runs finding 0 subjects' in text, text
    assert len(read_anipose_csv(out / 'keypoints3d.csv')['fnum']) == 0


def test_several_recordings_print_each_ones_summary(scene, tmp_path, capsys):
    """`monet process REC1 REC2 --subjects 2`: each recording's summary (frames, the
    identities with their births and deaths, the keypoints not triangulated, the detection
    and skipped counts, the filter's, the files written) is printed after the recording's
    name, line for line what a run of that recording alone prints (only the closing table
    was printed); the precision line is the command's, printed once."""
    import re
    folder, _, model = scene
    other, _, _ = write_two_subjects(tmp_path / 'other', T=8)
    recs = [folder / 'recording', other / 'recording']
    options = ['--rig', str(folder / 'rig.yaml'), '--model', str(model), *COMMON,
               '--subjects', '2', '--link-mm', '450', '--filter', 'kalman']

    def plain(line, out):            # times and output folders differ from run to run
        return re.sub(r'\d+\.\d+ s\b', 'S s', line.replace(str(out), 'OUT'))

    alone = []
    for i, rec in enumerate(recs):
        out = tmp_path / f'single{i}'
        assert monet(['process', str(rec), '--out', str(out), *options]) == 0
        lines = capsys.readouterr().out.splitlines()
        alone.append([plain(line.removeprefix('monet process: '), out) for line in lines
                      if 'precision' not in line])
    many = tmp_path / 'many'
    assert monet(['process', *map(str, recs), '--out', str(many), *options]) == 0
    text = capsys.readouterr().out.splitlines()
    for rec, name, single in zip(recs, ('recording', 'recording_2'), alone):
        head = f'monet process: {rec}: '
        mine = [plain(line.removeprefix(head), many / name) for line in text
                if line.startswith(head)]
        assert mine == single, (mine, single)
    assert any('2 births, 0 deaths' in line for line in alone[0]), alone[0]
    assert any(line.startswith('subjects: ') for line in alone[1]), alone[1]
    assert any(line.startswith('wrote trc subject ') for line in alone[1]), alone[1]
    assert sum('precision' in line for line in text) == 1, text
