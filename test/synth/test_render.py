"""Renderer: depth order (a nearer limb overwrites a farther one), lens distortion in the
drawn outlines, occlusion geometry against brute force, background through the lens."""
import numpy as np
import pytest

from monet_ros.geometry import Camera
from monet_ros.synth.render import (
    RenderConfig,
    Scene,
    capsule_outlines,
    draw_capsules,
    occlusion,
    segment_distance,
)
from monet_ros.synth.rig import look_at


def _camera(dist=(), width=200, height=150, center=(0.0, -4.0, 1.0)):
    R = look_at(center, (0.0, 0.0, 1.0))
    K = np.array([[180.0, 0, 99.5], [0, 180.0, 74.5], [0, 0, 1]])
    return Camera('cam0', K, dist, R, -R @ np.asarray(center), width, height)


@pytest.mark.parametrize('order', [(0, 1), (1, 0)])
def test_nearer_limb_overwrites_farther(order):
    cam = _camera()
    # a horizontal bar 1 m behind the origin and a vertical bar in front, crossing on screen
    A = np.array([[[-0.6, 1.0, 1.0], [0.0, -1.0, 0.6]]])
    B = np.array([[[0.6, 1.0, 1.0], [0.0, -1.0, 1.4]]])
    radii = np.array([0.08, 0.05])
    colors = np.array([[0.0, 0.0, 255.0], [255.0, 0.0, 0.0]])      # far blue, near red
    idx = list(order)
    outlines, depth, facing = capsule_outlines(cam, A[:, idx], B[:, idx], radii[idx],
                                               np.array([0.0, 0.0, 1.0]), levels=1)
    image = np.zeros((150, 200, 3), np.uint8)
    drawn = draw_capsules(image, outlines[0], depth[0], colors[idx], facing[0])
    assert list(np.asarray(idx)[drawn]) == [0, 1]                  # far first, near last
    cross = np.round(cam.project(np.array([[0.0, -1.0, 1.0]]))[0]).astype(int)
    assert tuple(image[cross[1], cross[0]]) == (255, 0, 0)
    # the far bar is visible beside the crossing, the background elsewhere
    far_end = np.round(cam.project(np.array([[0.45, 1.0, 1.0]]))[0]).astype(int)
    assert tuple(image[far_end[1], far_end[0]]) == (0, 0, 255)
    assert tuple(image[5, 5]) == (0, 0, 0)


def test_outlines_follow_lens_distortion():
    dist = np.array([-0.35, 0.1, 0, 0, 0])
    cam = _camera(dist=dist)
    # a thin vertical limb near the left border: barrel distortion pulls it inwards
    A = np.array([[[-1.7, 0.0, 0.3]]])
    B = np.array([[[-1.7, 0.0, 1.7]]])
    outlines, depth, facing = capsule_outlines(cam, A, B, np.array([0.02]),
                                               np.array([0.0, 0.0, 1.0]), levels=1,
                                               axis_points=9)
    image = np.zeros((150, 200, 3), np.uint8)
    draw_capsules(image, outlines[0], depth[0], np.array([[255.0, 255.0, 255.0]]))
    axis = A[0, 0] + np.linspace(0.1, 0.9, 5)[:, None] * (B - A)[0, 0]
    distorted = np.round(cam.project(axis)).astype(int)
    pinhole = np.round(cam.without_distortion().project(axis)).astype(int)
    assert np.abs(distorted - pinhole)[:, 0].min() >= 4       # distortion matters here
    assert np.all(image[distorted[:, 1], distorted[:, 0], 0] > 128)
    ends = pinhole[[0, -1]]                                   # far from the bent outline
    assert np.all(image[ends[:, 1], ends[:, 0], 0] == 0)


def _point_segment_distance(points, a, b):
    """Distance of points (N, 3) to the segment [a, b] (closed form, clamped projection)."""
    d = b - a
    s = np.clip((points - a) @ d / max(d @ d, 1e-12), 0, 1)
    return np.linalg.norm(points - (a + s[:, None] * d), axis=1)


