"""Crops: warpAffine output against brute-force bilinear sampling; boxes; inverse mapping."""
import numpy as np
import pytest

from monet_ros.cores import ViewThreads
from monet_ros.geometry import crop_transform
from monet_ros.io.images import ImageDecodeError, raw_to_rgb8
from monet_ros.models.crop import (
    crop_images,
    crop_to_original,
    fit_boxes_to_aspect,
    full_frame_boxes,
)


def smooth_image(rng, h, w):
    yy, xx = np.mgrid[0:h, 0:w]
    channels = [127 + 120 * np.sin(xx / rng.uniform(5, 15) + rng.uniform(0, 6))
                * np.cos(yy / rng.uniform(5, 15)) for _ in range(3)]
    return np.clip(np.stack(channels, -1), 0, 255).astype(np.uint8)


def brute_force_crop(image, box, out_size):
    """Bilinear sampling at u = (u' + 0.5) (x1 - x0) / W_out + x0 - 0.5 (zero outside)."""
    x0, y0, x1, y1 = box
    w_out, h_out = out_size
    h, w = image.shape[:2]
    src = np.pad(image.astype(np.float64), ((1, 1), (1, 1), (0, 0)))
    out = np.zeros((h_out, w_out, 3))
    for vp in range(h_out):
        for up in range(w_out):
            u = (up + 0.5) * (x1 - x0) / w_out + x0 - 0.5
            v = (vp + 0.5) * (y1 - y0) / h_out + y0 - 0.5
            iu, iv = int(np.floor(u)), int(np.floor(v))
            fu, fv = u - iu, v - iv
            value = np.zeros(3)
            for du, dv, weight in ((0, 0, (1 - fu) * (1 - fv)), (1, 0, fu * (1 - fv)),
                                   (0, 1, (1 - fu) * fv), (1, 1, fu * fv)):
                cu, cv = iu + du, iv + dv
                if 0 <= cu < w and 0 <= cv < h:
                    value += weight * src[cv + 1, cu + 1]
            out[vp, up] = value
    return out


def test_crop_matches_brute_force_bilinear():
    rng = np.random.default_rng(0)
    images = np.stack([smooth_image(rng, 60, 80) for _ in range(2)])
    boxes = np.array([[10.3, 5.7, 50.3, 45.7], [-8.0, 20.0, 40.0, 68.0]])  # 2nd leaves the image
    crops = crop_images(images, boxes, (24, 24), antialias=False)
    assert crops.shape == (2, 24, 24, 3) and crops.dtype == np.uint8
    for image, box, crop in zip(images, boxes, crops):
        expected = brute_force_crop(image, box, (24, 24))
        assert np.abs(crop - expected).max() <= 2.0


@pytest.mark.parametrize('antialias, side', [(False, 256), (True, 256), (True, 320),
                                             (True, 400)])
def test_crop_keeps_geometry_with_and_without_antialias(antialias, side):
    # A blob at a sub-pixel point must appear at S (u, v) in a 4x (5x, 6.25x) shrunk crop.
    h, w = 500, 500
    u, v = 231.3, 187.8
    yy, xx = np.mgrid[0:h, 0:w]
    blob = 250 * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 10.0 ** 2))
    image = np.repeat(blob[..., None], 3, axis=2).astype(np.uint8)
    box = np.array([100.0, 60.0, 100.0 + side, 60.0 + side])
    crop = crop_images(image[None], box[None], (64, 64), antialias=antialias)[0, ..., 0]
    weights = crop.astype(np.float64)
    cy, cx = np.mgrid[0:64, 0:64]
    centroid = np.array([(weights * cx).sum(), (weights * cy).sum()]) / weights.sum()
    expected = (crop_transform(box, (64, 64)) @ [u, v, 1.0])[:2]
    np.testing.assert_allclose(centroid, expected, atol=0.1)


@pytest.mark.parametrize('factor', [3, 4, 5, 7, 12])
def test_antialias_removes_aliasing(factor):
    # Pixel noise shrunk `factor` x: plain bilinear keeps much of it (aliasing); averaging
    # factor^2 source pixels per output pixel (the ideal box filter) divides the noise's
    # standard deviation by `factor`: the crop stays within 20% of that.
    side = 64 * factor
    image = np.random.default_rng(0).integers(0, 256, (side, side, 3), dtype=np.uint8)
    plain = crop_images(image[None], [[0, 0, side, side]], (64, 64), antialias=False)
    smooth = crop_images(image[None], [[0, 0, side, side]], (64, 64), antialias=True)
    assert plain.std() > 30
    assert smooth.std() < 1.2 * image.std() / factor
    assert abs(smooth.mean() - image.mean()) < 2


