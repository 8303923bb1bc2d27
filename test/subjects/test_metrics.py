"""Identity metrics against hand-counted cases."""
import numpy as np

from monet_ros.subjects.metrics import identity_scores


def _two_walkers(T=10):
    """Two GT subjects 2 m apart, 3 keypoints each, (T, 2, 3, 3)."""
    base = np.zeros((T, 2, 3, 3))
    base[:, 1, :, 0] = 2.0
    base[:, :, :, 1] = np.arange(T)[:, None, None] * 0.1
    return base


def test_a_swap_halfway_is_two_switches_and_idf1_one_half():
    gt = _two_walkers()
    pred = gt.copy()
    ids = np.tile([7, 8], (10, 1))
    ids[5:] = [8, 7]                      # from frame 5 the identities are swapped
    s = identity_scores(gt, pred, ids, threshold=0.1)
    # each GT subject changes track once; the best global pairing covers 5 + 5 frames
    assert s.switches == 2 and s.idtp == 10 and s.gt == 20 and s.pred == 20
    assert s.idf1 == 0.5 and s.matched == 20
    np.testing.assert_allclose(s.error, 0.0)
    np.testing.assert_array_equal(s.found, [10, 10])
    np.testing.assert_array_equal(s.track[:, 0], [7] * 5 + [8] * 5)
    np.testing.assert_allclose(s.distance, 0.0)


def test_perfect_tracks_with_a_gap_and_a_stray_track():
    gt = _two_walkers()
    pred = np.concatenate([gt, np.full((10, 1, 3, 3), np.nan)], axis=1)
    ids = np.tile([0, 1, -1], (10, 1))
    pred[3, 1] = np.nan                   # subject 1 missed in frame 3
    ids[3, 1] = -1
    pred[6, 2] = 9.0                      # a stray track far from both in frame 6
    ids[6, 2] = 5
    pred[:, 0] += [0.0, 0.0, 0.05]        # 5 cm error on subject 0
    s = identity_scores(gt, pred, ids, threshold=0.1)
    assert s.switches == 0 and s.idtp == 19 and s.gt == 20 and s.pred == 20
    assert s.idf1 == 2 * 19 / 40
    np.testing.assert_allclose(s.error, [0.05, 0.0], atol=1e-12)
    np.testing.assert_array_equal(s.found, [10, 9])
    assert s.track[3, 1] == -1 and np.isnan(s.distance[3, 1])
    np.testing.assert_array_equal(s.track[:, 0], 0)
