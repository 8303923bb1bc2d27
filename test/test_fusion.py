"""Fusion core: heatmaps of cropped virtual cameras -> 3D keypoints, against known points."""
import cv2
from helpers.scenes import cv2_project, gaussian_heatmaps, ring_rig, subject_box, to_crop
import numpy as np
import pytest

from monet_ros.fusion import FusionConfig, fuse_heatmaps, fuse_points, heat_to_source

GRID = (48, 64)  # heatmap (w, h)


def scene(rng, count=4, keypoints=14):
    rig = ring_rig(count)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(keypoints, 3))
    return rig, X


def render(rig, X, wrong=(), noise=0.0, rng=None, peaks=None):
    """Heatmaps (V, C, h, w), K_heat (V, 3, 3) and the Gaussian centres in source pixels."""
    heat, K_heat, centres = [], [], []
    for v, cam in enumerate(rig):
        uv = cv2_project(cam, X)
        box = subject_box(uv, cam.width, cam.height, GRID[0] / GRID[1])
        p = to_crop(uv, box, GRID)
        if v in wrong:  # a confidently wrong view: 12 heatmap px toward the centre
            p = p + np.where(p < np.array(GRID) / 2, 12.0, -12.0)
        if noise:
            p = p + rng.normal(0, noise, p.shape)
        x0, y0, x1, y1 = box
        scale = np.array([GRID[0] / (x1 - x0), GRID[1] / (y1 - y0)])
        centres.append((p + 0.5) / scale - 0.5 + np.array([x0, y0]))
        heat.append(gaussian_heatmaps(p, GRID[::-1], sigma=1.5,
                                      peak=1.0 if peaks is None else peaks[v]))
        K_heat.append(cam.crop(box, GRID).K)
    return np.stack(heat), np.stack(K_heat), np.stack(centres)


def test_exact_heatmaps_give_the_points_and_exclude_the_wrong_view():
    rng = np.random.default_rng(0)
    rig, X = scene(rng)
    heat, K_heat, _ = render(rig, X, wrong=(2,), peaks=[0.9, 0.8, 0.95, 0.7])
    result = fuse_heatmaps(heat, K_heat, rig, FusionConfig())
    assert np.abs(result.X - X).max() < 1e-4          # 0.1 mm on a 2 m rig
    assert result.inliers[2].sum() == 0 and result.inliers[[0, 1, 3]].all()
    assert (result.num_views == 3).all()
    # confidence = mean over the inlier views of each map's maximum value
    expected = heat[[0, 1, 3]].max(axis=(2, 3)).mean(axis=0)
    np.testing.assert_allclose(result.confidence, expected, atol=1e-6)
    assert np.nanmax(result.reprojection_error) < 1e-3
    assert np.isnan(result.view_mean_errors()[2])


def test_reported_errors_equal_an_opencv_recomputation():
    rng = np.random.default_rng(1)
    rig, X = scene(rng)
    heat, K_heat, centres = render(rig, X, wrong=(0,), noise=0.3, rng=rng)
    result = fuse_heatmaps(heat, K_heat, rig, FusionConfig(threshold_px=15.0))
    good = [1, 2, 3]
    errors = np.stack([np.linalg.norm(cv2_project(rig[v], result.X) - centres[v], axis=1)
                       for v in good])
    np.testing.assert_allclose(result.reprojection_error, errors.mean(axis=0), atol=2e-3)
    np.testing.assert_allclose(result.view_mean_errors()[good], errors.mean(axis=1), atol=2e-3)
    assert errors.mean() > 0.5  # the noise is visible: the check compares real numbers


def test_confidence_threshold_and_min_views():
    rng = np.random.default_rng(2)
    rig, X = scene(rng, count=3)
    heat, K_heat, _ = render(rig, X, peaks=[1.0, 1.0, 0.05])
    result = fuse_heatmaps(heat, K_heat, rig, FusionConfig(confidence_threshold=0.1))
    assert (result.num_views == 2).all() and not result.inliers[2].any()
    result = fuse_heatmaps(heat, K_heat, rig, FusionConfig(confidence_threshold=0.1,
                                                           min_views=3))
    assert np.isnan(result.X).all() and (result.num_views == 0).all()


def test_points_with_different_grids_and_ransac():
    rng = np.random.default_rng(3)
    rig, X = scene(rng, count=5)
    uv = np.stack([cv2_project(cam, X) for cam in rig])
    uv[4] += 80.0
    result = fuse_points(uv, np.ones(uv.shape[:2]), rig, FusionConfig(method='ransac'))
    assert np.abs(result.X - X).max() < 1e-6 and not result.inliers[4].any()


def test_heat_camera_must_be_a_crop_of_the_source():
    rig = ring_rig(2)
    K_heat = np.stack([rig[0].crop((10, 20, 330, 260), (48, 64)).K, rig[1].K.copy()])
    S = heat_to_source(K_heat, np.stack([c.K for c in rig]))
    np.testing.assert_allclose(S[1], np.eye(3), atol=1e-12)
    rotated = K_heat.copy()
    rotated[1] = rig[1].K @ cv2.Rodrigues(np.array([0.0, 0.0, 0.1]))[0]
    rotated[1] /= rotated[1][2, 2]
    with pytest.raises(ValueError, match='view 1: heatmap K is not a crop/scale'):
        heat_to_source(rotated, np.stack([c.K for c in rig]))


