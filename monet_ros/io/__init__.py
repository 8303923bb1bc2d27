"""MCAP / rosbag2 reading and writing, ROS <-> numpy message conversion.

Importing this package does not import rclpy: the rclpy message builders in
monet_ros.io.convert import it on first use; monet_ros.io.fields / images are pure numpy.
"""
from monet_ros.io.convert import (
    any_image_to_numpy,
    camera_from_camera_info,
    camera_info_from_camera,
    cloud_to_keypoints3d,
    compressed_image_msg,
    compressed_image_to_numpy,
    header_stamp_ns,
    heatmaps_to_image_msg,
    image_msg_to_heatmaps,
    image_to_numpy,
    keypoints3d_to_cloud,
    numpy_to_image_msg,
    skeleton_marker_array,
)
from monet_ros.io.images import ImageDecodeError
from monet_ros.io.writer import BagWriter, BagWriterError

__all__ = [
    'any_image_to_numpy', 'BagWriter', 'BagWriterError', 'camera_from_camera_info',
    'camera_info_from_camera', 'cloud_to_keypoints3d', 'compressed_image_msg',
    'compressed_image_to_numpy', 'header_stamp_ns', 'heatmaps_to_image_msg',
    'image_msg_to_heatmaps', 'image_to_numpy', 'ImageDecodeError', 'keypoints3d_to_cloud',
    'numpy_to_image_msg', 'skeleton_marker_array',
]
