"""Board corner detection in images (OpenCV aruco / checkerboard, sub-pixel), no ROS.

detect_board(image, board) finds one board view; detect_frames runs it over a camera's
frames and counts every frame that yields no usable board (never silently dropped).
Boards printed inverted (white markers on black) are found by trying the inverted image
when the image itself gives nothing.
"""
from dataclasses import dataclass, field

import numpy as np

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
        import cv2
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        found = self._once(gray)
        if found is None:
            found = self._once(255 - gray)     # a board printed inverted
        return found


@dataclass
class CameraDetections:
    """Detections of one camera over its frames.

    corners: (F, N, 2) px, NaN where a corner was not found (N = board.num_corners);
    size: (width, height) px of the frames; no_board: frame indices without a usable board.
    """

    name: str
    corners: np.ndarray
    size: tuple
    no_board: list = field(default_factory=list)

    @property
    def frames_with_board(self):
        return int(np.isfinite(self.corners[..., 0]).any(axis=1).sum())


def detect_frames(name, frames, board, total=None, progress=True, detector=None):
    """Detect the board in every frame of one camera.

    frames: iterable of (H, W) or (H, W, 3) uint8 images, all the same size; total: the
    count for the progress bar. Returns CameraDetections. Raises ValueError naming the
    camera when it has no frame or its frames change size."""
    from tqdm import tqdm

    detector = detector or BoardDetector(board)
    rows, no_board, size = [], [], None
    for index, image in enumerate(tqdm(frames, total=total, desc=f'detect {name}',
                                       unit='frame', disable=not progress, leave=False)):
        shape = (int(image.shape[1]), int(image.shape[0]))
        if size is None:
            size = shape
        elif shape != size:
            raise ValueError(f'camera {name!r}: frame {index} is {shape[0]}x{shape[1]}, '
                             f'the first was {size[0]}x{size[1]}')
        row = np.full((board.num_corners, 2), np.nan)
        found = detector.detect(image)
        if found is None:
            no_board.append(index)
        else:
            row[found[0]] = found[1]
        rows.append(row)
    if not rows:
        raise ValueError(f'camera {name!r}: no frame to detect the board in')
    return CameraDetections(name, np.stack(rows), size, no_board)
