"""Board corner detection in images (OpenCV aruco / checkerboard, sub-pixel), no ROS.

detect_board(image, board) finds one board view; detect_frames runs it over a camera's
frames and counts every frame that yields no usable board (never silently dropped).
Boards printed inverted (white markers on black) are found by trying the inverted image
when the image itself gives nothing; a board seen mirrored (left-right: through a mirror, or
a camera that flips its images) is found the same way, by trying the flipped image, and
counted apart: a mirrored view has no OpenCV camera model (a negative focal length), so it
is never used, only reported. A frame that cannot be read (None from the frame source, e.g.
a truncated JPEG) is counted as unreadable, not as a frame without a board. When a camera's
frames give no board, the first few are diagnosed (BoardDetector.diagnose): ArUco markers
that do not fit the board spec are named with the fields to check.
"""
from dataclasses import dataclass, field

import numpy as np

# Frames without a board diagnosed per camera (each costs a few marker detections).
DIAGNOSED_FRAMES = 2
# Fewest corners of a usable view: a board pose (PnP) needs at least 4 non-collinear
# points; 6 leaves margin against a near-degenerate ChArUco fragment.
MIN_CORNERS = 6
_SUBPIX_WINDOW = (5, 5)
_SUBPIX_CRITERIA = (3, 50, 1e-3)      # cv2.TERM_CRITERIA_EPS | MAX_ITER, 50, 0.001 px


class BoardDetector:
    """Reusable detector of one board (the OpenCV objects are made once).

    detect(gray) -> (ids (n,) int, corners (n, 2) float px) of the corners found, or
    None when fewer than min_corners are found (in the image and in its inverse)."""

    def __init__(self, board, min_corners=MIN_CORNERS):
        import cv2
        self.board = board
        self.min_corners = int(min_corners)
        if board.type == 'charuco':
            self._charuco = cv2.aruco.CharucoDetector(board.opencv_board())
        else:
            self._charuco = None

    def _once(self, gray):
        import cv2
        if self._charuco is not None:
            corners, ids, _, _ = self._charuco.detectBoard(gray)
            if ids is None or len(ids) < self.min_corners:
                return None
            ids = ids.reshape(-1).astype(np.int64)
            corners = corners.reshape(-1, 2).astype(np.float64)
            # collinear corners (one row of the board) give no pose
            if np.linalg.matrix_rank(corners - corners.mean(0), tol=1.0) < 2:
                return None
            return ids, corners
        grid = self.board.corner_grid
        flags = (cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
                 | cv2.CALIB_CB_FAST_CHECK)
        found, corners = cv2.findChessboardCorners(gray, grid, flags=flags)
        if not found:
            return None
        corners = cv2.cornerSubPix(gray, corners, _SUBPIX_WINDOW, (-1, -1), _SUBPIX_CRITERIA)
        return np.arange(grid[0] * grid[1]), corners.reshape(-1, 2).astype(np.float64)

    def detect(self, image):
        """Corners of the board in one image (H, W) gray or (H, W, 3) RGB uint8."""
        return self.detect_view(image)[0]

    def detect_view(self, image):
        """(found, how) of one image: found = (ids, corners) as detect() gives, or None;
        how = 'plain', 'inverted' (white markers on black), 'mirrored' (found only in the
        left-right flipped image; found is None then: such a view is not used) or None."""
        import cv2
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        found = self._once(gray)
        if found is not None:
            return found, 'plain'
        found = self._once(255 - gray)     # a board printed inverted
        if found is not None:
            return found, 'inverted'
        flipped = cv2.flip(gray, 1)
        if self._once(flipped) is not None or self._once(255 - flipped) is not None:
            return None, 'mirrored'
        return None, None

    def diagnose(self, image):
        """Why an image without a board may still hold one: a sentence naming the board
        fields to check when it holds ArUco markers that do not make this board (ChArUco
        only), else None. Markers of the board's dictionary whose ids lie beyond the
        board's -> board_x / board_y / dict_size; markers of the board's dictionary that
        give no corner -> board_x / board_y (swapped?), square_length / marker_length;
        markers only of another bit count -> marker_bits / dict_size."""
        import cv2
        if self._charuco is None:
            return None
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        board = self.board
        count = board.board_x * board.board_y // 2

        def markers(bits, size):
            dictionary = cv2.aruco.getPredefinedDictionary(
                getattr(cv2.aruco, f'DICT_{bits}X{bits}_{size}'))
            detector = cv2.aruco.ArucoDetector(dictionary)
            for img in (gray, 255 - gray):
                _, ids, _ = detector.detectMarkers(img)
                if ids is not None and len(ids) >= 4:
                    return ids.reshape(-1)
            return None

        own = markers(board.marker_bits, board.dict_size)
        name = f'DICT_{board.marker_bits}X{board.marker_bits}_{board.dict_size}'
        spec = f'board_x {board.board_x}, board_y {board.board_y}'
        if own is not None and own.max() >= count:
            return (f'{len(own)} {name} markers found with ids up to {own.max()}, but a '
                    f'{board.board_x} x {board.board_y} board has ids 0-{count - 1}: check '
                    f'{spec} and dict_size')
        if own is not None:
            return (f'{len(own)} {name} markers found (ids {own.min()}-{own.max()}) that do '
                    f'not fit a {board.board_x} x {board.board_y} board: check {spec} '
                    '(swapped?), square_length and marker_length')
        for bits in (4, 5, 6, 7):
            if bits == board.marker_bits:
                continue
            other = markers(bits, 1000)
            if other is not None:
                return (f'{len(other)} markers of {bits}-bit dictionaries found, none of '
                        f'{name}: check marker_bits ({board.marker_bits}; these are {bits}) '
                        'and dict_size')
        return None


