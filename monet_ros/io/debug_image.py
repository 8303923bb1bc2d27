"""A viewable debug image per camera (no ROS types): the source image with the detector's
crop box, its decoded heatmap peaks and the fused 3D keypoints reprojected; published as bgr8
(numpy_to_image_msg(..., encoding='bgr8')) so that RViz, Foxglove and rqt_image_view show it
as is.

Colours: crop box yellow, detected peaks green (radius grows with confidence; peaks below
`min_confidence` are not drawn), fused reprojections red crosses joined by the skeleton's
bones.
"""
import cv2
import numpy as np

from monet_ros.models import decode_heatmaps

BOX = (255, 220, 0)        # rgb
PEAK = (60, 220, 60)
FUSED = (240, 40, 40)


def heatmap_peaks_in_image(heat, K_heat, K):
    """Decoded peaks of (C, h, w) heatmaps in source-image pixels: the heatmap's virtual
    camera is K_heat = S K, so a heatmap pixel p maps back by S^-1 p.
    -> (peaks (C, 2), confidence (C,))."""
    peaks, confidence = decode_heatmaps(np.asarray(heat, np.float32)[None])
    S = np.asarray(K_heat, np.float64) @ np.linalg.inv(np.asarray(K, np.float64))
    homog = np.concatenate([np.asarray(peaks[0], np.float64),
                            np.ones((peaks.shape[1], 1))], axis=1)
    back = homog @ np.linalg.inv(S).T
    return back[:, :2] / back[:, 2:], np.asarray(confidence[0], np.float64)


def debug_image(image_rgb, box=None, peaks=None, confidence=None, reprojected=None,
                bone_indices=(), min_confidence=0.1, scale=1.0):
    """(H, W, 3) uint8 rgb -> (round(H*scale), round(W*scale), 3) uint8 rgb with the drawing.

    box: crop x0 y0 x1 y1 (pixel edges) or None; peaks (C, 2) source pixels with confidence
    (C,); reprojected (N, 2) source pixels of the fused keypoints (NaN = not fused) or None;
    bone_indices (B, 2) keypoint index pairs drawn between reprojections (reprojections
    more than one image size outside the image are left out). Raises ValueError
    for an image that is not (H, W, 3) uint8 or a non-positive scale."""
    image = np.asarray(image_rgb)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(f'need an (H, W, 3) uint8 image, got {image.dtype} {image.shape}')
    if not scale > 0:
        raise ValueError(f'scale must be > 0, got {scale}')
    if scale != 1.0:   # scaled straight from the source (no full-size copy to draw on)
        size = (max(1, round(image.shape[1] * scale)), max(1, round(image.shape[0] * scale)))
        out = cv2.resize(np.ascontiguousarray(image), size, interpolation=cv2.INTER_AREA)
    else:
        out = np.array(image)
    thick = max(1, round(2 * scale))

    def px(points):
        """Pixel centres -> integer drawing coordinates of the scaled image."""
        return np.round((np.asarray(points, np.float64) + 0.5) * scale - 0.5).astype(int)

    if box is not None:
        x0, y0, x1, y1 = (np.asarray(box, np.float64) * scale).round().astype(int)
        cv2.rectangle(out, (x0, y0), (x1 - 1, y1 - 1), BOX, thick)
    if reprojected is not None:
        rep = np.asarray(reprojected, np.float64).reshape(-1, 2)
        # points far outside the image (a wild triangulation) are not drawn: OpenCV takes
        # 32-bit coordinates, and a mark there would not be seen anyway
        size = np.array([image.shape[1], image.shape[0]], np.float64)
        with np.errstate(invalid='ignore'):
            ok = (np.isfinite(rep).all(axis=1) & (rep > -size).all(axis=1)
                  & (rep < 2 * size).all(axis=1))
        pts = px(np.where(ok[:, None], rep, 0))
        for a, b in np.asarray(bone_indices, int).reshape(-1, 2):
            if ok[a] and ok[b]:
                cv2.line(out, tuple(pts[a]), tuple(pts[b]), FUSED, thick, cv2.LINE_AA)
        for p in pts[ok]:
            cv2.drawMarker(out, tuple(p), FUSED, cv2.MARKER_CROSS, 6 * thick + 4, thick)
    if peaks is not None:
        peaks = np.asarray(peaks, np.float64).reshape(-1, 2)
        conf = (np.ones(len(peaks)) if confidence is None
                else np.asarray(confidence, np.float64).reshape(-1))
        keep = np.isfinite(peaks).all(axis=1) & (conf >= min_confidence)
        for p, c in zip(px(np.where(keep[:, None], peaks, 0))[keep], conf[keep]):
            cv2.circle(out, tuple(p), max(2, round((2 + 4 * min(c, 1.0)) * scale)), PEAK,
                       -1, cv2.LINE_AA)
    return out
