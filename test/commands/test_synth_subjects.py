"""`monet synth --subjects 2`: two subjects that pass and hide each other, with their
ground truth and their per-camera instances (shuffled labels), which `monet triangulate
--subjects 2` turns back into the two ground-truth subjects with one identity each."""
import numpy as np

from monet_ros.cli import main as monet
from monet_ros.geometry import load_rig
from monet_ros.io.export_tables import read_anipose_csv, read_trc
from monet_ros.skeleton import load_skeleton
from monet_ros.synth.render import occlusion
from monet_ros.synth.subjects import make_subjects

FRAMES = 40


def test_synth_two_subjects_then_triangulate_them(tmp_path, capsys):
    out = tmp_path / 'rec'
    code = monet(['synth', '--out', str(out), '--cameras', '4', '--frames', str(FRAMES),
                  '--width', '160', '--height', '120', '--subjects', '2', '--quiet',
                  '--hfov', '80'])
    assert code == 0
    assert (out / 'points2d.csv').is_file() and 'Several subjects' in \
        (out / 'README.md').read_text()
    gt = np.load(out / 'ground_truth.npz')
    X = gt['subjects_keypoints3d']
    assert X.shape == (FRAMES, 2, 14, 3)
    np.testing.assert_array_equal(gt['keypoints3d'], X[:, 0])
    # the subjects are make_subjects' (synth.subjects), at the recording's times
    times = (gt['stamps'] - gt['stamps'][0]) / 1e9
    sk = load_skeleton('human14')
    subjects = make_subjects(sk, 2)
    np.testing.assert_allclose(X[:, 1], subjects[1].keypoints3d(times), atol=1e-12)
    # each hides the other: more of subject 0 is hidden than by its own limbs alone
    cams = load_rig(out / 'rig.yaml')
    A, B = subjects[0].capsule_arrays(times)
    own = occlusion(cams, X[:, 0], A, B, subjects[0].radii, subjects[0].attached)
    both = gt['subjects_occluded'][:, :, 0]
    assert (both >= own).all() and both.sum() > own.sum()
    rows = (out / 'points2d.csv').read_text().splitlines()[1:]
    assert len(rows) == int((gt['subjects_in_image'] & ~gt['subjects_occluded']).sum())
    code = monet(['triangulate', str(out / 'points2d.csv'), '--rig', str(out / 'rig.yaml'),
                  '--subjects', '2', '--fps', '30', '--skeleton', 'human14',
                  '--out', str(tmp_path / 'tri')])
    assert code == 0, capsys.readouterr().err
    table = read_anipose_csv(tmp_path / 'tri' / 'keypoints3d.csv')
    ids = np.unique(table['subject'])
    assert len(ids) == 2
    owners = set()
    for i in ids:
        mine = table['subject'] == i
        err = np.linalg.norm(table['X'][mine][:, None] - X[table['fnum'][mine]], axis=-1)
        err = np.nanmean(err, axis=-1)                                  # (frames, 2)
        owner = np.argmin(err, axis=1)
        assert (owner == owner[0]).all()
        assert np.nanmax(err[:, owner[0]]) < 1e-3                       # exact projections
        owners.add(int(owner[0]))
    assert owners == {0, 1}


def _noisy_points(src, dst, noise_px, seed):
    """points2d.csv with Gaussian noise (px per axis) on u and v: a detector's 2D."""
    lines = src.read_text().splitlines()
    rng = np.random.default_rng(seed)
    out = [lines[0]]
    for line in lines[1:]:
        f = line.split(',')
        f[3], f[4] = (repr(float(v) + rng.normal(0.0, noise_px)) for v in f[3:5])
        out.append(','.join(f))
    dst.write_text('\n'.join(out) + '\n')
    return dst


def test_triangulate_two_subjects_with_the_filter(tmp_path, capsys):
    """`monet triangulate --subjects 2 --filter kalman|optim` on a `monet synth --subjects 2`
    recording's instances with 1 px noise: one filter per identity; each identity keeps
    its subject and its rows, the filtered points are closer to its ground truth than the
    unfiltered run's, and every file (CSV with its subject column and the filter's
    columns, one TRC per subject, NWB) holds the filtered rows."""
    rec = tmp_path / 'rec'
    # 320 x 240: at 160 x 120 the association of noisy instances where the subjects hide
    # each other gives new identities (measured: 5 with 1 px noise), not the filter's matter
    assert monet(['synth', '--out', str(rec), '--cameras', '4', '--frames', '60', '--width',
                  '320', '--height', '240', '--subjects', '2', '--quiet', '--hfov', '80']) == 0
    X = np.load(rec / 'ground_truth.npz')['subjects_keypoints3d']
    points = _noisy_points(rec / 'points2d.csv', tmp_path / 'noisy.csv', 1.0, seed=3)
    tables = {}
    for method in ('none', 'kalman', 'optim'):
        out = tmp_path / method
        code = monet(['triangulate', str(points), '--rig', str(rec / 'rig.yaml'),
                      '--subjects', '2', '--fps', '30', '--skeleton', 'human14', '--quiet',
                      '--filter', method, '--out', str(out)])
        text = capsys.readouterr()
        assert code == 0, text.err
        if method != 'none':
            assert f'filter {method} per subject (2 identities' in text.out
        tables[method] = table = read_anipose_csv(out / 'keypoints3d.csv')
        assert sorted(np.unique(table['subject'])) == [0, 1]
    raw = tables['none']
    for method in ('kalman', 'optim'):
        table = tables[method]
        assert sorted(table['extra']) == ['bridged', 'change_mm']
        for i in (0, 1):
            mine, raw_mine = table['subject'] == i, raw['subject'] == i
            # the identity's frames: those of its unfiltered rows (no gap to bridge here)
            np.testing.assert_array_equal(table['fnum'][mine], raw['fnum'][raw_mine])
            err = np.linalg.norm(table['X'][mine][:, None] - X[table['fnum'][mine]], axis=-1)
            err = np.nanmean(err, axis=-1)                                # (frames, 2)
            owner = np.argmin(err, axis=1)
            assert (owner == owner[0]).all(), f'{method}: identity {i} changes subject'
            raw_err = np.linalg.norm(raw['X'][raw_mine] - X[raw['fnum'][raw_mine], owner[0]],
                                     axis=-1)
            filt_err = err[:, owner[0]]
            assert np.nanmean(filt_err) < 0.8 * np.nanmean(raw_err), \
                (method, i, np.nanmean(filt_err), np.nanmean(raw_err))
            trc = read_trc(tmp_path / method / f'keypoints3d_subject{i}.trc')
            np.testing.assert_allclose(trc['X'][table['fnum'][mine]], table['X'][mine],
                                       rtol=1e-12)
        from ndx_pose import MultiCameraPoseEstimation  # noqa: F401 (registers the types)
        from pynwb import NWBHDF5IO
        with NWBHDF5IO(str(tmp_path / method / 'keypoints.nwb'), 'r') as io:
            behavior = io.read().processing['behavior']
            for i in (0, 1):
                head = behavior[f'monet_pose_subject{i}'].pose_estimation_series['head']
                mine = table['subject'] == i
                np.testing.assert_allclose(np.asarray(head.data[:])[table['fnum'][mine]],
                                           table['X'][mine][:, 0], rtol=1e-12)
                assert f'filter_change_mm_subject{i}' in behavior.data_interfaces
