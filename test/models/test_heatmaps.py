"""Heatmap codec: Gaussian targets against a brute-force formula, sub-pixel decode round trip."""
import numpy as np
import pytest
import torch

from monet_ros.models import decode_heatmaps, labelled_mask, render_heatmaps


def brute_force_gaussian(u, v, size, sigma):
    h, w = size
    out = np.zeros(size)
    for row in range(h):
        for col in range(w):
            out[row, col] = np.exp(-((col - u) ** 2 + (row - v) ** 2) / (2 * sigma ** 2))
    return out


def test_render_matches_brute_force_and_masks_nan():
    points = np.array([[[10.3, 20.7], [np.nan, np.nan], [-1.5, 3.25], [5.0, np.nan]]])
    heat = render_heatmaps(points, (46, 40), sigma=1.5)
    assert isinstance(heat, np.ndarray) and heat.shape == (1, 4, 46, 40)
    assert heat.dtype == np.float64, 'float64 in, float64 out'
    assert render_heatmaps(points.astype(np.float32), (46, 40), 1.5).dtype == np.float32
    np.testing.assert_allclose(heat[0, 0], brute_force_gaussian(10.3, 20.7, (46, 40), 1.5),
                               atol=1e-6)
    np.testing.assert_allclose(heat[0, 2], brute_force_gaussian(-1.5, 3.25, (46, 40), 1.5),
                               atol=1e-6)
    assert not heat[0, 1].any() and not heat[0, 3].any(), 'unlabelled -> all-zero map'
    np.testing.assert_array_equal(labelled_mask(points), [[True, False, True, False]])


def test_render_torch_keeps_type_and_device():
    points = torch.tensor([[[3.0, 4.0]]], dtype=torch.float64)
    heat = render_heatmaps(points, (8, 8), sigma=1.0)
    assert isinstance(heat, torch.Tensor) and heat.dtype == torch.float64
    assert heat[0, 0, 4, 3] == 1.0
    with pytest.raises(ValueError, match='sigma'):
        render_heatmaps(points, (8, 8), sigma=0)
    with pytest.raises(ValueError, match=r'\(B, C, 2\)'):
        render_heatmaps(points[0], (8, 8), sigma=1)


