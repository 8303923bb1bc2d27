"""Board detection on honest renderings of a known camera (truth: the projected corners)."""
import cv2
from helpers.boards import projected_corners, render_view
import numpy as np
import pytest

from monet_ros.calibration.board import Board
from monet_ros.calibration.detect import BoardDetector, detect_frames
from monet_ros.geometry import Camera

CAMERA = Camera(name='c', K=np.array([[700.0, 0, 399.5], [0, 700.0, 299.5], [0, 0, 1]]),
                dist=np.array([-0.1, 0.02, 0.0, 0.0, 0.0]), R=np.eye(3), t=np.zeros(3),
                width=800, height=600)


def pose(board, tilt_deg, distance):
    """Board -> camera: the board's middle on the optical axis, tilted about x."""
    columns, rows = board.corner_grid
    middle = np.array([(columns + 1) / 2.0, (rows + 1) / 2.0, 0.0]) * board.square_length
    if board.type == 'checkerboard':
        middle = np.array([(columns - 1) / 2.0, (rows - 1) / 2.0, 0.0]) * board.square_length
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.array([np.radians(tilt_deg), 0.2, 0.1]))[0]
    T[:3, 3] = -T[:3, :3] @ middle + [0.01, -0.02, distance]
    return T


CHARUCO = Board(8, 11, 0.02, 'charuco', 0.015, 4, 1000)
CHECKER = Board(7, 10, 0.02, 'checkerboard')


@pytest.fixture(scope='module')
def views():
    rng = np.random.default_rng(3)
    return {(b.type, tilt): render_view(b, CAMERA, pose(b, tilt, 0.45), rng=rng)
            for b in (CHARUCO, CHECKER) for tilt in (0.0, 35.0)}


@pytest.mark.parametrize('board', [CHARUCO, CHECKER], ids=['charuco', 'checkerboard'])
@pytest.mark.parametrize('tilt', [0.0, 35.0])
def test_corners_match_the_projection(views, board, tilt):
    ids, corners = BoardDetector(board).detect(views[board.type, tilt])
    truth = projected_corners(board, CAMERA, pose(board, tilt, 0.45))
    assert len(ids) == board.num_corners          # the whole board is in view
    errors = np.linalg.norm(corners - truth[ids], axis=1)
    assert errors.mean() < 0.15 and errors.max() < 0.5, (errors.mean(), errors.max())


def test_inverted_board_is_found(views):
    image = views['charuco', 35.0]
    inverted = 255 - image                          # white markers on black
    detector = BoardDetector(CHARUCO)
    assert detector._once(inverted) is None         # the plain detector misses it
    ids, corners = detector.detect(inverted)
    ids0, corners0 = detector.detect(image)
    assert len(ids) >= 60
    common, a, b = np.intersect1d(ids, ids0, return_indices=True)
    assert len(common) >= 60
    assert np.abs(corners[a] - corners0[b]).max() < 0.3


def test_frames_without_a_board_are_counted(views):
    blank = np.full((600, 800), 150, np.uint8)
    frames = [views['charuco', 0.0], blank, views['charuco', 35.0], blank[..., None]
              .repeat(3, axis=2)]
    result = detect_frames('c', frames, CHARUCO, progress=False)
    assert result.no_board == [1, 3]
    assert result.frames_with_board == 2
    assert result.corners.shape == (4, 70, 2)
    assert np.isnan(result.corners[[1, 3]]).all()
    assert result.size == (800, 600)


def test_frame_size_change_and_no_frames_are_errors(views):
    with pytest.raises(ValueError, match="camera 'c': frame 1 is 400x300"):
        detect_frames('c', [views['charuco', 0.0], np.zeros((300, 400), np.uint8)],
                      CHARUCO, progress=False)
    with pytest.raises(ValueError, match="camera 'c': no frame"):
        detect_frames('c', [], CHARUCO, progress=False)


def test_mirrored_board_is_found_apart_and_unreadable_frames_are_counted(views):
    """Issue 37: a board seen through a mirror (left-right) is recognised as such, never
    used; a frame the source could not read (None) is unreadable, not 'no board'."""
    image = views['charuco', 35.0]
    detector = BoardDetector(CHARUCO)
    assert detector.detect_view(image)[1] == 'plain'
    assert detector.detect_view(255 - image)[1] == 'inverted'
    mirrored = np.ascontiguousarray(image[:, ::-1])
    assert detector.detect_view(mirrored) == (None, 'mirrored')
    assert detector.detect(mirrored) is None
    result = detect_frames('c', [None, image, mirrored, None], CHARUCO, progress=False)
    assert result.unreadable == [0, 3] and result.mirrored == [2]
    assert result.no_board == [0, 2, 3] and result.frames_with_board == 1
    assert result.size == (800, 600) and result.hint == ''
    with pytest.raises(ValueError, match=r"camera 'c': no frame .* \(2 unreadable\)"):
        detect_frames('c', [None, None], CHARUCO, progress=False)


def test_markers_that_do_not_fit_the_board_are_diagnosed(views):
    from dataclasses import replace
    image = views['charuco', 0.0]
    swapped = replace(CHARUCO, board_x=11, board_y=8)
    result = detect_frames('c', [image], swapped, progress=False)
    assert result.frames_with_board == 0
    assert result.hint.startswith('44 DICT_4X4_1000 markers found (ids 0-43) that do not fit '
                                  'a 11 x 8 board: check board_x 11, board_y 8 (swapped?)')
    bits = detect_frames('c', [image], replace(CHARUCO, marker_bits=6), progress=False)
    assert 'check marker_bits (6; these are 4)' in bits.hint
    blank = np.full((600, 800), 150, np.uint8)
    assert detect_frames('c', [blank], CHARUCO, progress=False).hint == ''
