"""PCK against hand-computed values: perfect predictions, known offsets, missing points."""
import numpy as np
import pytest

from monet_ros.evaluation import PCK_THRESHOLDS, normalised_distances, pck


def test_perfect_predictions_score_one_everywhere():
    rng = np.random.default_rng(0)
    gt = rng.uniform(0, 46, size=(7, 14, 2))
    result = pck(normalised_distances(gt, gt, 46.0))
    assert result.overall.shape == (20,)
    np.testing.assert_array_equal(result.overall, 1.0)
    np.testing.assert_array_equal(result.per_keypoint, 1.0)
    assert result.counts.tolist() == [7] * 14


def test_known_offset_gives_step_at_its_normalised_distance():
    # Offset (3, 4) heatmap px = 5 px; window 46 -> 5/46 = 0.1087: wrong at 0.10, right at 0.11.
    gt = np.zeros((4, 3, 2)) + 20.0
    pred = gt + np.array([3.0, 4.0])
    result = pck(normalised_distances(pred, gt, 46.0))
    expected = (PCK_THRESHOLDS >= 5.0 / 46.0).astype(float)
    np.testing.assert_array_equal(result.overall, expected)
    assert result.at(0.1) == 0.0 and result.at(0.11) == 1.0


def test_mixture_per_keypoint_and_missing_points():
    gt = np.zeros((4, 2, 2))
    pred = gt.copy()
    # keypoint 0: offsets 0, 2.3, 4.6, 9.2 px on a 46 window -> 0, .05, .1, .2
    pred[:, 0, 0] = [0.0, 2.3, 4.6, 9.2]
    # keypoint 1: two samples missing (NaN prediction), others exact
    pred[:2, 1] = np.nan
    result = pck(normalised_distances(pred, gt, 46.0), keypoints=('a', 'b'))
    np.testing.assert_allclose(result.per_keypoint[PCK_THRESHOLDS == 0.05][0], [0.5, 1.0])
    np.testing.assert_allclose(result.per_keypoint[PCK_THRESHOLDS == 0.1][0], [0.75, 1.0])
    assert result.counts.tolist() == [4, 2]
    # overall over the 6 evaluated pairs: at 0.01 -> 1 + 2 correct
    assert result.at(0.01) == pytest.approx(3 / 6)
    assert result.at(0.2) == pytest.approx(1.0)
    assert result.as_dict()['per_keypoint']['b'][0] == 1.0


def test_window_per_sample_and_bad_shapes():
    gt = np.zeros((2, 1, 2))
    pred = np.array([[[1.0, 0.0]], [[1.0, 0.0]]])
    d = normalised_distances(pred, gt, np.array([[10.0], [100.0]]))
    np.testing.assert_allclose(d, [[0.1], [0.01]])
    with pytest.raises(ValueError, match='must both be'):
        normalised_distances(pred, gt[:1], 46.0)
    with pytest.raises(ValueError, match='positive'):
        normalised_distances(pred, gt, 0.0)
