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
