"""Image folders as frame sources: a truncated JPEG is named (issue 37), never read as the
grey-filled image OpenCV makes of it."""
import cv2
import numpy as np
import pytest

from monet_ros.io.frame_sources import FrameSource, FrameSourceError


@pytest.fixture
def folder(tmp_path):
    rng = np.random.default_rng(0)
    for k in range(3):
        image = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
        cv2.imwrite(str(tmp_path / f'frame_{k:03d}.jpg'), image)
    broken = tmp_path / 'frame_001.jpg'
    data = broken.read_bytes()
    broken.write_bytes(data[:len(data) * 2 // 3])
    assert cv2.imread(str(broken)) is not None        # OpenCV decodes it anyway
    return tmp_path, broken


def test_a_truncated_jpeg_is_an_error_naming_it(folder):
    path, broken = folder
    source = FrameSource(path)
    assert source.read()[1].shape == (48, 64, 3)
    with pytest.raises(FrameSourceError, match=f'{broken}: truncated JPEG'):
        source.read()


def test_skip_unreadable_gives_none_and_says_why(folder):
    path, broken = folder
    source = FrameSource(path, skip_unreadable=True)
    frames = [source.read() for _ in range(3)]
    assert [key for key, _ in frames] == [0, 1, 2]
    assert frames[1][1] is None and frames[0][1] is not None and frames[2][1] is not None
    assert source.unreadable == [f'{broken}: truncated JPEG (no end-of-image marker)']
    assert source.read() is None


def test_a_first_image_unreadable_takes_the_size_from_the_next(folder):
    path, _ = folder
    first = path / 'frame_000.jpg'
    data = first.read_bytes()
    first.write_bytes(data[:len(data) * 2 // 3])
    with pytest.raises(FrameSourceError, match='frame_000.jpg: truncated JPEG'):
        FrameSource(path)
    source = FrameSource(path, skip_unreadable=True)
    assert (source.width, source.height) == (64, 48)
    assert source.read()[1] is None