@pytest.mark.parametrize('sigma', [1.0, 1.5, 2.0, 3.0])
def test_decode_round_trip_subpixel(sigma):
    rng = np.random.default_rng(int(sigma * 10))
    h, w = 46, 64
    # Many random sub-pixel points over the whole map, borders included.
    points = np.stack([rng.uniform(0, w - 1, (8, 64)), rng.uniform(0, h - 1, (8, 64))], -1)
    heat = render_heatmaps(torch.from_numpy(points), (h, w), sigma)
    peaks, confidence = decode_heatmaps(heat)
    error = np.abs(peaks.numpy() - points)
    assert error.max() < 0.1, f'worst sub-pixel error {error.max():.4f} px'
    # confidence = the maximum value of each map
    np.testing.assert_allclose(confidence.numpy(), heat.numpy().max(axis=(2, 3)), rtol=1e-6)
    # the plain argmax is much worse: sub-pixel refinement is doing the work
    flat = heat.reshape(8, 64, -1).argmax(-1).numpy()
    argmax = np.stack([flat % w, flat // w], -1)
    assert np.abs(argmax - points).mean() > 0.2


def test_decode_scaled_and_numpy():
    points = np.array([[[12.25, 7.8], [0.2, 45.6]]])
    heat = 0.37 * render_heatmaps(points, (46, 46), sigma=2.0)
    peaks, confidence = decode_heatmaps(heat)
    assert isinstance(peaks, np.ndarray) and peaks.shape == (1, 2, 2)
    np.testing.assert_allclose(peaks, points, atol=0.01)
    np.testing.assert_allclose(confidence, heat.max(axis=(2, 3)), rtol=1e-6)


def test_decode_picks_the_higher_of_two_peaks_and_handles_empty_maps():
    a = render_heatmaps(np.array([[[10.4, 10.0]]]), (32, 32), 1.5)
    b = render_heatmaps(np.array([[[25.0, 20.6]]]), (32, 32), 1.5)
    heat = np.concatenate([0.5 * a + 0.9 * b, np.zeros_like(a)], axis=1)
    peaks, confidence = decode_heatmaps(heat)
    np.testing.assert_allclose(peaks[0, 0], [25.0, 20.6], atol=0.05)
    assert confidence[0, 0] == pytest.approx(heat[0, 0].max())
    assert confidence[0, 1] == 0.0 and np.isfinite(peaks[0, 1]).all()


def _awkward_views(rng, dtype):
    """5 views of 3 channels 20x24: Gaussian peaks inside and on every border and corner,
    an empty map, a map of negative values, NaN, +inf and -inf views."""
    points = np.array([[[10.3, 7.6], [0.0, 0.0], [23.0, 19.0]],
                       [[0.2, 12.5], [23.0, 4.4], [11.0, 0.0]],
                       [[5.5, 19.0], [14.7, 9.1], [2.2, 3.3]],
                       [[12.0, 10.0], [0.0, 19.0], [23.0, 0.0]],
                       [[7.1, 8.8], [16.0, 2.0], [20.0, 18.5]]])
    heat = render_heatmaps(points, (20, 24), sigma=1.5).astype(dtype)
    heat += rng.uniform(0, 1e-3, heat.shape).astype(dtype)
    heat[0, 1] = 0                      # empty map: the plain argmax
    heat[2, 2] = -rng.uniform(1, 2, (20, 24))
    heat[1, 0, 3, 4] = np.nan
    heat[3, 2, 19, 23] = np.inf
    heat[4, 1, 0, 0] = -np.inf
    return heat


@pytest.mark.parametrize('dtype', [np.float32, np.float64])
def test_decode_views_equals_the_stacked_decode_exactly(dtype):
    """decode_heatmap_views of separate arrays (what the fusion node holds) gives exactly
    decode_heatmaps of their stack, flags the non-finite views, and decodes views of other
    grids as decode_heatmaps decodes each alone."""
    from monet_ros.models import decode_heatmap_views
    heat = _awkward_views(np.random.default_rng(7), dtype)
    with np.errstate(invalid='ignore'):
        peaks, confidence = decode_heatmaps(heat)
    got_peaks, got_confidence, finite = decode_heatmap_views(list(heat))
    assert got_peaks.dtype == peaks.dtype == dtype
    np.testing.assert_array_equal(got_peaks, peaks)
    np.testing.assert_array_equal(got_confidence, confidence)
    np.testing.assert_array_equal(finite, [True, False, True, False, False])
    np.testing.assert_array_equal(finite, np.isfinite(heat).all(axis=(1, 2, 3)))
    # views with different grids, one of them not contiguous: each as decoded alone
    views = [heat[0], np.ascontiguousarray(heat[2][:, 2:17, 3:]), heat[2][:, ::2, ::3]]
    got_peaks, got_confidence, finite = decode_heatmap_views(views)
    assert finite.all()
    for v, view in enumerate(views):
        alone_peaks, alone_confidence = decode_heatmaps(view[None])
        np.testing.assert_array_equal(got_peaks[v], alone_peaks[0])
        np.testing.assert_array_equal(got_confidence[v], alone_confidence[0])
    with pytest.raises(ValueError, match='view 1 must be'):
        decode_heatmap_views([heat[0], heat[1][:2]])
    # no channels: nothing to decode, as decode_heatmaps
    got_peaks, got_confidence, finite = decode_heatmap_views([heat[0][:0]] * 2)
    assert got_peaks.shape == (2, 0, 2) and got_confidence.shape == (2, 0) and finite.all()


def test_decode_finds_border_peaks_and_empty_maps_give_the_argmax():
    heat = _awkward_views(np.random.default_rng(8), np.float64)
    peaks, confidence = decode_heatmaps(heat[[0, 2]])
    truth = np.array([[[10.3, 7.6], [0.0, 0.0], [23.0, 19.0]],
                      [[5.5, 19.0], [14.7, 9.1], [2.2, 3.3]]])
    finite = np.array([[True, False, True], [True, True, False]])  # empty / negative maps
    np.testing.assert_allclose(peaks[finite], truth[finite], atol=0.02)
    assert confidence[0, 1] <= 1e-3 and confidence[1, 2] < 0
    flat = heat[[0, 2]].reshape(2, 3, -1).argmax(-1)
    np.testing.assert_array_equal(peaks[0, 1], [flat[0, 1] % 24, flat[0, 1] // 24])
    np.testing.assert_array_equal(peaks[1, 2], [flat[1, 2] % 24, flat[1, 2] // 24])


def _brute_force_maxima(m, floor):
    """Local maxima of one map (>= their 8 neighbours, the border replicated), >= floor and
    > 0, as (value, flat index) highest first (ties: lowest index), written with loops."""
    h, w = m.shape
    found = []
    for row in range(h):
        for col in range(w):
            window = [m[min(max(row + dr, 0), h - 1), min(max(col + dc, 0), w - 1)]
                      for dr in (-1, 0, 1) for dc in (-1, 0, 1)]
            if m[row, col] >= max(window) and m[row, col] >= floor and m[row, col] > 0:
                found.append((-m[row, col], row * w + col))
    return [(-v, i) for v, i in sorted(found)]


@pytest.mark.parametrize('dtype', [np.float32, np.float64])
def test_decode_peaks_first_is_decode_views_the_rest_local_maxima(dtype):
    """decode_heatmap_peaks: candidate 0 is exactly decode_heatmap_views' peak (any floor);
    the next ones are the other local maxima above the floor, highest first, refined to
    the sub-pixel Gaussian centres; fewer maxima give NaN / 0."""
    from monet_ros.models import decode_heatmap_peaks, decode_heatmap_views
    rng = np.random.default_rng(11)
    heat = _awkward_views(rng, dtype)
    with np.errstate(invalid='ignore'):
        peaks, confidence, finite = decode_heatmap_peaks(list(heat), 3, floor=0.2)
        ref_peaks, ref_confidence, ref_finite = decode_heatmap_views(list(heat))
    np.testing.assert_array_equal(peaks[:, :, 0], ref_peaks)
    np.testing.assert_array_equal(confidence[:, :, 0], ref_confidence)
    np.testing.assert_array_equal(finite, ref_finite)
    # two Gaussians of heights 0.9 and 0.5 (and 0.15, under the floor)
    points = np.array([[[25.0, 20.6], [10.4, 10.0], [3.3, 27.0]]])
    g = render_heatmaps(points, (32, 32), 1.5).astype(dtype)[0]
    two = np.maximum(np.maximum(0.9 * g[0], 0.5 * g[1]), 0.15 * g[2])
    views = [np.stack([two, g[1], np.zeros_like(two)])]
    peaks, confidence, _ = decode_heatmap_peaks(views, 3, floor=0.2)
    np.testing.assert_allclose(peaks[0, 0, :2], points[0, :2], atol=0.05)
    # (the confidence is the map's value at the peak pixel, as decode_heatmaps')
    np.testing.assert_array_equal(confidence[0, 0, :2], [two.max(), two[10, 10]])
    assert np.isnan(peaks[0, 0, 2]).all() and confidence[0, 0, 2] == 0   # 0.15 < floor
    assert np.isnan(peaks[0, 1:, 1:]).all() and (confidence[0, 1:, 1:] == 0).all()
    # floor 0: the third Gaussian is found too; channels: only those maps
    peaks, confidence, _ = decode_heatmap_peaks(views, 3, floor=0.0, channels=[0])
    assert peaks.shape == (1, 1, 3, 2)
    np.testing.assert_allclose(peaks[0, 0], points[0], atol=0.05)
    # the candidates are the brute-force local maxima of random maps
    maps = (rng.random((4, 9, 11)) ** 3).astype(dtype)
    peaks, confidence, _ = decode_heatmap_peaks([maps], 4, floor=0.3)
    for c, m in enumerate(maps):
        expected = [v for v, i in _brute_force_maxima(m, 0.3) if i != m.argmax()][:3]
        got = confidence[0, c, 1:]
        np.testing.assert_array_equal(got[:len(expected)], np.array(expected, dtype))
        assert (got[len(expected):] == 0).all()
    with pytest.raises(ValueError, match='k must be an integer >= 1'):
        decode_heatmap_peaks([maps], 0)
