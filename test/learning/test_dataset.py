"""Augmented crops keep images, labels and virtual cameras consistent with each other."""
from helpers.ring import random_points, ring_rig
import numpy as np
import pytest

from monet_ros.learning.dataset import AugmentConfig, CropCache, boxes_from_points, fill_boxes
from monet_ros.learning.recording import Recording


def make_recording(cameras, X_t, draw=True):
    """Frames with a bright 3x3 dot at each projected point (T instants)."""
    T, C = X_t.shape[:2]
    frames = []
    for cam in cameras:
        f = np.zeros((T, cam.height, cam.width, 3), np.uint8)
        if draw:
            for t in range(T):
                for u, v in np.round(cam.project(X_t[t])).astype(int):
                    f[t, max(v - 1, 0):v + 2, max(u - 1, 0):u + 2] = 255
        frames.append(f)
    labels = np.full((T, len(cameras), C, 2), np.nan)
    return Recording('test', cameras, np.arange(T, dtype=np.int64) * 10, frames,
                     tuple(f'k{c}' for c in range(C)), labels, X_t)


@pytest.mark.parametrize('dist', [np.zeros(5), np.array([-0.2, 0.05, 0.0, 0.0, 0.0])])
def test_heatmap_cameras_match_label_transform_under_augmentation(dist):
    cameras = ring_rig(5, dist=dist)
    X = random_points(6, seed=1)[None].repeat(3, axis=0)
    rec = make_recording(cameras, X, draw=False)
    proj = np.stack([np.stack([c.project(X[t]) for c in cameras]) for t in range(3)])
    boxes = boxes_from_points(proj, aspect=1.0, margin=0.3)
    cache = CropCache(rec, boxes, (64, 64), (16, 16), cache_scale=1.4)
    rng = np.random.default_rng(3)
    inst, view = np.repeat(np.arange(3), 5), np.tile(np.arange(5), 3)
    batch = cache.views(inst, view, rng, AugmentConfig(rotate_deg=30.0))
    assert batch.images.shape == (15, 3, 64, 64)
    heat_labels = batch.to_heatmap(proj[inst, view])               # A @ original pixels
    for n in range(15):
        virtual = cameras[view[n]].replace(K=batch.K[n], R=batch.R[n], t=batch.t[n],
                                           width=16, height=16)
        np.testing.assert_allclose(virtual.project(X[inst[n]]), heat_labels[n], atol=1e-6)
    # the rotations were really applied (not silently skipped)
    R0 = np.stack([c.R for c in cameras])[view]
    Rz = batch.R @ R0.transpose(0, 2, 1)
    angles = np.degrees(np.arctan2(Rz[:, 1, 0], Rz[:, 0, 0]))
    assert np.abs(angles).max() > 5.0


def test_augmented_image_content_lands_where_labels_go():
    cameras = ring_rig(4)
    X = random_points(5, seed=4, spread=0.3)[None]
    rec = make_recording(cameras, X)
    proj = np.stack([c.project(X[0]) for c in cameras])[None]
    cache = CropCache(rec, boxes_from_points(proj, margin=0.4), (96, 96), (96, 96))
    batch = cache.views(np.zeros(4, int), np.arange(4), np.random.default_rng(0),
                        AugmentConfig(brightness=0, contrast=0, color=0, noise=0,
                                      rotate_deg=25.0))
    target = batch.to_heatmap(proj[0])                             # heatmap = input size here
    for n in range(4):
        image = batch.images[n, 0].numpy()
        for u, v in target[n]:
            if 2 <= u < 93 and 2 <= v < 93:
                iu, iv = int(round(u)), int(round(v))
                assert image[iv - 1:iv + 2, iu - 1:iu + 2].max() > 0.5


def test_boxes_and_fill():
    pts = np.array([[[10.0, 20.0], [30.0, 60.0]], [[np.nan, np.nan], [np.nan, np.nan]]])
    boxes = boxes_from_points(pts[:, None], aspect=1.0, margin=0.25)
    np.testing.assert_allclose(boxes[0, 0], [20.5 - 30, 40.5 - 30, 20.5 + 30, 40.5 + 30])
    assert np.isnan(boxes[1, 0]).all()
    cams = ring_rig(1)
    filled = fill_boxes(boxes, cams)
    np.testing.assert_allclose(filled[1, 0], filled[0, 0])
    full = fill_boxes(np.full((2, 1, 4), np.nan), cams)
    np.testing.assert_allclose(full[0, 0], [0, -20, 160, 140])
    with pytest.raises(ValueError, match='AugmentConfig.scale'):
        AugmentConfig(scale=-1)


def real_like_rig(dist):
    """A ring whose cameras have fx != fy (8%) and the given (tangential) distortion."""
    cameras = ring_rig(4, width=320, height=240, focal=300.0)
    out = []
    for cam in cameras:
        K = cam.K.copy()
        K[1, 1] *= 1.08
        out.append(cam.replace(K=K, dist=dist))
    return out


