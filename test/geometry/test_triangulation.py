"""Triangulation vs OpenCV and brute-force references on random rigs."""
from itertools import combinations

import cv2
from helpers.rigs import random_points, random_rig
import numpy as np
import pytest

from monet_ros.geometry import (
    project_views,
    reprojection_error,
    triangulate,
    triangulate_robust,
)


def _observe(cams, X):
    return np.stack([c.project(X) for c in cams])


def _loop_dlt(points2d, cams, weights, per_metre=1.0):
    """Reference: per-keypoint weighted DLT with explicit loops (as Pose2Sim writes it), one
    SVD per keypoint, solved in metres (per_metre: the rig's unit per metre)."""
    V, N, _ = points2d.shape
    out = np.full((N, 3), np.nan)
    for n in range(N):
        rows = []
        for v in range(V):
            uv = cams[v].undistort_points(points2d[v, n][None])[0]
            if np.all(np.isfinite(uv)) and weights[v, n] > 0:
                P = cams[v].P / [1, 1, 1, per_metre]
                rows += [(P[0] - uv[0] * P[2]) * weights[v, n],
                         (P[1] - uv[1] * P[2]) * weights[v, n]]
        if len(rows) >= 4:
            h = np.linalg.svd(np.array(rows))[2][-1]
            out[n] = h[:3] / h[3] * per_metre
    return out


def test_project_views_matches_camera_project():
    rng = np.random.default_rng(0)
    cams = random_rig(rng, 5, dist_len=8)
    X = random_points(rng, 30)
    np.testing.assert_allclose(project_views(cams, X), _observe(cams, X), atol=1e-9)
    Xb = random_points(rng, 60).reshape(2, 30, 3)
    out = project_views(cams, Xb)
    assert out.shape == (2, 5, 30, 2)
    np.testing.assert_allclose(out[1], _observe(cams, Xb[1]), atol=1e-9)


def test_two_view_matches_cv2_triangulate_points():
    rng = np.random.default_rng(1)
    cams = random_rig(rng, 2)
    X = random_points(rng, 100)
    obs = _observe(cams, X) + rng.normal(scale=1.0, size=(2, 100, 2))
    ours = triangulate(obs, cams)
    und = [cv2.undistortPoints(obs[v][:, None], c.K, c.dist, P=c.K,
                               criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
                                         100, 1e-15))[:, 0] for v, c in enumerate(cams)]
    Xh = cv2.triangulatePoints(cams[0].P, cams[1].P, und[0].T, und[1].T)
    ref = (Xh[:3] / Xh[3]).T
    np.testing.assert_allclose(ours, ref, atol=1e-6)


def test_exact_recovery_with_distortion_and_missing_views():
    rng = np.random.default_rng(2)
    cams = random_rig(rng, 6, dist_len=5)
    X = random_points(rng, 200)
    obs = _observe(cams, X)
    obs[rng.random((6, 200)) < 0.3] = np.nan
    obs[:, 0] = np.nan
    obs[1:, 1] = np.nan  # one view only
    obs[2:, 2] = np.nan  # exactly two views
    obs[:2, 2] = _observe(cams[:2], X[2:3])[:, 0]
    out = triangulate(obs, cams)
    n_views = np.isfinite(obs[..., 0]).sum(0)
    assert np.all(np.isnan(out[n_views < 2]))
    np.testing.assert_allclose(out[n_views >= 2], X[n_views >= 2], atol=1e-8)
    assert n_views[2] == 2 and np.all(np.isfinite(out[2]))


def test_weighted_batched_equals_per_keypoint_loop():
    rng = np.random.default_rng(3)
    cams = random_rig(rng, 5, dist_len=5)
    X = random_points(rng, 40)
    obs = _observe(cams, X) + rng.normal(scale=2.0, size=(5, 40, 2))
    weights = rng.uniform(0.0, 1.0, size=(5, 40))
    weights[weights < 0.2] = 0.0
    weights[0, :3] = np.nan
    ref = _loop_dlt(obs, cams, np.nan_to_num(weights))
    out = triangulate(obs, cams, weights)
    np.testing.assert_allclose(out, ref, atol=1e-9, equal_nan=True)
    # weights matter: the unweighted solution differs on noisy data
    assert np.nanmax(np.abs(triangulate(obs, cams) - out)) > 1e-4


