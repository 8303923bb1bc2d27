"""sensor_msgs Image / CompressedImage <-> numpy, without cv_bridge and without rclpy.

Works on any object with the message's attribute names: rclpy messages, messages decoded
from bags by mcap_ros2 or rosbags. Encodings follow sensor_msgs/image_encodings.
"""
import cv2
import numpy as np


class ImageDecodeError(ValueError):
    """An image message that cannot be turned into an array (the message names the cause)."""


# encoding -> (numpy dtype, channels)
_PLAIN = {
    'rgb8': (np.uint8, 3), 'bgr8': (np.uint8, 3), 'rgba8': (np.uint8, 4),
    'bgra8': (np.uint8, 4), 'mono8': (np.uint8, 1), 'mono16': (np.uint16, 1),
    'rgb16': (np.uint16, 3), 'bgr16': (np.uint16, 3),
}
_CV_DEPTH = {'8U': np.uint8, '8S': np.int8, '16U': np.uint16, '16S': np.int16,
             '32S': np.int32, '32F': np.float32, '64F': np.float64}
# ROS bayer pattern (top-left 2x2) -> OpenCV code (OpenCV names the pattern one pixel
# further in, as cv_bridge does: rggb -> BayerBG).
_BAYER = {'rggb': cv2.COLOR_BayerBG2RGB, 'bggr': cv2.COLOR_BayerRG2RGB,
          'gbrg': cv2.COLOR_BayerGR2RGB, 'grbg': cv2.COLOR_BayerGB2RGB}
_YUV = {'yuv422': cv2.COLOR_YUV2RGB_UYVY, 'uyvy': cv2.COLOR_YUV2RGB_UYVY,
        'yuv422_yuy2': cv2.COLOR_YUV2RGB_YUY2, 'yuyv': cv2.COLOR_YUV2RGB_YUY2}


def encoding_layout(encoding):
    """(dtype, channels) of a raw image encoding; ImageDecodeError when unknown.

    Bayer encodings are single-channel mosaics; yuv422 variants are 2 bytes per pixel.
    """
    enc = str(encoding).lower()
    if enc in _PLAIN:
        return _PLAIN[enc]
    if enc.startswith('bayer_') and enc[6:10] in _BAYER and enc[10:] in ('8', '16'):
        return (np.uint8 if enc[10:] == '8' else np.uint16), 1
    if enc in _YUV:
        return np.uint8, 2
    if 'c' in enc:
        depth, _, ch = enc.upper().partition('C')
        if depth in _CV_DEPTH and ch.isdigit() and int(ch) > 0:
            return _CV_DEPTH[depth], int(ch)
    raise ImageDecodeError(f'unsupported image encoding {encoding!r}')


def raw_image_array(msg):
    """The pixel buffer of an Image message as (H, W, ch) in its own encoding (no copy
    when possible); row padding (step) and big-endian data are handled."""
    dtype, ch = encoding_layout(msg.encoding)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    itemsize = np.dtype(dtype).itemsize
    row = w * ch * itemsize
    if step < row:
        raise ImageDecodeError(f'image step {step} < width*channels*bytes {row} '
                               f'({w}x{h} {msg.encoding})')
    buf = np.frombuffer(msg.data, np.uint8)
    if buf.size < step * h:
        raise ImageDecodeError(f'image data has {buf.size} bytes, expected {step * h} '
                               f'({w}x{h} {msg.encoding}, step {step})')
    rows = buf[:step * h].reshape(h, step)[:, :row]
    dt = np.dtype(dtype).newbyteorder('>' if msg.is_bigendian else '<')
    arr = rows.view(dt) if rows.flags.c_contiguous or itemsize == 1 else \
        np.ascontiguousarray(rows).view(dt)
    arr = arr.reshape(h, w, ch)
    if itemsize > 1 and msg.is_bigendian:
        arr = arr.astype(np.dtype(dtype))
    return arr


