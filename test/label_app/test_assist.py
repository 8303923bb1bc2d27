"""Geometry assist of `monet label`: triangulation, ghosts, flags and epipolar curves,
checked against OpenCV and brute-force geometry on random distorted rigs."""
import cv2
from helpers.rigs import random_points, random_rig
import numpy as np

from monet_ros.label_app.assist import assist_instant, assist_to_json, epipolar_polyline


def test_two_clicks_give_ghosts_at_the_projection_everywhere():
    rng = np.random.default_rng(1)
    cams = random_rig(rng, 4, width=640, height=480)
    X = random_points(rng, 5)
    truth = np.stack([c.project(X) for c in cams])                 # (V, C, 2)
    clicks = np.full_like(truth, np.nan)
    clicks[:2] = truth[:2]
    clicks[2, 4] = truth[2, 4]                                      # keypoint 4: 3 views
    result = assist_instant(clicks, cams)
    np.testing.assert_allclose(result['X'], X, atol=1e-6)
    for j, cam in enumerate(cams):
        # OpenCV's projection of the true points (independent of Camera.project)
        ref, _ = cv2.projectPoints(X, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, cam.dist)
        np.testing.assert_allclose(result['projections'][j], ref[:, 0], atol=1e-4)
    assert np.isnan(result['errors'][2:, :4]).all()
    assert (result['errors'][:2] < 1e-4).all() and not result['flagged'].any()
    assert result['robust'].all()
    out = assist_to_json(result, [c.name for c in cams], list('abcde'))
    assert set(out) == set('abcde')
    assert out['a']['views']['cam3']['error'] is None
    np.testing.assert_allclose(out['a']['views']['cam3']['ghost'], truth[3, 0], atol=1e-6)


def test_a_disagreeing_click_is_flagged_and_one_click_is_not_triangulated():
    rng = np.random.default_rng(2)
    cams = random_rig(rng, 4, width=640, height=480)
    X = random_points(rng, 2)
    clicks = np.stack([c.project(X) for c in cams])
    clicks[3, 0] += (120.0, -80.0)                                  # a wrong click
    clicks[1:, 1] = np.nan                                          # keypoint 1: one view
    result = assist_instant(clicks, cams, threshold_px=15.0, flag_px=10.0)
    assert result['flagged'][:, 0].tolist() == [False, False, False, True]
    np.testing.assert_allclose(result['X'][0], X[0], atol=1e-6)     # the outlier left out
    assert result['errors'][3, 0] > 100.0
    assert np.isnan(result['X'][1]).all() and np.isnan(result['projections'][:, 1]).all()
    # two views that disagree: no robust solution, the DLT still gives ghosts, both flagged
    two = np.full_like(clicks, np.nan)
    two[:2, 0] = clicks[:2, 0]
    line = np.array(epipolar_polyline(cams[0], two[0, 0], cams[1])[0])
    k = np.argmin(np.linalg.norm(line - two[1, 0], axis=1))
    direction = line[min(k + 1, len(line) - 1)] - line[max(k - 1, 0)]
    two[1, 0] += 60.0 * np.array([-direction[1], direction[0]]) / np.linalg.norm(direction)
    result = assist_instant(two, cams, threshold_px=15.0, flag_px=10.0)
    assert not result['robust'][0] and np.isfinite(result['X'][0]).all()
    assert result['flagged'][:2, 0].all()


def _distance_to_polyline(point, line):
    a, b = np.array(line[:-1]), np.array(line[1:])
    ab = b - a
    s = np.clip(((point - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
    return np.linalg.norm(a + s[:, None] * ab - point, axis=1).min()


def test_epipolar_curve_passes_through_the_projection_with_distortion():
    rng = np.random.default_rng(3)
    cams = random_rig(rng, 2, width=1280, height=960)
    cams = [c.replace(dist=np.array([-0.4, 0.15, 0.0, 0.0, 0.0])) for c in cams]   # strong
    X = random_points(rng, 8, scale=1.0)
    # the straight epipolar line of a pinhole model (F from the relative pose, by hand)
    R = cams[1].R @ cams[0].R.T
    t = cams[1].t - R @ cams[0].t
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    F = np.linalg.inv(cams[1].K).T @ tx @ R @ np.linalg.inv(cams[0].K)
    straight = []
    for x in X:
        uv_src = cams[0].project(x[None])[0]
        lines = epipolar_polyline(cams[0], uv_src, cams[1])
        assert lines
        target = cams[1].project(x[None])[0]
        assert min(_distance_to_polyline(target, line) for line in lines) < 0.5
        a, b, c = F @ np.array([*uv_src, 1.0])
        straight.append(abs(a * target[0] + b * target[1] + c) / np.hypot(a, b))
    # a straight line through the distorted pixels misses by pixels: the curve is needed
    assert max(straight) > 3.0


def test_epipolar_curve_is_empty_when_the_ray_is_behind_the_target():
    rng = np.random.default_rng(4)
    cam = random_rig(rng, 1, width=640, height=480)[0]
    # a camera beside the source looking the other way: the ray is behind it
    R = np.diag([-1.0, 1.0, -1.0]) @ cam.R
    center = cam.center + cam.R.T @ np.array([0.5, 0.0, 0.0])
    back = cam.replace(name='back', R=R, t=-R @ center)
    assert epipolar_polyline(cam, (320.0, 240.0), back) == []
    assert epipolar_polyline(back, (320.0, 240.0), cam) == []