def test_boxes_and_inverse_mapping():
    np.testing.assert_allclose(fit_boxes_to_aspect([[100, 100, 300, 200]], 1.0),
                               [[100, 50, 300, 250]])
    np.testing.assert_allclose(fit_boxes_to_aspect([[0, 0, 10, 40]], 0.5), [[-5, 0, 15, 40]])
    np.testing.assert_allclose(full_frame_boxes([(640, 480)], 1.0), [[0, -80, 640, 560]])
    with pytest.raises(ValueError, match='x1 > x0'):
        fit_boxes_to_aspect([[5, 0, 5, 10]], 1.0)
    boxes = np.array([[10.0, 20.0, 110.0, 120.0], [0.0, -80.0, 640.0, 560.0]])
    original = np.array([[[50.5, 60.25], [np.nan, np.nan]], [[320.0, 10.0], [1.0, 2.0]]])
    S = [crop_transform(b, (46, 46)) for b in boxes]
    cropped = np.stack([(np.c_[p, np.ones(2)] @ s.T)[:, :2] for p, s in zip(original, S)])
    np.testing.assert_allclose(crop_to_original(cropped, boxes, (46, 46)), original)


def test_a_box_far_larger_than_the_image_stays_within_memory():
    """Issue 37 (a live track_margin of 1e4): a crop box thousands of times the image was
    padded to one shrunk pixel of the box's size (GBs); the region now stays within twice
    the image. A moderate box beyond the image crops as before (brute force), and a huge
    one gives the image as a dot of its mean at the crop's centre."""
    import tracemalloc
    image = np.full((120, 160, 3), 200, np.uint8)
    huge = (-5e4, -4e4, 5e4 + 160, 4e4 + 120)
    tracemalloc.start()
    out = crop_images([image], np.array([huge]), (46, 46))[0]
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 20 * image.nbytes, peak
    assert out.shape == (46, 46, 3) and out.max() <= 200
    assert out[:20].max() == 0 and out[:, :20].max() == 0       # black beyond the image
    wide = (-300.0, -200.0, 460.0, 320.0)
    rng = np.random.default_rng(7)
    textured = smooth_image(rng, 120, 160)
    got = crop_images([textured], np.array([wide]), (46, 46), antialias=False)[0]
    np.testing.assert_allclose(got, brute_force_crop(textured, wide, (46, 46)), atol=1.01)


def test_crops_of_raw_layouts_are_the_crops_of_the_rgb_images():
    """crop_images(layouts=...): each image cropped in its own channel layout and converted
    into the one batch equals the crop of the image converted to RGB first (raw_to_rgb8)."""
    rng = np.random.default_rng(3)
    rgb = [smooth_image(rng, 120, 160) for _ in range(5)]
    alpha = np.full((120, 160, 1), 200, np.uint8)
    raw = [rgb[0], rgb[1][..., ::-1].copy(), np.concatenate([rgb[2], alpha], axis=2),
           np.concatenate([rgb[3][..., ::-1], alpha], axis=2), rgb[4][..., :1].copy()]
    layouts = ['rgb8', 'bgr8', 'rgba8', 'bgra8', 'mono8']
    boxes = np.array([(0, -20, 160, 140), (10, 10, 90, 90), (-30, 5, 50, 85),
                      (40, 30, 72, 62), (0, 0, 160, 160)], float)
    got = crop_images(raw, boxes, (32, 32), layouts=layouts)
    expected = crop_images([raw_to_rgb8(r, layout) for r, layout in zip(raw, layouts)], boxes,
                           (32, 32))
    assert got.shape == (5, 32, 32, 3) and got.dtype == np.uint8
    np.testing.assert_array_equal(got, expected)
    with ViewThreads(3) as threads:                  # the views cropped in parallel: the same
        np.testing.assert_array_equal(
            crop_images(raw, boxes, (32, 32), layouts=layouts, threads=threads), expected)
        np.testing.assert_array_equal(
            crop_images(np.stack(rgb), boxes, (32, 32), threads=threads),
            crop_images(np.stack(rgb), boxes, (32, 32)))
    with pytest.raises(ImageDecodeError, match='unsupported layout'):
        crop_images(raw[:1], boxes[:1], (32, 32), layouts=['yuv422'])
