"""Board descriptions: TOML parsing, validation naming the field, geometry against OpenCV."""
import numpy as np
import pytest

from monet_ros.calibration.board import Board, BoardError, board_from_mapping, load_board

CHARUCO = {'board_x': 8, 'board_y': 11, 'square_length': 24.0, 'marker_length': 18.75,
           'marker_bits': 4, 'dict_size': 1000}


def test_sleap_anipose_board_files(shared_data):
    session = shared_data / 'sleap_anipose_minimal_session'
    board = load_board(session / 'board.toml')
    assert (board.type, board.board_x, board.board_y, board.square_length,
            board.marker_length, board.marker_bits, board.dict_size) == (
        'charuco', 8, 11, 24.0, 18.75, 4, 1000)
    assert board.num_corners == 70
    checker = load_board(session / 'board_checker.toml')
    assert checker.type == 'checkerboard' and checker.corner_grid == (8, 11)


def test_charuco_corners_are_opencvs():
    board = board_from_mapping(CHARUCO)
    reference = np.asarray(board.opencv_board().getChessboardCorners())
    np.testing.assert_allclose(board.object_points, reference)


def test_adjacent_pairs_are_one_square_apart():
    board = board_from_mapping(CHARUCO)
    pairs = board.adjacent_pairs()
    columns, rows = board.corner_grid
    assert len(pairs) == (columns - 1) * rows + columns * (rows - 1)
    d = np.linalg.norm(board.object_points[pairs[:, 0]] - board.object_points[pairs[:, 1]],
                       axis=1)
    np.testing.assert_allclose(d, 24.0)


@pytest.mark.parametrize('change, field', [
    ({'board_x': 1}, 'board_x'), ({'board_y': 2.5}, 'board_y'), ({'board_x': 1000}, 'board_x'),
    ({'square_length': -1.0}, 'square_length'), ({'square_length': float('nan')},
                                                 'square_length'),
    ({'marker_length': 30.0}, 'marker_length'), ({'marker_bits': 3}, 'marker_bits'),
    ({'dict_size': 64}, 'dict_size'), ({'board_x': 20, 'board_y': 20, 'dict_size': 50},
                                       'dict_size'),
    ({'type': 'circles'}, 'type'), ({'sqaure_length': 3}, 'sqaure_length'),
    ({'board_x': True}, 'board_x'), ({'square_length': '24'}, 'square_length'),
])
def test_impossible_values_name_the_field(tmp_path, change, field):
    path = tmp_path / 'board.toml'
    values = {**CHARUCO, **change}
    path.write_text('\n'.join(f'{k} = {v!r}'.replace("'", '"').replace('nan', 'nan')
                              for k, v in values.items()).replace('True', 'true') + '\n')
    with pytest.raises(BoardError) as info:
        load_board(path)
    assert info.value.field == field
    message = str(info.value)
    assert '\n' not in message and str(path) in message and repr(field) in message


def test_missing_and_unreadable(tmp_path):
    with pytest.raises(BoardError, match="'square_length': missing"):
        board_from_mapping({'board_x': 8, 'board_y': 11})
    with pytest.raises(BoardError, match="'marker_bits': missing"):
        board_from_mapping({'board_x': 8, 'board_y': 11, 'square_length': 1.0,
                            'marker_length': 0.5})
    bad = tmp_path / 'bad.toml'
    bad.write_text('board_x = [')
    with pytest.raises(BoardError, match='not valid TOML'):
        load_board(bad)
    with pytest.raises(BoardError, match='cannot read'):
        load_board(tmp_path / 'absent.toml')


def test_board_is_frozen():
    board = Board(7, 10, 0.03, 'checkerboard')
    with pytest.raises(AttributeError):
        board.board_x = 3
    assert board.num_corners == 70
