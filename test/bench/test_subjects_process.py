"""bench/subjects_process.py reads `monet process --subjects N`'s keypoints3d.csv back by
stamp and scores it against the ground truth (no detector, no training here)."""
import argparse
import csv
import importlib.util

import numpy as np

from monet_ros.io.export_tables import write_anipose_csv


def bench_module(repo_root):
    spec = importlib.util.spec_from_file_location(
        'bench_subjects_process', repo_root / 'bench' / 'subjects_process.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_csv_is_read_back_by_stamp_and_scored_per_subject(repo_root, tmp_path):
    bench = bench_module(repo_root)
    keypoints = ['a', 'b']
    T, C = 6, 2
    stamps = 1000 + 33_000_000 * np.arange(T, dtype=np.int64)
    truth = np.zeros((T, 2, C, 3))
    truth[:, 1, :, 0] = 2.0                        # subject 1 two metres from subject 0
    truth[:, :, 1, 2] = 0.5
    # rows (frame, identity, the ground-truth subject shown): identities 4 and 9, none of
    # subject 0 in frame 2, and the two identities swapped in frame 5
    written = [(t, 4, 0) for t in (0, 1, 3, 4)] + [(t, 9, 1) for t in range(5)]
    written += [(5, 9, 0), (5, 4, 1)]
    frame = np.array([w[0] for w in written])
    X = np.stack([truth[t, g] + ([0.01, 0.0, 0.0] if g == 0 else 0.0)
                  for t, _, g in written])
    path = tmp_path / 'keypoints3d.csv'
    write_anipose_csv(path, keypoints, stamps[frame], X, np.zeros((len(X), C)),
                      np.full((len(X), C), 3), np.ones((len(X), C)),
                      subject=np.array([w[1] for w in written]))
    pred, ids = bench.read_keypoints3d(path, keypoints, stamps)
    assert pred.shape == (T, 2, C, 3) and ids.shape == (T, 2)
    assert sorted(ids[2]) == [-1, 9] and sorted(ids[5]) == [4, 9]
    s = bench.identity_scores(truth, pred, ids, 0.3)
    assert s.switches == 2                          # both subjects change identity at frame 5
    np.testing.assert_array_equal(s.found, [5, 6])
    np.testing.assert_allclose(s.error, [0.01, 0.0], atol=1e-9)
    assert bench.closest_pass(truth) == 2.0 and bench.closest_pass(truth[:, :1]) is None


def detector_options(**changes):
    """The bench's parsed options for its detector (its defaults, then changes)."""
    options = dict(train_frames=300, label_fraction=0.05, train_seed=0, train_motion_seed=7,
                   train_subjects=1, train_steps=1500, threads=1, cameras=8, width=320,
                   height=240)
    return argparse.Namespace(**{**options, **changes})


RIG = ['--cameras', 8, '--width', 320, '--height', 240, '--distinct-sides', '--quiet']


def test_one_training_subject_keeps_the_cached_detectors_settings_and_name(repo_root):
    bench = bench_module(repo_root)
    _, _, settings, key = bench.detector_commands(detector_options(), RIG)
    # the stamp and folder written by the bench before --train-subjects existed
    assert settings == {
        'synth': ['synth', '--frames', '300', '--label-fraction', '0.05', '--seed', '0',
                  '--motion-seed', '7', '--cameras', '8', '--width', '320', '--height', '240',
                  '--distinct-sides', '--quiet'],
        'train': ['--input-size', '128', '--steps', '1500', '--threads', '1',
                  '--checkpoint-every', '1500', '--no-progress']}
    assert key == 'model-f300-c8-320x240-s0-m7-steps1500'


def test_two_training_subjects_label_both_in_a_recording_not_scored(repo_root, tmp_path):
    """--train-subjects 2: `monet synth` (tiny) labels both subjects, under their own cache
    name, and their motion is not that of the scored recording (seed 0, no motion seed)."""
    bench = bench_module(repo_root)
    rig = ['--cameras', 2, '--width', 64, '--height', 48, '--quiet']
    options = detector_options(train_subjects=2, train_frames=4, label_fraction=0.5,
                               cameras=2, width=64, height=48)
    synth, train, settings, key = bench.detector_commands(options, rig)
    assert key.endswith('-k2') and settings['train'] == bench.detector_commands(
        detector_options(train_frames=4, label_fraction=0.5, cameras=2, width=64, height=48),
        rig)[2]['train']
    bench.monet([synth[0], '--out', tmp_path / 'train', *synth[1:]])
    bench.monet(['synth', '--out', tmp_path / 'scored', '--frames', 4, '--seed', 0,
                 '--subjects', 2, *rig])
    with open(tmp_path / 'train' / 'labels.csv', newline='') as f:
        rows = list(csv.DictReader(f))
    assert {r['subject'] for r in rows} == {'0', '1'}
    _, _, trained = bench.ground_truth(tmp_path / 'train')
    _, _, scored = bench.ground_truth(tmp_path / 'scored')
    assert trained.shape == scored.shape == (4, 2, 14, 3)
    # no training subject stands where a scored subject does in any frame (mean keypoint
    # distance, m): the scored frames are not training frames
    gaps = np.linalg.norm(trained[:, :, None] - scored[:, None], axis=-1).mean(-1)
    assert gaps.min() > 0.1