def test_reprojection_error_vs_cv2():
    rng = np.random.default_rng(4)
    cams = random_rig(rng, 3)
    X = random_points(rng, 20)
    obs = _observe(cams, X) + rng.normal(size=(3, 20, 2))
    obs[1, 5] = np.nan
    X[7] = np.nan
    err = reprojection_error(X, obs, cams)
    for v, c in enumerate(cams):
        proj = cv2.projectPoints(np.nan_to_num(X), cv2.Rodrigues(c.R)[0], c.t, c.K,
                                 c.dist)[0][:, 0]
        ref = np.linalg.norm(proj - obs[v], axis=1)
        ok = np.isfinite(err[v])
        np.testing.assert_allclose(err[v][ok], ref[ok], atol=1e-7)
    assert np.isnan(err[1, 5]) and np.all(np.isnan(err[:, 7]))
    assert np.isfinite(err).sum() == 3 * 20 - 1 - 3


def _pose2sim_reference(obs, cams, weights, threshold, min_views):
    """Per-keypoint transcription of Pose2Sim's triangulation_from_best_cameras."""
    V, N, _ = obs.shape
    out = np.full((N, 3), np.nan)
    for n in range(N):
        avail = [v for v in range(V) if weights[v, n] > 0 and np.isfinite(obs[v, n, 0])]
        for k in range(V - min_views + 1):
            if V - len(avail) + k > V - min_views:
                break
            best = (np.inf, None)
            for off in combinations(range(V), k):
                use = [v for v in avail if v not in off]
                if len(use) < 2:
                    continue
                Xn = _loop_dlt(obs[use][:, n:n + 1], [cams[v] for v in use],
                               weights[use][:, n:n + 1])[0]
                e = np.mean([np.linalg.norm(cams[v].project(Xn[None])[0] - obs[v, n])
                             for v in use])
                if e < best[0]:
                    best = (e, Xn)
            if best[0] <= threshold:
                out[n] = best[1]
                break
    return out


def _outlier_data(rng, V, N, noise=0.5, rate=0.15, offset=50.0):
    cams = random_rig(rng, V, dist_len=5)
    X = random_points(rng, N)
    obs = _observe(cams, X) + rng.normal(scale=noise, size=(V, N, 2))
    bad = rng.random((V, N)) < rate
    obs[bad] += offset
    return cams, X, obs, bad


def test_exclusion_matches_pose2sim_rule():
    rng = np.random.default_rng(5)
    cams, X, obs, bad = _outlier_data(rng, 5, 60, rate=0.25, offset=40.0)
    weights = rng.uniform(0.3, 1.0, size=(5, 60))
    weights[rng.random((5, 60)) < 0.1] = 0.0
    ref = _pose2sim_reference(obs, cams, weights, threshold=4.0, min_views=2)
    out, inl = triangulate_robust(obs, cams, weights, threshold_px=4.0, min_views=2)
    np.testing.assert_allclose(out, ref, atol=1e-9, equal_nan=True)
    assert np.isnan(out).any(axis=1).sum() < 60 and np.isfinite(out).all(axis=1).sum() > 40
    # the accepted subsets have a mean reprojection error within the threshold
    err = reprojection_error(out, obs, cams)
    ok = np.isfinite(out[:, 0])
    mean = np.nanmean(np.where(inl, err, np.nan), axis=0)
    assert np.all(mean[ok] <= 4.0)
    assert not inl[:, ~ok].any()