@dataclass
class CameraDetections:
    """Detections of one camera over its frames.

    corners: (F, N, 2) px, NaN where a corner was not found (N = board.num_corners);
    size: (width, height) px of the frames; no_board: frame indices without a usable board
    (mirrored and unreadable ones included); mirrored: those where the board was seen only
    mirrored (not used); unreadable: those the source could not read; hint: a diagnosis of
    markers that do not fit the board (BoardDetector.diagnose) or ''.
    """

    name: str
    corners: np.ndarray
    size: tuple
    no_board: list = field(default_factory=list)
    mirrored: list = field(default_factory=list)
    unreadable: list = field(default_factory=list)
    hint: str = ''

    @property
    def frames_with_board(self):
        return int(np.isfinite(self.corners[..., 0]).any(axis=1).sum())


def detect_frames(name, frames, board, total=None, progress=True, detector=None):
    """Detect the board in every frame of one camera.

    frames: iterable of (H, W) or (H, W, 3) uint8 images, all the same size, or None for a
    frame that could not be read (counted as unreadable); total: the count for the progress
    bar. Returns CameraDetections. Raises ValueError naming the camera when it has no
    readable frame or its frames change size."""
    from tqdm import tqdm

    detector = detector or BoardDetector(board)
    rows, no_board, mirrored, unreadable, size = [], [], [], [], None
    hints, diagnosed = [], 0
    for index, image in enumerate(tqdm(frames, total=total, desc=f'detect {name}',
                                       unit='frame', disable=not progress, leave=False)):
        row = np.full((board.num_corners, 2), np.nan)
        if image is None:
            unreadable.append(index)
            no_board.append(index)
            rows.append(row)
            continue
        shape = (int(image.shape[1]), int(image.shape[0]))
        if size is None:
            size = shape
        elif shape != size:
            raise ValueError(f'camera {name!r}: frame {index} is {shape[0]}x{shape[1]}, '
                             f'the first was {size[0]}x{size[1]}')
        found, how = detector.detect_view(image)
        if found is None:
            no_board.append(index)
            if how == 'mirrored':
                mirrored.append(index)
            elif diagnosed < DIAGNOSED_FRAMES and len(no_board) == index + 1:
                diagnosed += 1          # only while no frame so far had a board
                hint = detector.diagnose(image)
                if hint:
                    hints.append(hint)
        else:
            row[found[0]] = found[1]
        rows.append(row)
    if size is None:
        raise ValueError(f'camera {name!r}: no frame to detect the board in'
                         + (f' ({len(unreadable)} unreadable)' if unreadable else ''))
    corners = np.stack(rows)
    found_any = np.isfinite(corners[..., 0]).any()
    return CameraDetections(name, corners, size, no_board, mirrored, unreadable,
                            '' if found_any or not hints else hints[0])
