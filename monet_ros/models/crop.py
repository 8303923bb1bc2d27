"""Crop/resize images around boxes with the matching virtual cameras (K' = S K).

Boxes are (x0, y0, x1, y1) in pixel-EDGE coordinates (full W x H frame = (0, 0, W, H));
the crop math is monet_ros.geometry.crop_transform, and every crop is
cv2.warpAffine(image, S[:2], out_size), so crop pixel (u', v') sees original pixel
S^-1 (u', v', 1). Outside the image the crop is black (0).
"""
import cv2
import numpy as np

from monet_ros.geometry import crop_transform
from monet_ros.io.images import raw_to_rgb8


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


def crop_images(images, boxes, out_size, antialias=True, layouts=None, threads=None):
    """Crop and resize every image to out_size = (W_out, H_out) -> (N, H_out, W_out, 3) uint8.

    images: (N, H, W, 3) array or a sequence of (H_i, W_i, 3) arrays (cameras may differ);
    boxes: (N, 4) edge coordinates. antialias: when a box is shrunk by 2x or more, the box
    region is first block-averaged by power-of-two factors (2x2 means, cv2.resize INTER_AREA)
    so that the warp shrinks by less than 2x, and the warp is re-expressed in that region's
    pixels, so the geometry S is unchanged.
    layouts: None (the images are as they come, e.g. all rgb8) or, per image, the channel
    layout of an io.images.CROPPABLE buffer ('rgb8', 'bgr8', 'rgba8', 'bgra8', 'mono8' with
    (H, W, 3 | 4 | 1) arrays): each is cropped in its own layout and only the crop is
    converted to RGB (as io.images.raw_to_rgb8, by cv2.cvtColor into the output batch: a
    numpy channel flip of a 128 px crop took 81 us, cvtColor 2 us).
    threads: a cores.ViewThreads to crop the images in parallel (the same result), or None.
    cv2.warpAffine with bilinear interpolation, constant 0 border.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    if len(images) != len(boxes):
        raise ValueError(f'crop_images: {len(images)} images but {len(boxes)} boxes')
    if layouts is not None and len(layouts) != len(boxes):
        raise ValueError(f'crop_images: {len(layouts)} layouts for {len(boxes)} images')
    w_out, h_out = int(out_size[0]), int(out_size[1])
    channels = (3,) if layouts is not None else np.shape(images[0])[2:]
    out = np.empty((len(boxes), h_out, w_out) + channels, dtype=np.uint8)

    def crop(n):
        S = crop_transform(boxes[n], (w_out, h_out))
        source = images[n]
        if antialias:
            source, S = _area_shrunk_region(source, boxes[n], S)
        layout = 'rgb8' if layouts is None else layouts[n]
        # the crop in the image's own layout: straight into the batch when it is rgb8
        dst = out[n] if layout == 'rgb8' else None
        warped = cv2.warpAffine(source, S[:2], (w_out, h_out), dst=dst, flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if dst is None:
            _crop_to_rgb8(warped, layout, out[n])

    if threads is None:
        for n in range(len(boxes)):
            crop(n)
    else:
        threads.run(crop, len(boxes))
    return out


# io.images.raw_to_rgb8's channel shuffles as OpenCV conversions (the same bytes)
_TO_RGB = {'bgr8': cv2.COLOR_BGR2RGB, 'rgba8': cv2.COLOR_RGBA2RGB, 'bgra8': cv2.COLOR_BGRA2RGB,
           'mono8': cv2.COLOR_GRAY2RGB}


def _crop_to_rgb8(crop, layout, out):
    """Write raw_to_rgb8(crop, layout) into out (H, W, 3) uint8."""
    if layout not in _TO_RGB:
        out[...] = raw_to_rgb8(crop, layout)    # raises ImageDecodeError naming the layout
        return
    cv2.cvtColor(crop, _TO_RGB[layout], dst=out)


def _integer_span(lo, hi, factor, limit):
    """[start, start + n * factor) covering [lo, hi) within [0, limit) where possible."""
    start = int(np.clip(np.floor(lo) - 1, 0, limit))
    stop = int(np.clip(np.ceil(hi) + 1, 0, limit))
    n = max(1, -(-(stop - start) // factor))
    start = max(0, min(start, limit - n * factor))
    return start, n


def _area_shrunk_region(image, box, S):
    """The box region of `image` (1-pixel margin) box-filtered down by a power-of-two factor
    p (repeated cv2.resize INTER_AREA halvings: each output pixel is the rounded mean of a
    2x2 block, OpenCV's fast path: a 640x480 frame shrunk by 4 in 0.31 ms against 0.43-0.89
    ms for one INTER_AREA by 5), and S
    re-expressed in that region's pixels; p is the largest power of two with the warp then
    shrinking by less than 2x. Unchanged when the crop shrinks by less than 2x.
    A region that needs a few more columns/rows than the image has is padded by replication
    (under one shrunk pixel at the image border); p is at most the image's side, so the
    region is at most twice the image whatever the box (a box far larger than the image is
    warped from the image shrunk by that much)."""
    h, w = image.shape[:2]
    # never by more than the image's side: a box many times the image (a huge tracked
    # margin) would otherwise pad the region to one shrunk pixel of that size (GBs)
    fx = min(_power_of_two_at_most(1.0 / S[0, 0]), _power_of_two_at_most(w))
    fy = min(_power_of_two_at_most(1.0 / S[1, 1]), _power_of_two_at_most(h))
    if fx < 2 and fy < 2:
        return image, S
    if box[2] <= 0 or box[3] <= 0 or box[0] >= w or box[1] >= h:
        return image, S  # the box lies outside the image: the crop is black anyway
    x0, nx = _integer_span(box[0], box[2], fx, w)
    y0, ny = _integer_span(box[1], box[3], fy, h)
    region = image[y0:y0 + ny * fy, x0:x0 + nx * fx]
    pad_y, pad_x = ny * fy - region.shape[0], nx * fx - region.shape[1]
    if pad_x or pad_y:
        region = cv2.copyMakeBorder(region, 0, pad_y, 0, pad_x, cv2.BORDER_REPLICATE)
    while region.shape[1] > nx or region.shape[0] > ny:
        half = (max(nx, region.shape[1] // 2), max(ny, region.shape[0] // 2))
        region = cv2.resize(region, half, interpolation=cv2.INTER_AREA)
    # original pixels -> shrunk-region pixels, same edge convention as the crop itself
    D = crop_transform((x0, y0, x0 + nx * fx, y0 + ny * fy), (nx, ny))
    return region, S @ np.linalg.inv(D)


def _power_of_two_at_most(x):
    """The largest power of two <= x (1 for x < 2)."""
    return 1 << max(0, int(np.floor(np.log2(max(x, 1.0)))))


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
