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
    empty_crop_messages,
    header_stamp_ns,
    heatmaps_to_image_msg,
    image_msg_to_heatmaps,
    image_to_numpy,
    keypoints3d_to_cloud,
    numpy_to_image_msg,
    skeleton_marker_array,
)
from monet_ros.io.images import ImageDecodeError
from monet_ros.io.multiview import MultiviewFrame, camera_name_for_topic, iter_multiview_frames
from monet_ros.io.reader import BagError, BagMessage, BagReader, ReadReport, TopicInfo, open_bag
from monet_ros.io.rig import RigFromBagError, rig_from_bag
from monet_ros.io.writer import BagWriter, BagWriterError

__all__ = [
    'any_image_to_numpy', 'BagError', 'BagMessage', 'BagReader', 'BagWriter', 'BagWriterError',
    'camera_from_camera_info',
    'camera_info_from_camera', 'cloud_to_keypoints3d', 'compressed_image_msg',
    'compressed_image_to_numpy', 'empty_crop_messages', 'header_stamp_ns', 'heatmaps_to_image_msg',
    'image_msg_to_heatmaps', 'image_to_numpy', 'ImageDecodeError', 'keypoints3d_to_cloud',
    'numpy_to_image_msg', 'skeleton_marker_array', 'camera_name_for_topic',
    'iter_multiview_frames', 'MultiviewFrame', 'open_bag', 'ReadReport', 'rig_from_bag',
    'RigFromBagError', 'TopicInfo',
]
