"""Calibration boards: ChArUco and checkerboard descriptions, validated (no ROS).

The TOML form is anipose / sleap-anipose's board file::

    board_x = 8            # squares along x (ChArUco); inner corners along x (checkerboard)
    board_y = 11
    square_length = 24.0   # any unit (mm, m): the calibration's translations are in it
    marker_length = 18.75  # ChArUco only, same unit, < square_length
    marker_bits = 4        # ChArUco only: 4, 5, 6 or 7 (OpenCV DICT_{b}X{b}_{n})
    dict_size = 1000       # ChArUco only: 50, 100, 250 or 1000
    type = "charuco"       # optional: charuco (default when marker_length is given) or
                           # checkerboard

Checkerboard sizes follow aniposelib / OpenCV's findChessboardCorners: board_x x board_y
inner corners. A ChArUco board of board_x x board_y squares has (board_x - 1) x
(board_y - 1) inner corners, numbered row by row as OpenCV's CharucoBoard numbers them.
"""
from dataclasses import dataclass
import math
from pathlib import Path
import tomllib

import numpy as np

BOARD_TYPES = ('charuco', 'checkerboard')
MARKER_BITS = (4, 5, 6, 7)
DICT_SIZES = (50, 100, 250, 1000)
MAX_SQUARES = 100           # per side: a typo such as 800 would make a 640,000-corner board
KEYS = ('type', 'board_x', 'board_y', 'square_length', 'marker_length', 'marker_bits',
        'dict_size')


class BoardError(ValueError):
    """A board description is invalid; the message names the file (if any) and the field."""

    def __init__(self, field_name, message, path=None):
        self.field = field_name
        self.path = path
        self.message = message
        where = f'{path}: ' if path else ''
        super().__init__(f'{where}board field {field_name!r}: {message}')

    def __reduce__(self):
        # raised in a worker process: it must unpickle in the parent
        return type(self), (self.field, self.message, self.path)


def _integer(value):
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