def test_a_2x2_or_absurd_view_is_skipped_the_others_fused():
    """fuse_heatmaps: a view whose grid is smaller than 3x3, or whose camera_info K is
    absurd (1e300), is left out and named in skipped_views; the good views are fused to
    the same answer as without the bad view."""
    from monet_ros.fusion import fuse_heatmaps as fuse
    rig, X, heat, K_heat = _scene_for_skips()
    full = fuse(heat, K_heat, rig, FusionConfig())
    tiny = [h for h in heat]
    tiny[1] = np.full((heat.shape[1], 2, 2), 0.5, np.float32)
    got = fuse(tiny, K_heat, rig, FusionConfig())
    assert list(got.skipped_views) == [1] and '3x3' in got.skipped_views[1]
    keep = [0, 2, 3]
    ref = fuse(heat[keep], K_heat[keep], [rig[i] for i in keep], FusionConfig())
    np.testing.assert_allclose(got.X, ref.X, atol=1e-9)
    assert not got.inliers[1].any()
    absurd = K_heat.copy()
    absurd[2, 0, 0] = 1e300
    got = fuse(heat, absurd, rig, FusionConfig())
    assert list(got.skipped_views) == [2]
    assert np.isfinite(got.X).all() and np.isfinite(full.X).all()
    with pytest.raises(ValueError, match='view 0'):
        fuse([np.zeros((heat.shape[1], 2, 2))] * 4, K_heat, rig, FusionConfig())


def _scene_for_skips():
    rig, X = scene(np.random.default_rng(5))
    heat, K_heat, _ = render(rig, X, noise=0.2, rng=np.random.default_rng(6))
    return rig, X, heat.astype(np.float32), K_heat


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_a_view_with_a_non_finite_value_is_skipped_the_others_fused(bad):
    """One NaN / +inf / -inf anywhere in a view's heatmaps: that view is left out with its
    reason, the other views give the answer of fusing them alone."""
    rig, X, heat, K_heat = _scene_for_skips()
    views = list(heat)
    views[2] = heat[2].copy()
    views[2][5, 40, 3] = bad
    got = fuse_heatmaps(views, K_heat, rig, FusionConfig())
    assert got.skipped_views == {2: 'view 2: heatmaps hold non-finite values'}
    keep = [0, 1, 3]
    ref = fuse_heatmaps(heat[keep], K_heat[keep], [rig[i] for i in keep], FusionConfig())
    np.testing.assert_allclose(got.X, ref.X, atol=1e-9)
    np.testing.assert_array_equal(got.inliers[keep], ref.inliers)
    assert not got.inliers[2].any() and np.isnan(got.points2d[2]).all()
    assert np.abs(got.X - X).max() < 0.03  # noise of 0.2 heatmap px, 3 views


def render_swapped(rig, X, swapped_views, partner):
    """Two-peak heatmaps: in `swapped_views` every map's HIGHER peak (1.0) is at the
    partner joint and the true joint is the second (0.7); elsewhere the true joint is the
    only peak (0.9). -> heatmaps (V, C, h, w), K_heat (V, 3, 3)."""
    heat, K_heat = [], []
    for v, cam in enumerate(rig):
        uv = cv2_project(cam, X)
        box = subject_box(uv, cam.width, cam.height, GRID[0] / GRID[1])
        p = to_crop(uv, box, GRID)
        if v in swapped_views:
            maps = np.maximum(gaussian_heatmaps(p, GRID[::-1], 1.5, 0.7),
                              gaussian_heatmaps(p[partner], GRID[::-1], 1.5, 1.0))
        else:
            maps = gaussian_heatmaps(p, GRID[::-1], 1.5, 0.9)
        heat.append(maps)
        K_heat.append(cam.crop(box, GRID).K)
    return np.stack(heat), np.stack(K_heat)


def _spread_scene(rng):
    """4 cameras, 8 joints far apart (>= 0.25 m: each other's peaks are outliers), paired
    0-1, 2-3, ... as left / right partners."""
    rig = ring_rig(4)
    while True:
        X = rng.uniform([-0.4, -0.4, 0.5], [0.4, 0.4, 1.6], size=(8, 3))
        d = np.linalg.norm(X[:, None] - X[None], axis=-1) + np.eye(8)
        if d.min() > 0.25:
            return rig, X, np.arange(8) ^ 1


