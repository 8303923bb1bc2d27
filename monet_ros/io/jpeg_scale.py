"""Decode a JPEG at the crop's scale: libjpeg's DCT scaling (OpenCV's IMREAD_REDUCED_COLOR_2,
_4, _8) with the camera following the scale exactly (no ROS).

When the detector's crop of a frame is shrunk to the network input by 2x or more, decoding
the whole frame and shrinking it throws most of the decode away. libjpeg can instead run its
inverse DCT at 1/2, 1/4 or 1/8 of the size (each 8x8 block decoded straight to 4x4, 2x2 or
1x1 pixels), which costs a fraction of a full decode (a 640x480 frame: 0.7 ms full, 0.13 ms
at 1/8 on the development machine) and is the same box average the crop's antialiasing
(models.crop.crop_images: power-of-two INTER_AREA halvings) would have done.

Geometry. The reduced image of a W x H frame at scale 1/s is ceil(W/s) x ceil(H/s) (libjpeg's
jdiv_round_up; the last column/row covers the frame's edge padding). Reduced pixel j covers
full pixels j*s .. j*s + s - 1, whose centre is j*s + (s - 1)/2; with pixel centres on
integers (DESIGN.md) that is

    x_reduced = (x_full + 0.5) / s - 0.5        (the same for y)

so the reduced image is a virtual camera K_s = A_s K with
A_s = [[1/s, 0, 0.5/s - 0.5], [0, 1/s, 0.5/s - 0.5], [0, 0, 1]] (reduction_transform), the
same distortion and extrinsics. In pixel-EDGE coordinates (crop boxes) the map is a plain
division, e_reduced = e_full / s, and crop_transform(box / s) @ A_s == crop_transform(box):
the heatmap's virtual camera (K_heat) is the one a full decode gives.

The reduction chosen (reduction_for) is the largest of 1, 2, 4, 8 that still leaves the crop
box at least the network input size on both axes, so the warp to the input never enlarges.
Images are returned in OpenCV's BGR order ('bgr8'): the detector converts only the crop
(io.images.raw_to_rgb8), never the full frame.
"""
from dataclasses import replace
import math

import cv2
import numpy as np

from monet_ros.io.images import ImageDecodeError

REDUCTIONS = (1, 2, 4, 8)
_FLAGS = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
          8: cv2.IMREAD_REDUCED_COLOR_8}
# start-of-frame markers (baseline, extended, progressive, lossless, and the arithmetic-coded
# ones); 0xC4 (DHT), 0xC8 (JPG) and 0xCC (DAC) share the range but are not frames
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def is_jpeg(data):
    """True when the bytes start with a JPEG start-of-image marker (FF D8 FF)."""
    return bytes(memoryview(data)[:3]) == b'\xff\xd8\xff'


def jpeg_size(data):
    """(width, height) of a JPEG from its start-of-frame header, without decoding it.

    data: bytes-like. Raises ImageDecodeError when it is not a JPEG or has no readable
    start-of-frame segment."""
    buf = memoryview(data).cast('B') if not isinstance(data, np.ndarray) else \
        memoryview(np.ascontiguousarray(data, np.uint8))
    if not is_jpeg(buf):
        raise ImageDecodeError('not a JPEG (no start-of-image marker)')
    pos, n = 2, len(buf)
    while pos + 4 <= n:
        if buf[pos] != 0xFF:
            raise ImageDecodeError(f'JPEG header: no marker at byte {pos}')
        marker = buf[pos + 1]
        if marker == 0xFF:                        # fill byte
            pos += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:    # no length field
            pos += 2
            continue
        length = (buf[pos + 2] << 8) | buf[pos + 3]
        if marker in _SOF:
            if pos + 9 > n:
                break
            height = (buf[pos + 5] << 8) | buf[pos + 6]
            width = (buf[pos + 7] << 8) | buf[pos + 8]
            if width == 0 or height == 0:
                raise ImageDecodeError(f'JPEG header: size {width}x{height}')
            return width, height
        if marker in (0xD9, 0xDA) or length < 2:  # end of image / scan before any frame
            break
        pos += 2 + length
    raise ImageDecodeError('JPEG header: no start-of-frame segment')