@pytest.mark.parametrize('method', ['exclusion', 'ransac'])
@pytest.mark.parametrize('V', [8, 35])
def test_robust_rejects_gross_outliers(method, V):
    rng = np.random.default_rng(V)
    cams, X, obs, bad = _outlier_data(rng, V, 14, rate=0.1)
    plain = triangulate(obs, cams)
    out, inl = triangulate_robust(obs, cams, threshold_px=2.0, min_views=2, method=method)
    err_plain = np.linalg.norm(plain - X, axis=1)
    err = np.linalg.norm(out - X, axis=1)
    assert np.all(np.isfinite(err))
    assert np.median(err) < 0.5 * np.median(err_plain)
    # every gross outlier is flagged, and few good views are lost
    assert not np.any(inl & bad)
    assert (inl | bad).mean() > 0.95


@pytest.mark.parametrize('method', ['exclusion', 'ransac'])
def test_robust_view_errors_are_the_inliers_reprojection_errors(method):
    """errors=True: the inlier views' errors, equal to cv2.projectPoints of the answer
    against the observations; NaN at outliers, missing views and untriangulated points."""
    rng = np.random.default_rng(21)
    cams, X, obs, bad = _outlier_data(rng, 8, 14, rate=0.15)
    obs[3, 2] = np.nan
    obs[2:, 5] = np.nan  # 2 views left: fewer than min_views
    out, inl, errors = triangulate_robust(obs, cams, threshold_px=2.0, min_views=3,
                                          method=method, errors=True)
    same, same_inl = triangulate_robust(obs, cams, threshold_px=2.0, min_views=3,
                                        method=method)
    np.testing.assert_array_equal(out, same)
    np.testing.assert_array_equal(inl, same_inl)
    assert inl.sum() > 80 and np.isnan(out[5]).all() and not inl[3, 2]
    np.testing.assert_array_equal(np.isnan(errors), ~inl)
    for v, cam in enumerate(cams):
        kept = np.flatnonzero(inl[v])
        ref = cv2.projectPoints(out[kept], cv2.Rodrigues(cam.R)[0], cam.t, cam.K, cam.dist)[0]
        np.testing.assert_allclose(errors[v, kept],
                                   np.linalg.norm(ref[:, 0] - obs[v, kept], axis=1), atol=1e-6)
    # nothing to triangulate (one view per keypoint): NaN points, no inliers, no errors
    obs[1:] = np.nan
    out, inl, errors = triangulate_robust(obs, cams, method=method, errors=True)
    assert np.isnan(out).all() and inl.shape == (8, 14) and not inl.any()
    assert errors.shape == (8, 14) and np.isnan(errors).all()


def test_robust_min_views_and_nan():
    rng = np.random.default_rng(9)
    cams, X, obs, bad = _outlier_data(rng, 4, 10, rate=0.0)
    obs[2:, 0] = np.nan  # 2 views left for keypoint 0
    obs[1:, 1] = np.nan  # 1 view
    for method in ('exclusion', 'ransac'):
        out, inl = triangulate_robust(obs, cams, min_views=3, method=method)
        assert np.all(np.isnan(out[:2])) and not inl[:, :2].any()
        np.testing.assert_allclose(out[2:], X[2:], atol=5e-3)
    with pytest.raises(ValueError, match='method'):
        triangulate_robust(obs, cams, method='magic')
    with pytest.raises(ValueError, match='points2d'):
        triangulate(obs[:3], cams)


def test_points_the_distortion_cannot_invert_count_as_missing():
    rng = np.random.default_rng(12)
    cams = random_rig(rng, 3, dist_len=5)
    cams[0] = cams[0].replace(dist=np.array([5.0, 50.0, 0.0, 0.0, 500.0]))
    X = random_points(rng, 5)
    obs = _observe(cams, X)
    obs[0] = [[1e9, -1e9]] * 5  # far outside: the inversion diverges
    out = triangulate(obs, cams)
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out, triangulate(obs[1:], cams[1:]), atol=1e-9)


