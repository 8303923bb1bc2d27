"""Multi-camera geometry: cameras, rig files, epipolar geometry, triangulation (no ROS)."""
from monet_ros.geometry.camera import Camera, CameraError, crop_transform

__all__ = ['Camera', 'CameraError', 'crop_transform']
