"""bench/subjects_process.py reads `monet process --subjects N`'s keypoints3d.csv back by
stamp and scores it against the ground truth (no detector, no training here)."""
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
