"""JPEG frames decoded at the crop's scale (io.jpeg_scale): the reduced image's camera is
exact (a blob drawn at a projected 3D point lands where the reduced K projects it), and a
trained detector finds the same peaks in a reduced decode as in a full one."""
import cv2
from helpers.blob_net import NAMES, SIZE, blob_images, train_blob_net
from helpers.rigs import random_camera
import numpy as np
import pytest

from monet_ros.cores import ViewThreads
from monet_ros.geometry import Camera
from monet_ros.io.images import ImageDecodeError
from monet_ros.io.jpeg_scale import (
    decode_for_crop,
    decode_jpeg,
    decode_views,
    jpeg_size,
    reduced_camera,
    reduced_size,
    reduction_for,
)
from monet_ros.models.detector import Detector
from monet_ros.models.heatmaps import decode_heatmaps

WIDTH, HEIGHT = 645, 483        # not multiples of 8: libjpeg's last block is partial


def jpeg(image, quality=95, **params):
    flags = [cv2.IMWRITE_JPEG_QUALITY, quality]
    for key, value in params.items():
        flags += [getattr(cv2, key), value]
    ok, data = cv2.imencode('.jpg', image, flags)
    assert ok
    return data.tobytes()


def centroid(image, background):
    """Intensity-weighted centroid (u, v) of image - background (pixel-centre convention)."""
    mass = image.astype(np.float64).mean(axis=2) - background
    mass[mass < 3.0] = 0.0
    v, u = np.mgrid[0:mass.shape[0], 0:mass.shape[1]]
    return np.array([(mass * u).sum(), (mass * v).sum()]) / mass.sum()


