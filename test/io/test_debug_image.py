"""Debug image drawing: peaks mapped back to source pixels, box, size and colours."""
import cv2
from helpers.scenes import gaussian_heatmaps, ring_rig, to_crop
import numpy as np
import pytest

from monet_ros.io.debug_image import BOX, FUSED, PEAK, debug_image, heatmap_peaks_in_image


def test_peaks_map_back_through_the_crop_camera():
    cam = ring_rig(1)[0]
    box = (150.0, 80.0, 470.0, 320.0)
    grid = (64, 48)
    uv = np.array([[200.3, 100.7], [300.0, 200.0], [455.5, 310.2]])
    heat = gaussian_heatmaps(to_crop(uv, box, grid), grid[::-1], sigma=1.5, peak=[0.9, 0.5, 1])
    peaks, confidence = heatmap_peaks_in_image(heat, cam.crop(box, grid).K, cam.K)
    np.testing.assert_allclose(peaks, uv, atol=0.05)
    np.testing.assert_allclose(confidence, heat.max(axis=(1, 2)), rtol=1e-5)


def test_drawing_size_and_marks():
    image = np.full((240, 320, 3), 30, np.uint8)
    peaks = np.array([[100.0, 50.0], [200.0, 150.0]])
    fused = np.array([[60.0, 200.0], [np.nan, np.nan]])
    out = debug_image(image, (10, 20, 300, 230), peaks, [0.9, 0.05], fused,
                      bone_indices=[(0, 1)])
    assert out.shape == image.shape and out.dtype == np.uint8
    assert tuple(out[100, 10]) == BOX                  # left edge of the box
    assert tuple(out[50, 100]) == PEAK                 # a confident peak
    assert tuple(out[150, 200]) == (30, 30, 30)        # below min_confidence: not drawn
    assert tuple(out[200, 60]) == FUSED                # a fused reprojection
    half = debug_image(image, None, peaks, None, scale=0.5)
    assert half.shape == (120, 160, 3)
    assert tuple(half[25, 50]) == PEAK
    assert np.array_equal(image, np.full((240, 320, 3), 30, np.uint8))   # input untouched
    with pytest.raises(ValueError, match='uint8'):
        debug_image(image.astype(np.float32))


def test_wild_reprojections_are_left_out():
    """A wild triangulation reprojects to ~1e12 px: it is not drawn (OpenCV takes 32-bit
    coordinates) and the bones to it are left out; the rest is drawn."""
    image = np.full((240, 320, 3), 30, np.uint8)
    fused = np.array([[60.0, 200.0], [1e12, -3e11], [-400.0, 100.0], [250.0, 40.0]])
    out = debug_image(image, None, None, None, fused, bone_indices=[(0, 1), (1, 3), (0, 3)])
    assert tuple(out[200, 60]) == FUSED and tuple(out[40, 250]) == FUSED
    # only the bone 0-3 is drawn: the pixels on its line are red, and nothing else is
    expected = np.full_like(image, 30)
    cv2.line(expected, (60, 200), (250, 40), FUSED, 2, cv2.LINE_AA)
    drawn = (out != 30).any(axis=2)
    line = (expected != 30).any(axis=2)
    assert drawn[line].mean() > 0.95
    far = ~cv2.dilate(line.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
    assert not drawn[far].any()