def image_to_numpy(msg):
    """Decode a sensor_msgs/Image.

    Returns (H, W, 3) uint8 rgb for colour encodings (rgb8, bgr8, rgba8, bgra8, bayer_*8,
    yuv422), (H, W, 3) uint16 rgb for rgb16/bgr16/bayer_*16, (H, W) for single-channel
    encodings (mono8, mono16, 8UC1, 16UC1, 32FC1, ...), (H, W, C) for other nC encodings
    (e.g. 32FC14 heatmaps). Raises ImageDecodeError on unknown encodings or short data.
    rgb8 / mono / float images are zero-copy views of the message data (read-only when the
    message came from a bag): copy before writing into them.
    """
    enc = str(msg.encoding).lower()
    arr = raw_image_array(msg)
    if enc.startswith('bayer_'):
        return cv2.cvtColor(np.ascontiguousarray(arr[:, :, 0]), _BAYER[enc[6:10]])
    if enc in _YUV:
        return cv2.cvtColor(np.ascontiguousarray(arr), _YUV[enc])
    if enc in ('rgb8', 'rgb16'):
        return arr
    if enc in ('bgr8', 'bgr16'):
        return arr[:, :, ::-1]
    if enc == 'rgba8':
        return arr[:, :, :3]
    if enc == 'bgra8':
        return arr[:, :, 2::-1]
    if arr.shape[2] == 1:
        return arr[:, :, 0]
    return arr


def compressed_image_to_numpy(msg):
    """Decode a sensor_msgs/CompressedImage (jpeg, png; image_transport formats such as
    'rgb8; jpeg compressed bgr8' too) -> (H, W, 3) uint8 rgb, or (H, W) for grey images
    (uint16 for 16-bit png). Raises ImageDecodeError when the data does not decode."""
    fmt = str(msg.format).lower()
    if 'compresseddepth' in fmt:
        raise ImageDecodeError(f'unsupported compressed image format {msg.format!r}')
    buf = np.frombuffer(msg.data, np.uint8)
    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
    if img is None:
        raise ImageDecodeError(f'compressed image ({msg.format!r}, {buf.size} bytes) '
                               'does not decode')
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    return img


def to_rgb8(image):
    """Any decoded image -> (H, W, 3) uint8 RGB, the detector's input.

    (H, W, 3) uint8 as is; grey (H, W) or (H, W, 1) repeated to 3 channels; 16-bit and
    other integer or float images (mono16, 16UC1, rgb16, 32FC1 ...) are stretched linearly
    from their own finite minimum..maximum to 0..255 (a 12-bit sensor in a 16-bit container
    stays visible; NaN becomes 0). Raises ImageDecodeError for other channel counts or
    empty images."""
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3) \
            or image.size == 0:
        raise ImageDecodeError(f'need a colour (H, W, 3) or grey (H, W) image, got '
                               f'{image.shape} {image.dtype}')
    if image.dtype != np.uint8:
        values = image.astype(np.float32)
        finite = np.isfinite(values)
        low = float(values[finite].min()) if finite.any() else 0.0
        high = float(values[finite].max()) if finite.any() else 0.0
        scale = 255.0 / (high - low) if high > low else 0.0
        values = np.where(finite, (values - low) * scale, 0.0)
        image = np.clip(values + 0.5, 0, 255).astype(np.uint8)
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    return image


def any_image_to_numpy(msg):
    """Image or CompressedImage (told apart by the `format` attribute) -> numpy."""
    if hasattr(msg, 'format') and not hasattr(msg, 'encoding'):
        return compressed_image_to_numpy(msg)
    return image_to_numpy(msg)


def image_fields(image, encoding='rgb8'):
    """Fields of a sensor_msgs/Image for an array (no header).

    image: (H, W, 3) rgb for rgb8/bgr8 (uint8) or rgb16/bgr16 (uint16); (H, W) or (H, W, 1)
    for mono8 / mono16 / 8UC1 / 16UC1 / 32FC1; (H, W, C) for nC encodings.
    Returns dict(height, width, encoding, is_bigendian, step, data (contiguous uint8 array)).
    """
    arr = np.asarray(image)
    dtype, ch = encoding_layout(encoding)
    enc = str(encoding).lower()
    if enc.startswith('bayer_') or enc in _YUV:
        raise ImageDecodeError(f'writing {encoding!r} images is not supported')
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3:
        raise ValueError(f'image must be (H, W) or (H, W, C), got shape {arr.shape}')
    if enc in ('bgr8', 'bgr16'):
        arr = arr[:, :, ::-1]
    elif enc == 'bgra8':
        arr = arr[:, :, [2, 1, 0, 3]]
    if arr.shape[2] != ch:
        raise ValueError(f'encoding {encoding!r} needs {ch} channel(s), image has shape '
                         f'{np.asarray(image).shape}')
    if arr.dtype != dtype:
        if np.issubdtype(dtype, np.integer) and not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(f'encoding {encoding!r} needs {np.dtype(dtype).name} data, '
                             f'got {arr.dtype}')
        arr = arr.astype(dtype)
    arr = np.ascontiguousarray(arr, dtype=np.dtype(dtype).newbyteorder('<'))
    h, w = arr.shape[:2]
    return dict(height=h, width=w, encoding=str(encoding), is_bigendian=0,
                step=w * ch * arr.itemsize, data=arr.reshape(-1).view(np.uint8))


