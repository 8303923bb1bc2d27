"""Gap bridging and bone-length estimation against brute-force references."""
import numpy as np

from monet_ros.temporal import bone_lengths, bridgeable, frames_for


def bridged_reference(observed, max_frames):
    """Per column, per run of missing frames: bridged when interior and short enough."""
    T, C = observed.shape
    out = np.zeros_like(observed)
    for c in range(C):
        t = 0
        while t < T:
            if observed[t, c]:
                t += 1
                continue
            end = t
            while end < T and not observed[end, c]:
                end += 1
            if t > 0 and end < T and end - t <= max_frames:
                out[t:end, c] = True
            t = end
    return out


def test_bridgeable_matches_a_run_by_run_reference():
    rng = np.random.default_rng(1)
    for _ in range(20):
        observed = rng.random((60, 5)) < rng.uniform(0.2, 0.9)
        for max_frames in (0, 1, 3, 10):
            np.testing.assert_array_equal(bridgeable(observed, max_frames),
                                          bridged_reference(observed, max_frames))


def test_frames_for_uses_the_median_period():
    stamps = np.round(np.arange(10) * 1e9 / 60).astype(np.int64)
    assert frames_for(0.25, stamps) == 15
    assert frames_for(0.25, stamps[:1]) == 0


def test_bone_lengths_are_medians_over_confident_frames():
    rng = np.random.default_rng(2)
    T = 50
    X = np.zeros((T, 3, 3))
    X[:, 1, 0] = 0.3 + rng.normal(0, 0.001, T)         # bone 0-1: 0.3 m
    X[:, 2, 1] = 0.5                                     # bone 0-2: 0.5 m
    X[:5, 1, 0] = 2.0                                    # 5 frames on the wrong limb
    X[7, 2] = np.nan
    confident = np.ones((T, 3), bool)
    confident[:5] = False
    lengths = bone_lengths(X, [(0, 1), (0, 2)], confident)
    expected = np.median(np.linalg.norm(X[5:, 1] - X[5:, 0], axis=-1))
    assert lengths[0] == expected
    assert lengths[1] == 0.5
    # too few confident frames: every finite frame counts
    few = np.zeros((T, 3), bool)
    few[:3] = True
    assert bone_lengths(X, [(0, 1)], few)[0] == np.median(np.linalg.norm(X[:, 1] - X[:, 0],
                                                                         axis=-1))
    assert np.isnan(bone_lengths(np.full((4, 2, 3), np.nan), [(0, 1)])[0])