def cv2_project(X, R, t, K, dist):
    import cv2
    rvec, _ = cv2.Rodrigues(np.asarray(R, np.float64))
    uv, _ = cv2.projectPoints(np.asarray(X, np.float64), rvec, np.asarray(t, np.float64),
                              np.asarray(K, np.float64), np.asarray(dist, np.float64))
    return uv.reshape(-1, 2)


REAL_DISTORTIONS = [np.array([-0.15, 0.03, 0.004, -0.006, 0.0]),
                    np.array([-0.1, 0.02, -0.003, 0.005, 0.001, 0, 0, 0,
                              0.002, -0.001, -0.003, 0.0015])]


@pytest.mark.parametrize('dist', REAL_DISTORTIONS)
def test_rotation_augmentation_is_exact_for_real_calibrations(dist):
    """fx != fy and tangential (and prism) distortion: the augmented view's virtual camera
    (K, dist, R, t) projects with cv2.projectPoints exactly where the labels are warped."""
    cameras = real_like_rig(dist)
    X = random_points(8, seed=2, spread=0.35)[None].repeat(2, axis=0)
    rec = make_recording(cameras, X, draw=False)
    proj = np.stack([np.stack([cv2_project(X[t], c.R, c.t, c.K, c.dist) for c in cameras])
                     for t in range(2)])                          # independent of Camera
    cache = CropCache(rec, boxes_from_points(proj, margin=0.3), (64, 64), (16, 16), 1.4)
    inst, view = np.repeat(np.arange(2), 4), np.tile(np.arange(4), 2)
    batch = cache.views(inst, view, np.random.default_rng(5), AugmentConfig(rotate_deg=40.0))
    heat_labels = batch.to_heatmap(proj[inst, view])
    for n in range(len(inst)):
        expected = cv2_project(X[inst[n]], batch.R[n], batch.t[n], batch.K[n], batch.dist[n])
        np.testing.assert_allclose(heat_labels[n], expected, atol=1e-6)
    R0 = np.stack([c.R for c in cameras])[view]
    Rz = batch.R @ R0.transpose(0, 2, 1)
    angles = np.degrees(np.arctan2(Rz[:, 1, 0], Rz[:, 0, 0]))
    assert np.abs(angles).max() > 15.0                           # rotation not skipped


def test_rotated_image_content_matches_projection_with_tangential_distortion():
    """Gaussian dots drawn at the cv2.projectPoints projections of 3D points land, after a
    rotation augmentation, within 0.5 px of the projection by the augmented virtual camera."""
    cameras = real_like_rig(REAL_DISTORTIONS[0])
    X = random_points(6, seed=7, spread=0.35)
    yy, xx = np.mgrid[0:240, 0:320].astype(np.float64)
    frames, proj = [], []
    for cam in cameras:
        uv = cv2_project(X, cam.R, cam.t, cam.K, cam.dist)
        image = np.zeros((240, 320))
        for u, v in uv:
            image += np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 1.6 ** 2))
        frames.append(np.repeat(np.clip(image * 255, 0, 255).astype(np.uint8)[None, ..., None],
                                3, axis=3))
        proj.append(uv)
    proj = np.stack(proj)[None]                                   # (1, V, C, 2)
    rec = Recording('dots', cameras, np.zeros(1, np.int64), frames,
                    tuple(f'k{c}' for c in range(6)), np.full((1, 4, 6, 2), np.nan), X[None])
    cache = CropCache(rec, boxes_from_points(proj, margin=0.3), (128, 128), (128, 128), 1.4)
    batch = cache.views(np.zeros(4, int), np.arange(4), np.random.default_rng(1),
                        AugmentConfig(scale=0.1, translate=0.05, rotate_deg=35.0, brightness=0,
                                      contrast=0, color=0, noise=0))
    checked = 0
    for n in range(4):
        expected = cv2_project(X, batch.R[n], batch.t[n], batch.K[n], batch.dist[n])
        image = batch.images[n, 0].numpy().astype(np.float64)
        gap = np.linalg.norm(expected[:, None] - expected[None], axis=-1) + \
            np.eye(len(X)) * 1e9
        for c, (u, v) in enumerate(expected):
            if gap[c].min() < 14 or not (6 <= u < 121 and 6 <= v < 121):
                continue                                          # overlapping or at the edge
            iu, iv = int(round(u)), int(round(v))
            patch = image[iv - 5:iv + 6, iu - 5:iu + 6]
            py, px = np.mgrid[iv - 5:iv + 6, iu - 5:iu + 6]
            centroid = np.array([(patch * px).sum(), (patch * py).sum()]) / patch.sum()
            assert np.linalg.norm(centroid - (u, v)) < 0.5, (n, c, centroid, (u, v))
            checked += 1
    assert checked >= 8
