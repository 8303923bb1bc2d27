"""Image / CompressedImage decoding against OpenCV and hand-built buffers."""
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from monet_ros.io.images import (
    ImageDecodeError,
    compressed_image_to_numpy,
    encode_compressed,
    image_fields,
    image_for_crop,
    image_to_numpy,
    raw_to_rgb8,
    to_rgb8,
    view_for_crop,
)


def smooth_rgb(h=48, w=64, seed=0):
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, (h // 8, w // 8, 3)).astype(np.uint8)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)


def msg_from(arr, encoding, step=None, bigendian=False):
    arr = np.ascontiguousarray(arr)
    h, w = arr.shape[:2]
    row = arr.reshape(h, -1).view(np.uint8)
    step = row.shape[1] if step is None else step
    padded = np.zeros((h, step), np.uint8)
    padded[:, :row.shape[1]] = row
    return SimpleNamespace(height=h, width=w, encoding=encoding, is_bigendian=int(bigendian),
                           step=step, data=padded.tobytes())


def test_rgb_bgr_mono_round_trip():
    rgb = smooth_rgb()
    for enc in ('rgb8', 'bgr8'):
        f = image_fields(rgb, enc)
        got = image_to_numpy(SimpleNamespace(**f))
        np.testing.assert_array_equal(got, rgb)
    # bgr8 stores the channels reversed
    f = image_fields(rgb, 'bgr8')
    np.testing.assert_array_equal(np.frombuffer(f['data'], np.uint8).reshape(rgb.shape),
                                  rgb[:, :, ::-1])
    mono = rgb[:, :, 0]
    np.testing.assert_array_equal(image_to_numpy(SimpleNamespace(**image_fields(mono, 'mono8'))),
                                  mono)
    depth = (rgb[:, :, 1].astype(np.uint16) * 257)
    got = image_to_numpy(SimpleNamespace(**image_fields(depth, 'mono16')))
    assert got.dtype == np.uint16
    np.testing.assert_array_equal(got, depth)
    flt = rgb[:, :, 2].astype(np.float32) / 7.0
    got = image_to_numpy(SimpleNamespace(**image_fields(flt, '32FC1')))
    assert got.dtype == np.float32 and got.shape == flt.shape
    np.testing.assert_array_equal(got, flt)


def test_row_padding_and_big_endian():
    rgb = smooth_rgb(10, 13)
    got = image_to_numpy(msg_from(rgb, 'rgb8', step=13 * 3 + 5))
    np.testing.assert_array_equal(got, rgb)
    depth = np.arange(10 * 13, dtype=np.uint16).reshape(10, 13) * 300
    got = image_to_numpy(msg_from(depth.astype('>u2'), 'mono16', step=13 * 2 + 6,
                                  bigendian=True))
    np.testing.assert_array_equal(got, depth)
    bgra = np.dstack([rgb[:, :, ::-1], np.full((10, 13), 255, np.uint8)])
    np.testing.assert_array_equal(image_to_numpy(msg_from(bgra, 'bgra8')), rgb)


@pytest.mark.parametrize('pattern', ['rggb', 'bggr', 'gbrg', 'grbg'])
def test_bayer_demosaic_matches_source(pattern):
    """Build a mosaic from a smooth rgb image with the ROS pattern (top-left 2x2), decode:
    the demosaiced image is close to the source, and the sampled pixels are exact."""
    rgb = smooth_rgb(64, 80, seed=3)
    idx = {'r': 0, 'g': 1, 'b': 2}
    mosaic = np.zeros(rgb.shape[:2], np.uint8)
    for k, ch in enumerate(pattern):
        dy, dx = divmod(k, 2)
        mosaic[dy::2, dx::2] = rgb[dy::2, dx::2, idx[ch]]
    got = image_to_numpy(msg_from(mosaic, f'bayer_{pattern}8'))
    assert got.shape == rgb.shape
    inner = (slice(4, -4), slice(4, -4))
    err = np.abs(got[inner].astype(int) - rgb[inner].astype(int)).mean()
    assert err < 6.0, err
    for k, ch in enumerate(pattern):       # measured samples survive demosaicing
        dy, dx = divmod(k, 2)
        sampled = got[dy::2, dx::2, idx[ch]][2:-2, 2:-2].astype(int)
        truth = rgb[dy::2, dx::2, idx[ch]][2:-2, 2:-2].astype(int)
        assert np.abs(sampled - truth).max() <= 1
    # a wrong pattern gives a clearly worse image
    wrong = {'rggb': 'bggr', 'bggr': 'rggb', 'gbrg': 'grbg', 'grbg': 'gbrg'}[pattern]
    bad = image_to_numpy(msg_from(mosaic, f'bayer_{wrong}8'))
    assert np.abs(bad[inner].astype(int) - rgb[inner].astype(int)).mean() > 2 * err


def test_compressed_jpeg_png():
    rgb = smooth_rgb(40, 56)
    fmt, data = encode_compressed(rgb, 'png')
    got = compressed_image_to_numpy(SimpleNamespace(format=fmt, data=data.tobytes()))
    np.testing.assert_array_equal(got, rgb)
    fmt, data = encode_compressed(rgb, 'jpeg', quality=95)
    got = compressed_image_to_numpy(SimpleNamespace(format='rgb8; jpeg compressed bgr8',
                                                    data=data))
    assert got.shape == rgb.shape
    assert np.abs(got.astype(int) - rgb.astype(int)).mean() < 3
    # channel order: a pure red image stays red
    red = np.zeros((16, 16, 3), np.uint8)
    red[..., 0] = 255
    got = compressed_image_to_numpy(SimpleNamespace(format='png',
                                                    data=encode_compressed(red, 'png')[1]))
    np.testing.assert_array_equal(got, red)


def test_bad_inputs_raise_named_errors():
    with pytest.raises(ImageDecodeError, match='unsupported image encoding'):
        image_to_numpy(SimpleNamespace(height=2, width=2, encoding='weird9', is_bigendian=0,
                                       step=2, data=b'\0' * 4))
    with pytest.raises(ImageDecodeError, match='expected 12'):
        image_to_numpy(SimpleNamespace(height=2, width=2, encoding='rgb8', is_bigendian=0,
                                       step=6, data=b'\0' * 11))
    with pytest.raises(ImageDecodeError, match='does not decode'):
        compressed_image_to_numpy(SimpleNamespace(format='jpeg', data=b'not a jpeg'))
    with pytest.raises(ValueError, match='needs 3 channel'):
        image_fields(np.zeros((4, 4), np.uint8), 'rgb8')


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'rgba8', 'bgra8', 'mono8', '8UC1',
                                      '8UC3', 'bayer_rggb8'])