@pytest.mark.parametrize('s', [2, 4, 8])
def test_reduced_camera_projects_where_the_reduced_image_shows_a_point(s):
    rng = np.random.default_rng(s)
    camera = random_camera(rng, width=WIDTH, height=HEIGHT)
    X = rng.uniform(-0.2, 0.2, size=(1, 3))
    u, v = camera.project(X)[0]                 # full-frame pixels, with distortion
    assert 100 < u < WIDTH - 100 and 100 < v < HEIGHT - 100
    yy, xx = np.mgrid[0:HEIGHT, 0:WIDTH]
    blob = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 12.0 ** 2))
    frame = np.repeat(np.clip(60 + 180 * blob, 0, 255).astype(np.uint8)[..., None], 3, 2)
    data = jpeg(frame)
    reduced = decode_jpeg(data, s)
    assert (reduced.shape[1], reduced.shape[0]) == reduced_size(WIDTH, HEIGHT, s) == \
        (-(-WIDTH // s), -(-HEIGHT // s))
    small = reduced_camera(camera, s)
    assert (small.width, small.height) == (reduced.shape[1], reduced.shape[0])
    # independent: the reduced pixel of full pixel x is (x + 0.5) / s - 0.5
    expected = (np.array([u, v]) + 0.5) / s - 0.5
    np.testing.assert_allclose(small.project(X)[0], expected, atol=1e-9)
    seen = centroid(reduced, 60.0)
    # measured: within 0.005 reduced px; the naive x / s would be (1 - 1/s) / 2 >= 0.25 off
    assert np.abs(seen - expected).max() < 0.03, (seen, expected)
    assert np.abs(seen - np.array([u, v]) / s).max() > 0.2
    np.testing.assert_allclose(small.dist, camera.dist)
    np.testing.assert_allclose(small.P, small.K @ np.hstack([camera.R, camera.t[:, None]]))


def test_the_heatmap_camera_is_the_full_decodes():
    rng = np.random.default_rng(0)
    camera = random_camera(rng, width=WIDTH, height=HEIGHT)
    frame = np.full((HEIGHT, WIDTH, 3), 90, np.uint8)
    for box in ([10.0, 20.5, 600.0, 470.0], [-40.0, -30.0, 700.0, 520.0], [0, 0, 200, 150]):
        image, layout, small, small_box, s = decode_for_crop(jpeg(frame), camera, box, (64, 48))
        assert layout == 'bgr8' and s == reduction_for(box, (64, 48)) and s > 1
        assert image.shape[:2] == (small.height, small.width)
        np.testing.assert_allclose(small.crop(small_box, (16, 12)).K,
                                   camera.crop(box, (16, 12)).K, rtol=0, atol=1e-9)


def test_reduction_is_the_largest_that_keeps_the_crop_at_least_the_input():
    out = (64, 48)
    assert reduction_for((0, 0, 64, 48), out) == 1
    assert reduction_for((0, 0, 127.9, 200), out) == 1
    assert reduction_for((0, 0, 128, 96), out) == 2
    assert reduction_for((10, 10, 10 + 64 * 3.9, 10 + 48 * 5), out) == 2
    assert reduction_for((0, 0, 256, 192), out) == 4
    assert reduction_for((-100, -100, 5000, 4000), out) == 8
    assert reduction_for((0, 0, 32, 24), out) == 1          # enlarged: never reduced
    with pytest.raises(ValueError, match='x1 > x0'):
        reduction_for((5, 0, 5, 10), out)


def test_jpeg_size_reads_the_header_of_every_kind():
    frame = np.random.default_rng(0).integers(0, 255, (HEIGHT, WIDTH, 3), np.uint8)
    for data in (jpeg(frame), jpeg(frame, IMWRITE_JPEG_PROGRESSIVE=1),
                 jpeg(frame[..., 0]), jpeg(frame, IMWRITE_JPEG_SAMPLING_FACTOR=0x111111)):
        assert jpeg_size(data) == (WIDTH, HEIGHT)
        assert jpeg_size(np.frombuffer(data, np.uint8)) == (WIDTH, HEIGHT)
        for s in (1, 2, 4, 8):
            assert decode_jpeg(data, s).shape == reduced_size(WIDTH, HEIGHT, s)[::-1] + (3,)
    ok, png = cv2.imencode('.png', frame)
    with pytest.raises(ImageDecodeError, match='not a JPEG'):
        jpeg_size(png.tobytes())
    with pytest.raises(ImageDecodeError, match='no start-of-frame'):
        jpeg_size(jpeg(frame)[:20])
    with pytest.raises(ImageDecodeError, match='image is 645x483 but the camera is 640x483'):
        decode_for_crop(jpeg(frame), random_camera(np.random.default_rng(0), width=640,
                                                   height=HEIGHT), (0, 0, 640, 483), (64, 48))


@pytest.fixture(scope='module')
def trained():
    return train_blob_net()


@pytest.mark.parametrize('s', [2, 4, 8])
def test_reduced_decode_finds_the_full_decodes_peaks(trained, s):
    """Frames s times the network input, blobs s times as wide: the crop shrinks by s, so the
    frame is decoded at 1/s. Peaks of the two decodes, in heatmap pixels (1 heatmap px =
    4 s frame px)."""
    rng = np.random.default_rng(10 + s)
    size = SIZE * s
    images, centres = blob_images(rng, 6, size=size, sigma=2.5 * s, margin=8 * s)
    camera = Camera(name='cam', K=np.diag([500.0, 500.0, 1.0]), dist=np.zeros(5),
                    R=np.eye(3), t=np.zeros(3), width=size, height=size)
    detector = Detector(trained, {'keypoints': NAMES}, device='cpu', precision='float32')
    box = np.array([0.0, 0.0, size, size])
    data = [jpeg(cv2.cvtColor(image, cv2.COLOR_RGB2BGR), quality=90) for image in images]
    full = [cv2.cvtColor(cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_COLOR),
                         cv2.COLOR_BGR2RGB) for d in data]
    heat_full, cams_full = detector.predict(full, [camera] * len(full), [box] * len(full))
    reduced = [decode_for_crop(d, camera, box, (SIZE, SIZE)) for d in data]
    assert {r[4] for r in reduced} == {s}
    heat_small, cams_small = detector.predict([r[0] for r in reduced], [r[2] for r in reduced],
                                              np.stack([r[3] for r in reduced]),
                                              encodings=[r[1] for r in reduced])
    for a, b in zip(cams_full, cams_small):
        np.testing.assert_allclose(b.K, a.K, rtol=0, atol=1e-9)
    peaks_full = decode_heatmaps(heat_full)[0]
    peaks_small = decode_heatmaps(heat_small)[0]
    # the net finds the blobs in the full decode (else the comparison says nothing):
    # heatmap px = (frame px + 0.5) / (4 s) - 0.5
    truth = (centres + 0.5) / (4 * s) - 0.5
    assert np.median(np.linalg.norm(peaks_full - truth, axis=-1)) < 0.4
    shift = np.linalg.norm(peaks_small - peaks_full, axis=-1)
    # measured: median 0.003-0.006, largest 0.012 heatmap px (0.05-0.4 frame px)
    assert shift.max() < 0.05, shift


def calibration_jpegs(shared_data, n):
    """n real camera JPEGs (1280x1024 checkerboard frames of the sleap-anipose session)."""
    paths = sorted((shared_data / 'sleap_anipose_minimal_session').glob('*/calibration_images/'
                                                                         '*.jpg'))
    if len(paths) < n:
        pytest.skip(f'{len(paths)} calibration JPEGs in ../shared/data, need {n}')
    return [path.read_bytes() for path in paths[:n]]


@pytest.mark.parametrize('threads', [1, 2, 5])
def test_parallel_decode_is_bit_identical_to_sequential_cv2_decode(shared_data, threads):
    data = calibration_jpegs(shared_data, 7)
    camera = Camera(name='c', K=np.array([[1000.0, 0, 639.5], [0, 1000.0, 511.5], [0, 0, 1]]),
                    dist=np.zeros(5), R=np.eye(3), t=np.zeros(3), width=1280, height=1024)
    # crops shrunk 1x, 2x, 4x and 8x to a 128 px input: every reduction, full decode too
    boxes = [(0, 0, 1280, 1024), (100, 50, 356, 306), (0, 0, 160, 128), (10, 20, 650, 532),
             (400, 300, 912, 812), (0, 0, 1280, 1024), (600, 500, 700, 600)]
    views = [(d, camera, b) for d, b in zip(data, boxes)]
    views.insert(3, (data[0][:2000], camera, boxes[0]))     # a truncated JPEG: its own error
    views.insert(5, (b'not a jpeg', camera, boxes[0]))
    with ViewThreads(threads) as pool:
        results = decode_views(views, (128, 128), pool)
        again = decode_views(views, (128, 128), pool)          # the pool is reused
    assert pool.threads == threads and len(results) == len(views)
    flags = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2,
             4: cv2.IMREAD_REDUCED_COLOR_4, 8: cv2.IMREAD_REDUCED_COLOR_8}
    seen, failed = set(), 0
    for (data_i, camera_i, box), result, second in zip(views, results, again):
        try:                                     # the same view decoded sequentially
            expected = decode_for_crop(data_i, camera_i, box, (128, 128))
        except ImageDecodeError as error:        # a bad view: its own error, in its place
            assert type(result) is ImageDecodeError and str(result) == str(error)
            failed += 1
            continue
        image, layout, small, small_box, s = result
        seen.add(s)
        reference = cv2.imdecode(np.frombuffer(data_i, np.uint8), flags[s])
        assert layout == 'bgr8' and image.dtype == reference.dtype
        assert np.array_equal(image, reference) and np.array_equal(second[0], reference)
        assert s == expected[4] and np.array_equal(small.K, expected[2].K)
        np.testing.assert_array_equal(small_box, expected[3])
    assert failed == 2
    assert seen == {1, 2, 4, 8}
    assert decode_views([], (128, 128), ViewThreads(2)) == []