def encode_compressed(image, fmt='jpeg', quality=90):
    """(H, W, 3) rgb uint8 or (H, W) grey -> (format string, encoded bytes) for a
    sensor_msgs/CompressedImage (OpenCV's encoder; png keeps the array exactly)."""
    arr = np.asarray(image)
    if fmt not in ('jpeg', 'png'):
        raise ValueError(f'compressed format must be jpeg or png, got {fmt!r}')
    if arr.ndim == 3 and arr.shape[2] == 3:
        arr = cv2.cvtColor(np.ascontiguousarray(arr), cv2.COLOR_RGB2BGR)
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if fmt == 'jpeg' else []
    ok, buf = cv2.imencode('.jpg' if fmt == 'jpeg' else '.png', arr, params)
    if not ok:
        raise ValueError(f'OpenCV could not encode a {arr.shape} {arr.dtype} image as {fmt}')
    return fmt, buf.reshape(-1)


# 8-bit layouts a detector can crop straight from the message buffer (channels per pixel)
CROPPABLE = {'rgb8': 3, 'bgr8': 3, 'rgba8': 4, 'bgra8': 4, 'mono8': 1, '8uc1': 1, '8uc3': 3}


def image_for_crop(msg):
    """(array, layout) of an Image message for cropping: the raw buffer (H, W, ch), no copy,
    when its encoding is one of CROPPABLE (layout = that encoding, lower case; 8UC3 is read
    as rgb8 and 8UC1 as mono8, as image_to_numpy does), else the decoded (H, W, 3) rgb image and
    'rgb8'. Convert the crop with raw_to_rgb8(crop, layout): no full-frame colour conversion.
    Raises ImageDecodeError like image_to_numpy."""
    enc = str(msg.encoding).lower()
    if enc in CROPPABLE:
        layout = {'8uc1': 'mono8', '8uc3': 'rgb8'}.get(enc, enc)
        return raw_image_array(msg), layout
    return image_to_numpy(msg), 'rgb8'


def view_for_crop(msg):
    """(array (H, W, ch) uint8, layout) of an Image or CompressedImage message for the
    detector's crop, converted to RGB only after cropping (raw_to_rgb8(crop, layout)): the
    one rule of the detector node and `monet process` for views not decoded at the crop's
    scale (io.jpeg_scale).

    An Image in a CROPPABLE encoding is its message buffer (image_for_crop, no copy); a
    CompressedImage is OpenCV's decode as it comes (8-bit: 'bgr8', 'bgra8' or 'mono8', no
    full-frame colour conversion); anything else (16-bit, float, bayer, yuv) is converted to
    rgb8 (to_rgb8). Grey images are (H, W, 1) 'mono8'. Raises ImageDecodeError when the
    message does not decode."""
    if hasattr(msg, 'format') and not hasattr(msg, 'encoding'):
        if 'compresseddepth' in str(msg.format).lower():
            raise ImageDecodeError(f'unsupported compressed image format {msg.format!r}')
        buf = np.frombuffer(msg.data, np.uint8)
        image = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
        if image is None:
            raise ImageDecodeError(f'compressed image ({msg.format!r}, {buf.size} bytes) '
                                   'does not decode')
        if image.ndim == 2:
            image = image[..., None]
        layout = {1: 'mono8', 3: 'bgr8', 4: 'bgra8'}.get(image.shape[2])
        if image.dtype != np.uint8 or layout is None:
            image, layout = to_rgb8(compressed_image_to_numpy(msg)), 'rgb8'
    else:
        image, layout = image_for_crop(msg)
        if layout == 'rgb8' and (image.dtype != np.uint8 or image.ndim != 3):
            image = to_rgb8(image)        # grey / 16-bit / float -> the network's rgb8
    if image.ndim == 2:
        image, layout = image[..., None], 'mono8'
    return image, layout


def raw_to_rgb8(array, layout):
    """(H, W, ch) uint8 pixels in `layout` (a CROPPABLE encoding) -> (H, W, 3) uint8 rgb."""
    arr = np.asarray(array)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if layout == 'rgb8':
        return arr
    if layout == 'bgr8':
        return arr[:, :, ::-1]
    if layout == 'rgba8':
        return arr[:, :, :3]
    if layout == 'bgra8':
        return arr[:, :, 2::-1]
    if layout == 'mono8':
        return np.repeat(arr[:, :, :1], 3, axis=2)
    raise ImageDecodeError(f'raw_to_rgb8: unsupported layout {layout!r}')
