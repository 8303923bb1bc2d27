"""`monet synth --subjects 2 --label-subjects`: labels.csv labels every subject at the
labelled instants (its subject column = the slot of ground_truth.npz), exactly the
ground-truth projections inside the images, by the rule of subject 0's labels; without the
flag labels.csv is subject 0's, as before; --label-subjects alone (one subject) changes
nothing."""
import numpy as np

from monet_ros.cli import main as monet
from monet_ros.labels import read_labels
from monet_ros.learning.recording import load_recording

ARGS = ['--frames', '20', '--cameras', '3', '--width', '160', '--height', '120',
        '--label-fraction', '0.2', '--quiet']


def test_every_subject_is_labelled_at_the_labelled_instants(tmp_path):
    out = tmp_path / 'two'
    assert monet(['synth', '--out', str(out), '--subjects', '2', '--label-subjects',
                  *ARGS]) == 0
    gt = np.load(out / 'ground_truth.npz')
    labels = read_labels(out / 'labels.csv')
    assert labels.subjects == [0, 1]
    labelled = np.flatnonzero(gt['labelled'])
    assert labels.stamps == gt['stamps'][labelled].tolist()
    keypoints = list(gt['keypoint_names'])
    order = [labels.keypoints.index(k) for k in keypoints]
    cameras = list(gt['camera_names'])
    for t in labelled:
        for s in (0, 1):
            got = labels.points(gt['stamps'][t], cameras, s)[:, order]       # (V, C, 2)
            uv = gt['subjects_keypoints2d'][t, :, s]
            inside = gt['subjects_in_image'][t, :, s]
            np.testing.assert_array_equal(got[inside], uv[inside])
            assert np.isnan(got[~inside]).all()
    # subject 0's rows are what the file held before the flag
    plain = tmp_path / 'plain'
    assert monet(['synth', '--out', str(plain), '--subjects', '2', *ARGS]) == 0
    assert read_labels(plain / 'labels.csv').subjects == [0]
    zero = [r[:5] for r in labels.subject_rows() if r[5] == 0]
    assert zero == list(read_labels(plain / 'labels.csv').rows())
    rec = load_recording(out, max_instants=None)
    assert rec.num_subjects == 2 and len(rec.other_instants) == len(labelled)
    one = tmp_path / 'one'
    assert monet(['synth', '--out', str(one), '--label-subjects', *ARGS]) == 0
    assert (one / 'labels.csv').read_text().splitlines()[0] == 'stamp_ns,camera,keypoint,u,v'