def test_image_for_crop_keeps_the_buffer_and_converts_like_image_to_numpy(encoding):
    """A crop taken from the raw buffer and converted (raw_to_rgb8) equals the same crop of
    the fully decoded image; the raw buffer is the message data (no copy)."""
    rgb = smooth_rgb()
    source = rgb[..., 0] if encoding.lower() in ('mono8', '8uc1', 'bayer_rggb8') else rgb
    if encoding in ('rgba8', 'bgra8'):
        source = np.concatenate([rgb, np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=2)
        if encoding == 'bgra8':
            source = source[..., [2, 1, 0, 3]]
    elif encoding == 'bgr8':
        source = rgb[..., ::-1]
    msg = msg_from(source, encoding, step=source[0].size + 8)  # padded rows
    raw, layout = image_for_crop(msg)
    decoded = image_to_numpy(msg)
    if decoded.ndim == 2:
        decoded = np.repeat(decoded[..., None], 3, axis=2)
    crop = (slice(5, 30), slice(7, 50))
    np.testing.assert_array_equal(raw_to_rgb8(raw[crop], layout), decoded[crop])
    if not encoding.startswith('bayer'):
        assert np.shares_memory(raw, np.frombuffer(msg.data, np.uint8))
    else:
        assert layout == 'rgb8'
    with pytest.raises(ImageDecodeError, match='unsupported layout'):
        raw_to_rgb8(raw, 'yuv422')


@pytest.mark.parametrize('kind', ['bgr8 image', 'mono16 image', 'png', 'grey png', 'bgra png',
                                  'jpeg', 'png16'])
def test_view_for_crop_converts_only_what_is_not_8_bit(kind):
    """view_for_crop (the detector node's and `monet process`'s input rule): 8-bit pixels
    stay as they come (an Image: its buffer; a CompressedImage: OpenCV's BGR decode), so
    only the crop is converted (raw_to_rgb8); its RGB is what the full decode gives."""
    rgb = smooth_rgb()
    if kind == 'bgr8 image':
        msg = msg_from(rgb[..., ::-1], 'bgr8')
        expected, layout = rgb, 'bgr8'
    elif kind == 'mono16 image':
        msg = msg_from((rgb[..., 0].astype(np.uint16) * 200), 'mono16')
        expected, layout = to_rgb8(image_to_numpy(msg)), 'rgb8'
    else:
        source = {'grey png': rgb[..., 0], 'png16': rgb.astype(np.uint16) * 100,
                  'bgra png': np.concatenate([rgb[..., ::-1], rgb[..., :1]], axis=2)}.get(
                      kind, rgb[..., ::-1])
        ext = '.jpg' if kind == 'jpeg' else '.png'
        msg = SimpleNamespace(format=ext[1:], data=cv2.imencode(ext, source)[1].tobytes())
        expected = to_rgb8(compressed_image_to_numpy(msg))
        layout = {'png': 'bgr8', 'jpeg': 'bgr8', 'grey png': 'mono8', 'bgra png': 'bgra8',
                  'png16': 'rgb8'}[kind]
    image, got_layout = view_for_crop(msg)
    assert got_layout == layout and image.dtype == np.uint8 and image.ndim == 3
    np.testing.assert_array_equal(raw_to_rgb8(image, got_layout), expected)
    if kind == 'bgr8 image':
        assert np.shares_memory(image, np.frombuffer(msg.data, np.uint8))
    with pytest.raises(ImageDecodeError, match='does not decode'):
        view_for_crop(SimpleNamespace(format='png', data=b'not a png'))
