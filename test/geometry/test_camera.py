"""Camera projection/undistortion vs OpenCV, validation errors, crop virtual camera."""
import cv2
from helpers.rigs import random_camera, random_points
import numpy as np
import pytest

from monet_ros.geometry import (
    Camera,
    CameraError,
    crop_transform,
    load_rig,
    project_views,
    undistort_views,
)


@pytest.mark.parametrize('dist_len', [0, 4, 5, 8, 12])
def test_project_matches_cv2_project_points(dist_len):
    rng = np.random.default_rng(dist_len)
    for _ in range(5):
        cam = random_camera(rng, dist_len=dist_len)
        X = random_points(rng, 200)
        ours = cam.project(X)
        rvec = cv2.Rodrigues(cam.R)[0]
        ref = cv2.projectPoints(X, rvec, cam.t, cam.K, cam.dist if dist_len else None)[0]
        np.testing.assert_allclose(ours, ref[:, 0], atol=1e-7)


# the model's terms that are zero in every camera are skipped: each combination of them
WITHOUT_TERMS = {'radial only': [-0.08, 0.02, 0, 0, 0.003],
                 'rational, no tangential': [-0.2, 0.05, 0, 0, 0.01, 0.02, -0.01, 0.005],
                 'prism, no tangential': [-0.2, 0.05, 0, 0, 0.01, 0, 0, 0, 1e-3, -5e-4, 8e-4,
                                          2e-4],
                 'tangential only': [0, 0, 0.002, -0.001]}


@pytest.mark.parametrize('name', WITHOUT_TERMS)
def test_project_views_without_some_terms_matches_cv2(name):
    rng = np.random.default_rng(len(name))
    rig = [random_camera(rng, name=f'c{i}').replace(dist=np.array(WITHOUT_TERMS[name]))
           for i in range(3)]
    X = random_points(rng, 100)
    ours = project_views(rig, X)
    for v, cam in enumerate(rig):
        ref = cv2.projectPoints(X, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, cam.dist)[0]
        np.testing.assert_allclose(ours[v], ref[:, 0], atol=1e-7)
        np.testing.assert_allclose(cam.project(X), ref[:, 0], atol=1e-7)


def test_p_and_center():
    rng = np.random.default_rng(1)
    cam = random_camera(rng, distortion=False)
    X = random_points(rng, 50)
    Xh = np.hstack([X, np.ones((50, 1))]) @ cam.P.T
    np.testing.assert_allclose(Xh[:, :2] / Xh[:, 2:], cam.project(X), atol=1e-9)
    np.testing.assert_allclose(cam.R @ cam.center + cam.t, 0, atol=1e-12)
    assert cam.P.shape == (3, 4)


def test_skew_honoured_in_projection():
    rng = np.random.default_rng(2)
    cam = random_camera(rng, skew=3.5)
    X = random_points(rng, 100)
    Xc = X @ cam.R.T + cam.t
    # distorted normalised coordinates from OpenCV with an identity K, then our skewed K
    xy = cv2.projectPoints(X, cv2.Rodrigues(cam.R)[0], cam.t, np.eye(3), cam.dist)[0][:, 0]
    uv = (np.hstack([xy, np.ones((100, 1))]) @ cam.K.T)[:, :2]
    np.testing.assert_allclose(cam.project(X), uv, atol=1e-7)
    assert np.all(Xc[:, 2] > 0)


@pytest.mark.parametrize('dist_len, skew', [(5, 0.0), (8, 0.0), (12, 0.0), (5, 4.0)])
def test_undistort_inverts_project(dist_len, skew):
    rng = np.random.default_rng(3 + dist_len)
    cam = random_camera(rng, dist_len=dist_len, skew=skew)
    X = random_points(rng, 300)
    observed = cam.project(X)
    ideal = cam.without_distortion().project(X)
    np.testing.assert_allclose(cam.undistort_points(observed), ideal, atol=1e-9)
    if skew == 0.0:
        ref = cv2.undistortPoints(observed[:, None], cam.K, cam.dist, P=cam.K,
                                  criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
                                            100, 1e-15))[:, 0]
        np.testing.assert_allclose(cam.undistort_points(observed), ref, atol=1e-6)


def test_undistort_keeps_nan_rows():
    cam = random_camera(np.random.default_rng(4))
    uv = np.array([[600.0, 500.0], [np.nan, np.nan], [10.0, 20.0]])
    out = cam.undistort_points(uv)
    assert np.all(np.isnan(out[1])) and np.all(np.isfinite(out[[0, 2]]))
    wild = cam.replace(dist=np.array([5.0, 50.0, 0.0, 0.0, 500.0]))
    assert np.all(np.isnan(wild.undistort_points(np.array([[1e9, -1e9]]))))