def test_top_k_uses_the_second_peak_where_the_first_is_the_other_joint():
    """Views 1 and 2 see every joint's partner as the higher peak (the two wrong views
    agree with each other): one peak per view can at best keep the 2 right views (or
    triangulates the partner); with 2 candidates per view the true joint is seen by all 4
    views, from the second peak of views 1 and 2, within 1 mm of the truth."""
    rig, X, partner = _spread_scene(np.random.default_rng(21))
    heat, K_heat = render_swapped(rig, X, (1, 2), partner)
    one = fuse_heatmaps(heat, K_heat, rig, FusionConfig(peaks_per_view=1))
    two = fuse_heatmaps(heat, K_heat, rig, FusionConfig(peaks_per_view=2))
    assert (one.num_views <= 2).all()
    np.testing.assert_array_equal(two.num_views, 4)
    assert np.abs(two.X - X).max() < 1e-3
    np.testing.assert_array_equal(two.peak_index[[1, 2]], 1)
    np.testing.assert_array_equal(two.peak_index[[0, 3]], 0)
    np.testing.assert_array_equal(one.peak_index, 0)
    # the confidences are of the peaks used: the 0.7 Gaussians in views 1, 2 (the value at
    # the peak pixel, a little under the sub-pixel maximum), 0.9 in views 0, 3
    assert (two.peak_confidence[[1, 2]] <= 0.7).all() and (two.peak_confidence[[1, 2]] > 0.6).all()
    assert (two.peak_confidence[[0, 3]] > 0.8).all()
    np.testing.assert_allclose(two.confidence, two.peak_confidence.mean(axis=0), rtol=1e-12)
    # one swapped view: one peak per view drops it (3 views), two candidates use it (4)
    heat, K_heat = render_swapped(rig, X, (2,), partner)
    one = fuse_heatmaps(heat, K_heat, rig, FusionConfig(peaks_per_view=1))
    two = fuse_heatmaps(heat, K_heat, rig, FusionConfig(peaks_per_view=2))
    np.testing.assert_array_equal(one.num_views, 3)
    np.testing.assert_array_equal(two.num_views, 4)
    assert np.abs(two.X - X).max() < 1e-3 and np.abs(one.X - X).max() < 1e-3


@pytest.mark.parametrize('method', ['exclusion', 'ransac'])
def test_one_peak_per_view_is_the_single_peak_fusion_exactly(method):
    """peaks_per_view=1 gives exactly the decode + robust triangulation of the best peaks
    (the fusion before candidates, composed here from its parts); and on single-peak maps
    2 candidates per view change nothing."""
    from monet_ros.geometry import triangulate_robust
    from monet_ros.models import decode_heatmap_views
    rig, X, partner = _spread_scene(np.random.default_rng(22))
    for heat, K_heat in (render_swapped(rig, X, (1, 2), partner),
                         render(rig, X, wrong=(0,), noise=0.4,
                                rng=np.random.default_rng(3))[:2]):
        config = FusionConfig(peaks_per_view=1, method=method)
        got = fuse_heatmaps(heat, K_heat, rig, config)
        peaks, conf, _ = decode_heatmap_views(list(heat))
        S = heat_to_source(K_heat, np.stack([c.K for c in rig]))
        uv = (peaks - S[:, None, :2, 2]) / np.diagonal(S, axis1=1, axis2=2)[:, None, :2]
        uv[conf < config.confidence_threshold] = np.nan
        X_ref, inliers_ref = triangulate_robust(
            uv, rig, weights=np.where(conf < config.confidence_threshold, 0.0, conf),
            threshold_px=config.threshold_px, method=method)
        np.testing.assert_array_equal(got.X, X_ref)
        np.testing.assert_array_equal(got.inliers, inliers_ref & np.isfinite(X_ref).all(1))
        np.testing.assert_array_equal(got.points2d, uv)
    single = render(rig, X, wrong=(0,), noise=0.4, rng=np.random.default_rng(3))[:2]
    for config in (FusionConfig(peaks_per_view=1, method=method),):
        a = fuse_heatmaps(*single, rig, config)
        b = fuse_heatmaps(*single, rig, FusionConfig(peaks_per_view=2, method=method))
        for name in ('X', 'inliers', 'confidence', 'reprojection_error', 'points2d'):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_fuse_points_takes_candidates_too():
    """fuse_points with (V, C, K, 2) candidates (another tool's top-K detections): the
    true point is found where the best candidate of two views is wrong."""
    rng = np.random.default_rng(23)
    rig, X = scene(rng, count=4)
    uv = np.stack([cv2_project(cam, X) for cam in rig])
    wrong = uv + np.array([90.0, -60.0])
    points = np.stack([uv, wrong], axis=2)                  # candidate 0 true, 1 wrong
    points[[0, 3]] = points[[0, 3]][:, :, ::-1]             # views 0, 3: the wrong one first
    conf = np.broadcast_to([0.9, 0.6], points.shape[:3])
    result = fuse_points(points, conf, rig, FusionConfig())
    np.testing.assert_array_equal(result.num_views, 4)
    assert np.abs(result.X - X).max() < 1e-6
    np.testing.assert_array_equal(result.peak_index[[0, 3]], 1)
    with pytest.raises(ValueError, match=r'\(V, C, K, 2\)'):
        fuse_points(points, conf[..., 0], rig)