def test_segment_distance_against_brute_force():
    rng = np.random.default_rng(0)
    for _ in range(40):
        p0, p1, q0, q1 = rng.normal(size=(4, 3))
        if rng.random() < 0.2:
            q1 = q0.copy()                                    # a sphere
        dist, _ = segment_distance(p0, p1, q0, q1)
        samples = p0 + np.linspace(0, 1, 20001)[:, None] * (p1 - p0)
        assert abs(dist - _point_segment_distance(samples, q0, q1).min()) < 1e-6
    # parallel segments
    dist, _ = segment_distance(np.zeros(3), np.array([1.0, 0, 0]), np.array([0.5, 1, 0]),
                               np.array([2.0, 1, 0]))
    assert abs(dist - 1.0) < 1e-12


def test_occlusion_against_ray_sampling():
    rng = np.random.default_rng(1)
    cams = [_camera(center=(0.0, -4.0, 1.0)), _camera(center=(4.0, 0.0, 1.5))]
    T, C, P = 3, 6, 5
    X = rng.uniform(-0.5, 0.5, (T, C, 3)) + [0, 0, 1]
    A = rng.uniform(-0.6, 0.6, (T, P, 3)) + [0, 0, 1]
    B = A + rng.normal(scale=0.3, size=(T, P, 3))
    radii = rng.uniform(0.05, 0.2, P)
    attached = rng.random((P, C)) < 0.2
    got = occlusion(cams, X, A, B, radii, attached)
    assert got.shape == (T, 2, C) and 0.1 < got.mean() < 0.9
    s = np.linspace(0, 1, 4001)
    checked = 0
    for t in range(T):
        for v, cam in enumerate(cams):
            for c in range(C):
                ray = cam.center + s[:, None] * (X[t, c] - cam.center)
                gap = np.array([_point_segment_distance(ray, A[t, p], B[t, p]).min()
                                - radii[p] for p in range(P)])[~attached[:, c]]
                if np.all(np.abs(gap) > 2e-3):       # not a grazing ray
                    assert got[t, v, c] == np.any(gap < 0)
                    checked += 1
    assert checked > 30


def test_background_is_seeded_and_textured():
    cams = [_camera(dist=(-0.1, 0.02, 0, 0, 0)), _camera(center=(3.0, 3.0, 2.0))]
    a = Scene(cams, ('torso', 'leg'), seed=5)
    b = Scene(cams, ('torso', 'leg'), seed=5)
    c = Scene(cams, ('torso', 'leg'), seed=6)
    img = a.background(cams[0])
    assert img.shape == (150, 200, 3) and img.dtype == np.uint8
    np.testing.assert_array_equal(img, b.background(cams[0]))
    assert np.abs(img.astype(int) - c.background(cams[0])).mean() > 10
    assert img.std() > 15
    # the lower part of the image sees the floor, the upper part the wall: they differ
    assert np.abs(img[:40].mean((0, 1)) - img[-40:].mean((0, 1))).max() > 3


def test_render_config_validation():
    with pytest.raises(ValueError, match="'levels'"):
        RenderConfig(levels=0)
    with pytest.raises(ValueError, match="'noise'"):
        RenderConfig(noise=-1.0)


def test_shadow_is_a_soft_blob_without_box_edges():
    cam = _camera(center=(0.0, -4.0, 2.0))
    scene = Scene([cam], ('torso',), seed=0)
    image = np.full((150, 200, 3), 200, np.uint8)
    scene.shadow(image, cam, np.zeros(3), 0.35)
    centre = np.round(cam.project(np.zeros((1, 3)))[0]).astype(int)
    assert image[centre[1], centre[0], 0] < 200 * 0.75          # dark under the subject
    edge = np.round(cam.project(np.array([[1.2, 0.0, 0.0], [0.0, 1.2, 0.0]]))).astype(int)
    assert np.all(image[edge[:, 1], edge[:, 0]] == 200)         # untouched farther out
    darkened = np.argwhere(image[..., 0] < 200)
    # the darkened region is round: its bounding box corners stay untouched
    (y0, x0), (y1, x1) = darkened.min(0), darkened.max(0)
    assert np.all(image[[y0, y0, y1, y1], [x0, x1, x0, x1], 0] > 195)
