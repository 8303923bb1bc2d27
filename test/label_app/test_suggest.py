"""Suggested instants: one per cluster of pose / appearance, spread over time."""
import numpy as np

from monet_ros.label_app.suggest import kmeans_picks, suggest_from_predictions


def test_kmeans_picks_one_instant_per_cluster():
    rng = np.random.default_rng(0)
    centres = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    which = rng.integers(0, 3, 60)
    features = centres[which] + rng.normal(scale=0.3, size=(60, 2))
    picks = kmeans_picks(features, 3)
    assert len(picks) == 3
    assert sorted(which[picks].tolist()) == [0, 1, 2]     # brute-force truth: the clusters
    # each pick is the member nearest its cluster's mean
    for p in picks:
        members = np.flatnonzero(which == which[p])
        mean = features[members].mean(axis=0)
        d = np.linalg.norm(features[members] - mean, axis=1)
        assert np.linalg.norm(features[p] - mean) <= np.sort(d)[2] + 1e-9


def test_time_spreads_picks_of_a_static_scene():
    features = np.zeros((100, 4))                  # nothing moves: only time tells apart
    picks = kmeans_picks(features, 4, times=np.arange(100.0))
    assert len(picks) == 4
    gaps = np.diff([0, *picks, 99])
    assert gaps.max() < 50                         # spread over the recording


def test_suggest_from_predictions_uses_poses_and_skips_missing_joints():
    rng = np.random.default_rng(1)
    poses = {0: rng.normal(size=(5, 3)), 1: rng.normal(size=(5, 3)) + 5}
    predictions = {}
    for t in range(40):
        X = poses[t % 2] + rng.normal(scale=0.01, size=(5, 3))
        X[rng.integers(0, 5)] = np.nan                     # a joint not triangulated
        predictions[t] = {'X': X}
    picks = suggest_from_predictions(predictions, 2)
    assert len(picks) == 2
    assert {p % 2 for p in picks} == {0, 1}                # one of each pose
    assert suggest_from_predictions({}, 3) == []
