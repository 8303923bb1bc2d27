"""`monet synth --subjects 2`: two subjects that pass and hide each other, with their
ground truth and their per-camera instances (shuffled labels), which `monet triangulate
--subjects 2` turns back into the two ground-truth subjects with one identity each."""
import numpy as np

from monet_ros.cli import main as monet
from monet_ros.geometry import load_rig
from monet_ros.io.export_tables import read_anipose_csv
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
