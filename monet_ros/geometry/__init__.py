"""Multi-camera geometry: cameras, rig files, epipolar geometry, triangulation (no ROS)."""
from monet_ros.geometry.camera import (
    Camera,
    CameraError,
    crop_transform,
    project_views,
    stack_cameras,
    undistort_views,
)
from monet_ros.geometry.epipolar import (
    apply_homography,
    epipolar_lines,
    fundamental_from_params,
    fundamental_matrix,
    rectification_homographies,
    rectifying_rotation,
    relative_pose,
    skew_matrix,
    stereo_rectify,
)
from monet_ros.geometry.rig import RigError, load_rig, read_rig, save_anipose_toml, save_rig
from monet_ros.geometry.triangulation import (
    reprojection_error,
    select_candidates,
    triangulate,
    triangulate_robust,
)

__all__ = [
    'Camera', 'CameraError', 'crop_transform', 'project_views', 'stack_cameras',
    'undistort_views',
    'apply_homography', 'epipolar_lines', 'fundamental_from_params', 'fundamental_matrix',
    'rectification_homographies', 'rectifying_rotation', 'relative_pose', 'skew_matrix',
    'stereo_rectify',
    'RigError', 'load_rig', 'read_rig', 'save_anipose_toml', 'save_rig',
    'reprojection_error', 'select_candidates', 'triangulate', 'triangulate_robust',
]
