"""Crop/resize images around boxes with the matching virtual cameras (K' = S K).

Boxes are (x0, y0, x1, y1) in pixel-EDGE coordinates (full W x H frame = (0, 0, W, H));
the crop math is monet_ros.geometry.crop_transform, and every crop is
cv2.warpAffine(image, S[:2], out_size), so crop pixel (u', v') sees original pixel
S^-1 (u', v', 1). Outside the image the crop is black (0).
"""
import cv2
import numpy as np

from monet_ros.geometry import crop_transform


def fit_boxes_to_aspect(boxes, aspect):
    """Grow boxes (N, 4) about their centres to width / height = aspect (never shrink)."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    cx = (boxes[:, 0] + boxes[:, 2]) / 2
    cy = (boxes[:, 1] + boxes[:, 3]) / 2
    w = boxes[:, 2] - boxes[:, 0]
    h = boxes[:, 3] - boxes[:, 1]
    if not (np.all(w > 0) and np.all(h > 0)):
        raise ValueError(f'boxes must have x1 > x0 and y1 > y0, got {boxes.tolist()}')
    w, h = np.maximum(w, h * aspect), np.maximum(h, w / aspect)
    return np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], axis=1)


def full_frame_boxes(sizes, aspect):
    """Boxes (N, 4) covering whole frames of sizes [(W, H), ...], grown to `aspect` (padding)."""
    sizes = np.asarray(sizes, dtype=np.float64).reshape(-1, 2)
    boxes = np.concatenate([np.zeros_like(sizes), sizes], axis=1)
    return fit_boxes_to_aspect(boxes, aspect)


def crop_images(images, boxes, out_size, antialias=True):
    """Crop and resize every image to out_size = (W_out, H_out) -> (N, H_out, W_out, 3) uint8.

    images: (N, H, W, 3) array or a sequence of (H_i, W_i, 3) arrays (cameras may differ);
    boxes: (N, 4) edge coordinates. antialias: when a box is shrunk by more than 1x, blur
    the source region first with a Gaussian of sigma = (shrink - 1) / 2 per axis (symmetric,
    so the geometry S is unchanged). cv2.warpAffine with bilinear interpolation, constant 0
    border.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    if len(images) != len(boxes):
        raise ValueError(f'crop_images: {len(images)} images but {len(boxes)} boxes')
    w_out, h_out = int(out_size[0]), int(out_size[1])
    out = np.empty((len(boxes), h_out, w_out) + np.shape(images[0])[2:], dtype=np.uint8)
    for n, (image, box) in enumerate(zip(images, boxes)):
        S = crop_transform(box, (w_out, h_out))
        source = image
        if antialias:
            source, S = _blurred_region(image, box, S)
        cv2.warpAffine(source, S[:2], (w_out, h_out), dst=out[n], flags=cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out


def _blurred_region(image, box, S):
    """The box region of `image` (with a margin) Gaussian-blurred for a shrink of 1/S, and S
    shifted to that region's origin; unchanged when the crop does not shrink."""
    shrink_x, shrink_y = 1.0 / S[0, 0], 1.0 / S[1, 1]
    if shrink_x <= 1.0 and shrink_y <= 1.0:
        return image, S
    sigma_x = max((shrink_x - 1) / 2, 0.0)
    sigma_y = max((shrink_y - 1) / 2, 0.0)
    h, w = image.shape[:2]
    mx, my = int(np.ceil(3 * sigma_x)) + 2, int(np.ceil(3 * sigma_y)) + 2
    x0 = int(np.clip(np.floor(box[0]) - mx, 0, w))
    x1 = int(np.clip(np.ceil(box[2]) + mx, 0, w))
    y0 = int(np.clip(np.floor(box[1]) - my, 0, h))
    y1 = int(np.clip(np.ceil(box[3]) + my, 0, h))
    if x1 <= x0 or y1 <= y0:  # the box lies outside the image: the crop is black anyway
        return image, S
    region = cv2.GaussianBlur(image[y0:y1, x0:x1], (0, 0), sigmaX=max(sigma_x, 1e-3),
                              sigmaY=max(sigma_y, 1e-3), borderType=cv2.BORDER_REPLICATE)
    shift = np.array([[1.0, 0.0, x0], [0.0, 1.0, y0], [0.0, 0.0, 1.0]])
    return region, S @ shift


def crop_to_original(points, boxes, out_size):
    """Crop pixels (N, C, 2) of crops of size out_size (W, H) -> original image pixels.

    Inverse of crop_transform per box; NaN stays NaN.
    """
    points = np.asarray(points, dtype=np.float64)
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    S = np.stack([crop_transform(box, out_size) for box in boxes])   # (N, 3, 3)
    scale = np.stack([S[:, 0, 0], S[:, 1, 1]], axis=-1)[:, None, :]  # (N, 1, 2)
    offset = np.stack([S[:, 0, 2], S[:, 1, 2]], axis=-1)[:, None, :]
    return (points - offset) / scale
