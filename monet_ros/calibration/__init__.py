"""A rig's calibration from ChArUco / checkerboard views (no ROS): `monet calibrate`.

board (Board, load_board: the anipose board TOML) -> detect (BoardDetector,
detect_frames: corners per frame, frames without a board counted) -> intrinsics
(calibrateCamera per camera) -> extrinsics (pairwise poses chained over a spanning tree)
-> bundle (joint robust bundle adjustment) -> rig (calibrate_rig: all of it) -> summary
(per camera / pair figures, the board triangulated back) and report (PNG).
"""
from monet_ros.calibration.board import Board, BoardError, board_from_mapping, load_board
from monet_ros.calibration.detect import BoardDetector, CameraDetections, detect_frames
from monet_ros.calibration.rig import CalibrationConfig, CalibrationResult, calibrate_rig

__all__ = ['Board', 'BoardDetector', 'BoardError', 'CalibrationConfig', 'CalibrationResult',
           'CameraDetections', 'board_from_mapping', 'calibrate_rig', 'detect_frames',
           'load_board']