def _pixel_grid(cam, step=16):
    """Every `step`-th pixel of the image, edges included: (M, 2)."""
    u, v = np.meshgrid(np.r_[np.arange(0, cam.width, step), cam.width - 1],
                       np.r_[np.arange(0, cam.height, step), cam.height - 1])
    return np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)


def _opencv_undistort(cam, uv, iterations=200):
    """cv2.undistortPoints iterated to convergence (its default stops after 5 steps)."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, 1e-16)
    return cv2.undistortPoints(uv[:, None], cam.K, cam.dist, P=cam.K, criteria=criteria)[:, 0]


def _distorted_rigs(shared_data):
    rng = np.random.default_rng(11)
    rigs = {f'random dist{n}': [random_camera(rng, name=f'c{i}', dist_len=n) for i in range(3)]
            for n in (4, 5, 8, 12)}
    strong = np.array([-0.35, 0.12, 0.001, -0.002, -0.02])  # wide-angle barrel
    rigs['strong barrel'] = [random_camera(rng).replace(dist=strong)]
    for name, dist in WITHOUT_TERMS.items():
        rigs[name] = [random_camera(rng, name=f'c{i}').replace(dist=np.array(dist))
                      for i in range(2)]
    rigs['pose2sim'] = load_rig(
        shared_data / 'pose2sim_demo_balancing/S00_Calibration/Calib_qualisys.toml')
    return rigs


def test_undistort_matches_opencv_inside_the_image(shared_data):
    """Every pixel (16-px grid) of distorted rigs, the real Pose2Sim calibration included:
    Camera.undistort_points and undistort_views (the batched fusion path) agree with
    OpenCV to 0.01 px (in fact to 1e-6) and are exact inverses of project."""
    rigs = _distorted_rigs(shared_data)
    assert any(np.any(c.dist) for c in rigs['pose2sim'])
    for name, rig in rigs.items():
        grids = [_pixel_grid(c) for c in rig]
        n = min(len(g) for g in grids)
        uv = np.stack([g[:n] for g in grids])
        batched = undistort_views(rig, uv)
        for v, cam in enumerate(rig):
            ours = cam.undistort_points(uv[v])
            ref = _opencv_undistort(cam, uv[v])
            assert np.all(np.isfinite(ours)), name
            error = np.abs(ours - ref).max()
            assert error <= 0.01 and error < 1e-6, f'{name} {cam.name}: {error} px'
            np.testing.assert_allclose(batched[v], ours, atol=1e-9)
            # back through the distortion model: the observed pixels again
            xy = cam.pixels_to_normalized(ours)
            back = cam.normalized_to_pixels(cam.distort_normalized(xy))
            np.testing.assert_allclose(back, uv[v], atol=1e-8, err_msg=name)


def test_undistort_views_mixed_rig_and_missing_points():
    rng = np.random.default_rng(12)
    rig = [random_camera(rng, name='a'), random_camera(rng, name='b', distortion=False),
           random_camera(rng, name='c', dist_len=12)]
    uv = rng.uniform([0, 0], [1280, 960], (3, 50, 2))
    uv[0, 3] = np.nan
    uv[2, 7, 1] = np.nan
    out = undistort_views(rig, uv)
    for v, cam in enumerate(rig):
        np.testing.assert_allclose(out[v], cam.undistort_points(uv[v]), atol=1e-9)
    np.testing.assert_allclose(out[1], uv[1], atol=1e-9)  # no distortion: unchanged
    assert np.isnan(out[0, 3]).all() and np.isnan(out[2, 7]).all()
    assert np.isfinite(np.delete(out[0], 3, axis=0)).all()
    with pytest.raises(ValueError, match='uv must have shape'):
        undistort_views(rig, uv[:2])


def test_undistort_past_the_fold_is_nan():
    """Barrel distortion folds over beyond some radius: there r(1 + k1 r^2) is no longer
    invertible, and a distorted point beyond the largest reachable radius has no inverse."""
    cam = random_camera(np.random.default_rng(13)).replace(dist=np.array([-0.5, 0, 0, 0]))
    # r_d = r (1 - 0.5 r^2) peaks at r = sqrt(2/3), r_d = 0.544
    xy = np.array([[0.5, 0.0], [0.6, 0.0], [0.0, -0.7]])
    out = cam.undistort_normalized(xy)
    assert np.isfinite(out[0]).all() and np.isnan(out[1:]).all()
    np.testing.assert_allclose(cam.distort_normalized(out[:1]), xy[:1], atol=1e-12)


@pytest.mark.parametrize('d', [(-0.5, 0.0, 0.0), (-0.3, 0.12, -0.02), (0.2, -0.05, 0.01)])
def test_radial_undistortion_is_the_2d_newton_solve(d):
    """A radial model (k1, k2, k3 only) is undistorted by a 1D Newton solve of the radius;
    inside the model's fold the general 2D solve (here run on the same model with its
    tangential branch on and p1 = p2 = 0) gives the same points; past the fold (distorted
    radii no ideal radius on the branch from the centre reaches, found by brute force on a
    fine grid) the radial solve is NaN, and the 2D solve's answers there, if any, lie on
    the opposite ray. A grid out to 1.5 in normalised coordinates."""
    from monet_ros.geometry.camera import _model_terms, _undistort_newton

    d12 = np.zeros(12)
    d12[[0, 1, 4]] = d
    g = np.linspace(-1.5, 1.5, 61)
    x0, y0 = (a.ravel() for a in np.meshgrid(g, g))
    x0[:2], y0[:2] = [np.nan, 0.0], [0.0, 0.0]         # a missing point and the centre
    coeffs, rational, prism, _ = _model_terms(d12)
    assert not rational and not prism
    x, y = _undistort_newton(d12, x0, y0, 20, 1e-15)
    x2, y2 = _undistort_newton(d12, x0, y0, 20, 1e-15, (coeffs, False, False, True))
    # brute force: the largest distorted radius of the branch from the centre
    r = np.linspace(0, 5, 500001)
    k1, k2, k3 = d
    rd = r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)
    fold = np.flatnonzero(np.diff(rd) <= 0)
    rd_max = rd[fold[0]] if len(fold) else np.inf
    r0 = np.hypot(x0, y0)
    inside = r0 < rd_max * (1 - 1e-6)
    assert np.isnan(x[0]) and x[1] == y[1] == 0.0
    assert np.isfinite(x[inside]).all() and np.isnan(x[r0 > rd_max]).all()
    np.testing.assert_allclose(x[inside], x2[inside], atol=1e-12)
    np.testing.assert_allclose(y[inside], y2[inside], atol=1e-12)
    beyond = (r0 > rd_max) & np.isfinite(x2)
    assert (x2[beyond] * x0[beyond] + y2[beyond] * y0[beyond] < 0).all()
    assert inside.mean() < 0.9 or not len(fold)


def _valid_kwargs():
    return dict(name='c', K=np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]]),
                dist=np.zeros(5), R=np.eye(3), t=np.zeros(3), width=640, height=480)


@pytest.mark.parametrize('field, value', [
    ('K', np.eye(2)),
    ('K', np.array([[-800.0, 0, 320], [0, 800, 240], [0, 0, 1]])),
    ('K', np.array([[800.0, 0, 320], [0, 800, 240], [0, 1, 1]])),
    ('dist', np.zeros(6)),
    ('R', np.diag([1.0, 1.0, -1.0])),
    ('R', np.ones((3, 3))),
    ('t', np.zeros(4)),
    ('t', np.array([0.0, np.nan, 0.0])),
    ('width', 0),
    ('height', 2.5),
    ('name', ''),
])
def test_invalid_fields_are_named(field, value):
    kwargs = _valid_kwargs()
    kwargs[field] = value
    with pytest.raises(CameraError) as info:
        Camera(**kwargs)
    assert info.value.field == field
    assert repr(field) in str(info.value)


def test_camera_is_frozen_and_arrays_read_only():
    cam = Camera(**_valid_kwargs())
    with pytest.raises(AttributeError):
        cam.width = 10
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0
    assert cam == Camera(**_valid_kwargs())
    assert cam != cam.replace(t=np.array([0.0, 0.0, 1.0]))


def test_crop_transform_formula():
    S = crop_transform((100, 50, 300, 250), (46, 46))
    uv = np.array([[100 - 0.5, 50 - 0.5], [300 - 0.5, 250 - 0.5], [150.25, 77.0]])
    out = (np.hstack([uv, np.ones((3, 1))]) @ S.T)[:, :2]
    # the box's edges map to the crop's edges (-0.5 and W_out - 0.5)
    np.testing.assert_allclose(out[0], [-0.5, -0.5])
    np.testing.assert_allclose(out[1], [45.5, 45.5])
    np.testing.assert_allclose(out[2], [(150.25 + 0.5 - 100) * 46 / 200 - 0.5,
                                        (77.0 + 0.5 - 50) * 46 / 200 - 0.5])
    full = crop_transform((0, 0, 640, 480), (640, 480))
    np.testing.assert_allclose(full, np.eye(3))
    with pytest.raises(ValueError):
        crop_transform((10, 10, 5, 20), (46, 46))


@pytest.mark.parametrize('box, out_size', [((37.0, 21.0, 237.0, 171.0), (92, 69)),
                                           ((-20.5, 10.25, 300.0, 230.0), (368, 368)),
                                           ((0, 0, 320, 240), (640, 480))])
def test_warp_affine_with_s_moves_points_as_s_says(box, out_size):
    """A linear ramp image f(u, v) warped with S[:2] must equal f(S^-1 (u', v')) at every
    interior crop pixel (bilinear interpolation is exact on a linear function; OpenCV uses
    1/32-pixel coordinate precision). A half-pixel convention error would be ~0.5 px."""
    h, w = 240, 320
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    fu = u.astype(np.float32)
    fv = v.astype(np.float32)
    S = crop_transform(box, out_size)
    wu = cv2.warpAffine(fu, S[:2], out_size, flags=cv2.INTER_LINEAR, borderValue=np.nan)
    wv = cv2.warpAffine(fv, S[:2], out_size, flags=cv2.INTER_LINEAR, borderValue=np.nan)
    vo, uo = np.mgrid[0:out_size[1], 0:out_size[0]].astype(np.float64)
    src = np.stack([uo.ravel(), vo.ravel(), np.ones(uo.size)])
    src = np.linalg.solve(S, src)
    inside = ((src[0] >= 0) & (src[0] <= w - 1) & (src[1] >= 0) & (src[1] <= h - 1))
    assert inside.sum() > 100
    err_u = np.abs(wu.ravel()[inside] - src[0][inside])
    err_v = np.abs(wv.ravel()[inside] - src[1][inside])
    assert err_u.max() < 1 / 16 and err_v.max() < 1 / 16


def test_crop_camera_projects_into_crop_pixels():
    rng = np.random.default_rng(5)
    cam = random_camera(rng)
    box, out_size = (400.0, 300.0, 900.0, 700.0), (46, 46)
    heat = cam.crop(box, out_size)
    S = crop_transform(box, out_size)
    X = random_points(rng, 100)
    full = cam.project(X)
    expected = (np.hstack([full, np.ones((100, 1))]) @ S.T)[:, :2]
    np.testing.assert_allclose(heat.project(X), expected, atol=1e-9)
    np.testing.assert_allclose(heat.K, S @ cam.K)
    assert (heat.width, heat.height) == out_size
    np.testing.assert_array_equal(heat.dist, cam.dist)
    np.testing.assert_array_equal(heat.R, cam.R)
    # undistortion in the crop camera equals undistort-then-crop
    np.testing.assert_allclose(
        heat.undistort_points(heat.project(X)),
        (np.hstack([cam.undistort_points(full), np.ones((100, 1))]) @ S.T)[:, :2], atol=1e-9)


@pytest.mark.parametrize('dist', [(-0.3, 0.1, 0.0, 0.0, -0.02), (-0.3, 0.1, 0.01, -0.005, 0.0)])
def test_a_loose_tolerance_gives_converged_points_not_nan(dist):
    """undistort_normalized(tol=...) stops each point within the caller's tolerance: with
    a loose tol the points are finite and within it of the tight solve (a radial model's
    1D solve, and the 2D solve of a model with tangential terms), the same alone or in a
    batch of other points (the iteration of one point does not depend on the others)."""
    cam = random_camera(np.random.default_rng(4)).replace(dist=np.array(dist))
    xy = np.random.default_rng(5).uniform(-0.5, 0.5, (400, 2))
    tight = cam.undistort_normalized(xy)
    assert np.isfinite(tight).all()
    for tol in (1e-3, 1e-6, 1e-9):
        loose = cam.undistort_normalized(xy, tol=tol)
        assert np.isfinite(loose).all(), tol
        np.testing.assert_allclose(loose, tight, atol=10 * tol)
    if not any(dist[2:4]):
        one = cam.undistort_normalized(xy[:1], tol=1e-3)
        np.testing.assert_array_equal(one, cam.undistort_normalized(xy, tol=1e-3)[:1])