def test_robust_with_the_callers_undistorted_points_is_the_same():
    """triangulate_robust(ideal=undistort_views(...)) (subjects.association's call) gives
    what it gives when it undistorts itself."""
    from monet_ros.geometry import undistort_views
    rng = np.random.default_rng(5)
    cams = random_rig(rng, 4)
    obs = _observe(cams, random_points(rng, 20)) + rng.normal(scale=0.5, size=(4, 20, 2))
    obs[1, 3] = np.nan
    a = triangulate_robust(obs, cams, errors=True)
    b = triangulate_robust(obs, cams, errors=True, ideal=undistort_views(cams, obs))
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    with pytest.raises(ValueError, match='ideal must have the shape'):
        triangulate_robust(obs, cams, ideal=obs[:, :3])


def test_exclusion_breaks_an_exact_tie_by_subset_order_not_by_rounding():
    """Three cameras with their centres in one plane and each view's peak in that plane: any
    two rays meet (zero residual), all three do not. The three view pairs tie exactly; the
    one kept is the first in subset order (view 0 left out: views 1 and 2) whatever the
    last bits of the input, so every CPU gives the same answer (the SVD's rounding, which
    differs between CPUs, chose before). The answer is OpenCV's point of that pair."""
    from helpers.scenes import look_at

    from monet_ros.geometry import Camera

    cams = []
    for i in range(3):
        angle = 2 * np.pi * i / 3
        R, t = look_at((3 * np.cos(angle), 3 * np.sin(angle), 1.0), (0.0, 0.0, 0.7))
        K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])
        cams.append(Camera(f'c{i}', K, np.zeros(5), R, t, 640, 480))
    # each view sees a different point of the plane z = 1 (the cameras' centres' plane)
    targets = np.array([[0.2, 0.1, 1.0], [-0.3, 0.0, 1.0], [0.1, -0.3, 1.0]])
    base = np.stack([cam.project(targets[v:v + 1])[0] for v, cam in enumerate(cams)])
    kept = set()
    rng = np.random.default_rng(3)
    for _ in range(40):
        obs = (base + rng.normal(0, 1e-9, base.shape))[:, None]          # (3, 1, 2)
        X, inl, err = triangulate_robust(obs, cams, threshold_px=5.0, errors=True)
        kept.add(tuple(inl[:, 0].tolist()))
        assert np.nanmax(err) < 1e-6
    assert kept == {(False, True, True)}
    Xh = cv2.triangulatePoints(cams[1].P, cams[2].P, base[1].reshape(2, 1),
                               base[2].reshape(2, 1))
    np.testing.assert_allclose(X[0], Xh[:3, 0] / Xh[3, 0], atol=1e-6)


@pytest.mark.parametrize('name', ['aniposelib_testdata/12cam-allen-mouse/calibration.toml',
                                  'pose2sim_demo_balancing/S00_Calibration/Calib_qualisys.toml'])
def test_dlt_eigen_solve_equals_the_svd_on_real_rigs(shared_data, name):
    """solve_dlt takes the smallest eigenvector of A^T A, which squares A's condition
    number: on real rigs (a 12-camera mm rig, a metre rig) its points equal the SVD's of
    the same weighted rows (_loop_dlt, per keypoint) within 1e-12 m, noisy 2D and weights."""
    from monet_ros.geometry import load_rig

    cams = load_rig(shared_data / name, units='mm' if 'allen' in name else 'm')
    per_metre = 1000.0 if 'allen' in name else 1.0
    rng = np.random.default_rng(5)
    centres = np.stack([-c.R.T @ c.t for c in cams])
    X = centres.mean(0) + rng.normal(size=(60, 3)) * 0.2 * centres.std()
    obs = np.stack([c.project(X) for c in cams]) + rng.normal(scale=2.0, size=(len(cams), 60, 2))
    weights = rng.uniform(0.2, 1.0, size=obs.shape[:2])
    ref = _loop_dlt(obs, cams, weights, per_metre)
    out = triangulate(obs, cams, weights)
    assert np.isfinite(ref).sum() > 100
    np.testing.assert_allclose(out / per_metre, ref / per_metre, atol=1e-12, equal_nan=True)