def reduced_size(width, height, s):
    """(ceil(width / s), ceil(height / s)): libjpeg's output size at scale 1/s."""
    return -(-int(width) // int(s)), -(-int(height) // int(s))


def reduction_for(box, out_size):
    """The largest s of REDUCTIONS with the box still at least out_size after dividing by s.

    box: (x0, y0, x1, y1) pixel-edge coordinates of the crop in the full frame;
    out_size: (W_out, H_out) the network input. -> int s (1 when the crop is not shrunk 2x
    or more). Raises ValueError for an empty box."""
    x0, y0, x1, y1 = (float(v) for v in np.asarray(box, np.float64).reshape(4))
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f'crop box {(x0, y0, x1, y1)} must have x1 > x0 and y1 > y0')
    shrink = min((x1 - x0) / float(out_size[0]), (y1 - y0) / float(out_size[1]))
    if not math.isfinite(shrink):
        return 1
    return max(s for s in REDUCTIONS if s <= max(shrink, 1.0))


def reduction_transform(s):
    """3x3 A_s: full-frame pixels -> pixels of the frame decoded at 1/s (centres on
    integers: x_r = (x + 0.5) / s - 0.5)."""
    s = float(s)
    return np.array([[1.0 / s, 0.0, 0.5 / s - 0.5],
                     [0.0, 1.0 / s, 0.5 / s - 0.5],
                     [0.0, 0.0, 1.0]])


def reduced_camera(camera, s):
    """The virtual camera of `camera`'s frame decoded at 1/s: K = A_s K, size
    reduced_size(width, height, s), same distortion and extrinsics (s = 1: `camera`)."""
    if int(s) == 1:
        return camera
    width, height = reduced_size(camera.width, camera.height, s)
    return replace(camera, K=reduction_transform(s) @ camera.K, width=width, height=height)


def decode_jpeg(data, s=1):
    """(H', W', 3) uint8 BGR of JPEG bytes decoded at 1/s (s in REDUCTIONS; grey JPEGs are
    repeated to 3 channels). Raises ImageDecodeError when it does not decode, and ValueError
    for another s."""
    if int(s) not in _FLAGS:
        raise ValueError(f'JPEG reduction must be one of {REDUCTIONS}, got {s!r}')
    buf = np.frombuffer(data, np.uint8) if not isinstance(data, np.ndarray) else data
    image = cv2.imdecode(buf, _FLAGS[int(s)]) if buf.size else None
    if image is None:
        raise ImageDecodeError(f'JPEG ({buf.size} bytes) does not decode')
    return image


def decode_for_crop(data, camera, box, out_size, reduce=True):
    """Decode a JPEG frame of `camera` for a crop `box` shrunk to out_size = (W_out, H_out).

    -> (image (H', W', 3) uint8 BGR, 'bgr8', the camera of that image (reduced_camera),
    the box in its pixels (box / s), s). With reduce=False, or when the crop is not shrunk
    2x or more, s = 1 (a full decode). The heatmap camera of the crop,
    camera'.crop(box', out) equals camera.crop(box, out) (see the module docstring).
    Raises ImageDecodeError when the bytes are not a JPEG of camera's size or do not decode.
    """
    width, height = jpeg_size(data)
    if (width, height) != (camera.width, camera.height):
        raise ImageDecodeError(f'image is {width}x{height} but the camera is '
                               f'{camera.width}x{camera.height}')
    s = reduction_for(box, out_size) if reduce else 1
    image = decode_jpeg(data, s)
    expected = reduced_size(width, height, s)
    if (image.shape[1], image.shape[0]) != expected:     # never seen: libjpeg's rule
        raise ImageDecodeError(f'JPEG decoded at 1/{s} is {image.shape[1]}x{image.shape[0]}, '
                               f'expected {expected[0]}x{expected[1]}')
    box = np.asarray(box, np.float64).reshape(4) / s
    return image, 'bgr8', reduced_camera(camera, s), box, s


def decode_views(views, out_size, threads=None, reduce=True):
    """Decode the JPEG views of one instant at their crops' scale (decode_for_crop), in
    parallel: the one decoding step of the detector node and `monet process`.

    views: sequence of (JPEG bytes, Camera, box); threads: a cores.ViewThreads (the
    Detector's view_threads; None = one after the other). -> a list in the same order, each
    decode_for_crop's (image, 'bgr8', camera, box, s) or the ImageDecodeError / ValueError
    it raised for that view (one bad view never costs the others). Bit-identical to
    sequential decodes (cv2.imdecode releases the GIL; each view is the same call)."""
    views = list(views)
    out = [None] * len(views)

    def one(i):
        data, camera, box = views[i]
        try:
            out[i] = decode_for_crop(data, camera, box, out_size, reduce)
        except ValueError as error:               # ImageDecodeError is a ValueError
            out[i] = error

    if threads is None:
        for i in range(len(views)):
            one(i)
    else:
        threads.run(one, len(views))
    return out