@dataclass(frozen=True)
class Board:
    """A planar calibration target. Lengths in the board's unit (mm or m), kept as is.

    type: 'charuco' or 'checkerboard'. board_x / board_y: squares (ChArUco, >= 2 each) or
    inner corners (checkerboard, >= 2 each), at most MAX_SQUARES. square_length > 0;
    marker_length in (0, square_length) for ChArUco. marker_bits / dict_size: the OpenCV
    predefined dictionary DICT_{bits}X{bits}_{size}, which must hold the board's markers.
    Raises BoardError naming the field.
    """

    board_x: int
    board_y: int
    square_length: float
    type: str = 'charuco'
    marker_length: float = 0.0
    marker_bits: int = 4
    dict_size: int = 50

    def __post_init__(self):
        if self.type not in BOARD_TYPES:
            raise BoardError('type', f'must be one of {", ".join(BOARD_TYPES)}, got '
                             f'{self.type!r}')
        for key in ('board_x', 'board_y'):
            value = getattr(self, key)
            if not _integer(value):
                raise BoardError(key, f'must be an integer, got {value!r}')
            if not 2 <= value <= MAX_SQUARES:
                raise BoardError(key, f'must be in 2..{MAX_SQUARES}, got {value}')
        for key in ('square_length', 'marker_length'):
            value = getattr(self, key)
            if not isinstance(value, (int, float, np.number)) or isinstance(value, bool) \
                    or not math.isfinite(value):
                raise BoardError(key, f'must be a finite number, got {value!r}')
            object.__setattr__(self, key, float(value))
        if not self.square_length > 0:
            raise BoardError('square_length', f'must be positive, got {self.square_length}')
        if self.type == 'charuco':
            if not 0 < self.marker_length < self.square_length:
                raise BoardError('marker_length', 'must be positive and smaller than '
                                 f'square_length ({self.square_length}), got '
                                 f'{self.marker_length}')
            if self.marker_bits not in MARKER_BITS or not _integer(self.marker_bits):
                raise BoardError('marker_bits', f'must be one of {MARKER_BITS}, got '
                                 f'{self.marker_bits!r}')
            if self.dict_size not in DICT_SIZES or not _integer(self.dict_size):
                raise BoardError('dict_size', f'must be one of {DICT_SIZES}, got '
                                 f'{self.dict_size!r}')
            markers = self.board_x * self.board_y // 2
            if markers > self.dict_size:
                raise BoardError('dict_size', f'a {self.board_x} x {self.board_y} board has '
                                 f"{markers} markers, more than the dictionary's "
                                 f'{self.dict_size}')

    @property
    def corner_grid(self):
        """(columns, rows) of the board's inner-corner grid."""
        if self.type == 'charuco':
            return self.board_x - 1, self.board_y - 1
        return self.board_x, self.board_y

    @property
    def num_corners(self):
        columns, rows = self.corner_grid
        return columns * rows

    @property
    def object_points(self):
        """(N, 3) corner positions on the board plane z = 0, board units, row by row
        (corner id = row * columns + column; OpenCV's CharucoBoard.getChessboardCorners
        order for ChArUco)."""
        columns, rows = self.corner_grid
        col, row = np.meshgrid(np.arange(columns), np.arange(rows))
        points = np.zeros((columns * rows, 3))
        offset = 1.0 if self.type == 'charuco' else 0.0   # ChArUco: corners inside the frame
        points[:, 0] = (col.ravel() + offset) * self.square_length
        points[:, 1] = (row.ravel() + offset) * self.square_length
        return points

    def adjacent_pairs(self):
        """(P, 2) corner-id pairs one square apart (along rows and along columns)."""
        columns, rows = self.corner_grid
        ids = np.arange(columns * rows).reshape(rows, columns)
        return np.concatenate([np.stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()], 1),
                               np.stack([ids[:-1].ravel(), ids[1:].ravel()], 1)])

    def opencv_board(self):
        """cv2.aruco.CharucoBoard (ChArUco only)."""
        import cv2
        if self.type != 'charuco':
            raise ValueError('opencv_board: only a ChArUco board has an OpenCV board object')
        dictionary = cv2.aruco.getPredefinedDictionary(
            getattr(cv2.aruco, f'DICT_{self.marker_bits}X{self.marker_bits}_{self.dict_size}'))
        return cv2.aruco.CharucoBoard((self.board_x, self.board_y), self.square_length,
                                      self.marker_length, dictionary)

    def describe(self):
        """One line, e.g. 'charuco 8 x 11 squares, square 24.0, marker 18.75, DICT_4X4_1000'."""
        if self.type == 'charuco':
            return (f'charuco {self.board_x} x {self.board_y} squares '
                    f'({self.num_corners} corners), square {self.square_length:g}, marker '
                    f'{self.marker_length:g}, DICT_{self.marker_bits}X{self.marker_bits}_'
                    f'{self.dict_size}')
        return (f'checkerboard {self.board_x} x {self.board_y} inner corners, square '
                f'{self.square_length:g}')


def board_from_mapping(data, path=None):
    """Board from a TOML-like mapping (module docstring); BoardError naming the field."""
    if not isinstance(data, dict):
        raise BoardError('(file)', 'must be a table of board fields', path)
    unknown = sorted(set(data) - set(KEYS))
    if unknown:
        raise BoardError(unknown[0], f'unknown field (expected {", ".join(KEYS)})', path)
    for key in ('board_x', 'board_y', 'square_length'):
        if key not in data:
            raise BoardError(key, 'missing', path)
    values = dict(data)
    values.setdefault('type', 'charuco' if 'marker_length' in data else 'checkerboard')
    if values['type'] == 'charuco':
        for key in ('marker_length', 'marker_bits', 'dict_size'):
            if key not in data:
                raise BoardError(key, 'missing (a ChArUco board needs marker_length, '
                                 'marker_bits and dict_size)', path)
    try:
        return Board(**values)
    except BoardError as error:
        raise BoardError(error.field, error.message, path) from None


def load_board(path):
    """Board from a TOML board file (module docstring). BoardError names the file and
    field; a missing or unreadable file or invalid TOML is a BoardError too."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise BoardError('(file)', f'cannot read ({getattr(exc, "strerror", None) or exc})',
                         path) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise BoardError('(file)', f'not valid TOML ({exc})', path) from None
    return board_from_mapping(data, path)
