"""ROS 2 (rclpy) message <-> numpy conversions for the nodes.

Decoding functions accept rclpy messages and messages decoded from bags alike (same
attribute names). Building functions return rclpy message instances (sensor_msgs,
visualization_msgs from the ROS 2 Jazzy wheels); rclpy is imported on first use, so the
pure-numpy parts (monet_ros.io.fields, monet_ros.io.images) stay importable without it.
"""
import array

import numpy as np

from .fields import (
    camera_from_camera_info,
    camera_info_fields,
    cloud_to_keypoints3d,
    header_stamp_ns,
    heatmap_image_fields,
    image_msg_to_heatmaps,
    keypoint_cloud_fields,
    keypoints_to_metres,
    split_stamp,
)
from .images import (
    any_image_to_numpy,
    compressed_image_to_numpy,
    encode_compressed,
    image_fields,
    image_to_numpy,
)
from .markers import skeleton_marker_specs

__all__ = [
    'any_image_to_numpy', 'camera_from_camera_info', 'camera_info_from_camera',
    'cloud_to_keypoints3d', 'compressed_image_msg', 'compressed_image_to_numpy',
    'empty_crop_messages',
    'header_stamp_ns', 'heatmaps_to_image_msg', 'image_msg_to_heatmaps', 'image_to_numpy',
    'delete_all_markers', 'keypoints3d_to_cloud', 'marker_array', 'numpy_to_image_msg',
    'skeleton_marker_array',
]


def _stamp_ns(stamp):
    """int nanoseconds, or a builtin_interfaces/Time-like object -> int nanoseconds."""
    if hasattr(stamp, 'sec') and hasattr(stamp, 'nanosec'):
        return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return int(stamp)


def _header(stamp, frame_id):
    """std_msgs/Header with `stamp` (int ns or a Time-like, kept as is, before 1970 too)."""
    from builtin_interfaces.msg import Time
    from std_msgs.msg import Header

    sec, nanosec = split_stamp(_stamp_ns(stamp))
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=str(frame_id))


def _bytes_array(data):
    """uint8 numpy data -> array.array('B') (the fast way to fill an rclpy uint8[] field)."""
    out = array.array('B')
    out.frombytes(np.ascontiguousarray(data, np.uint8).reshape(-1).data)   # one copy
    return out


def numpy_to_image_msg(image, stamp, frame_id, encoding='rgb8'):
    """(H, W, 3) rgb / (H, W) mono / (H, W, C) array -> sensor_msgs.msg.Image.
    See monet_ros.io.images.image_fields for the accepted encodings."""
    from sensor_msgs.msg import Image

    f = image_fields(image, encoding)
    msg = Image(header=_header(stamp, frame_id), height=f['height'], width=f['width'],
                encoding=f['encoding'], is_bigendian=f['is_bigendian'], step=f['step'])
    msg.data = _bytes_array(f['data'])
    return msg


def compressed_image_msg(image, stamp, frame_id, fmt='jpeg', quality=90):
    """(H, W, 3) rgb uint8 -> sensor_msgs.msg.CompressedImage (jpeg or png)."""
    from sensor_msgs.msg import CompressedImage

    fmt, data = encode_compressed(image, fmt, quality)
    msg = CompressedImage(header=_header(stamp, frame_id), format=fmt)
    msg.data = _bytes_array(data)
    return msg


def camera_info_from_camera(camera, stamp, frame_id):
    """monet_ros.geometry.Camera -> sensor_msgs.msg.CameraInfo (K, D, R = I, P = [K|0])."""
    from sensor_msgs.msg import CameraInfo

    f = camera_info_fields(camera)
    return CameraInfo(header=_header(stamp, frame_id), height=f['height'], width=f['width'],
                      distortion_model=f['distortion_model'], d=f['d'].tolist(), k=f['k'],
                      r=f['r'], p=f['p'])


def heatmaps_to_image_msg(heatmaps, stamp, frame_id):
    """(C, h, w) float heatmaps -> sensor_msgs.msg.Image, encoding 32FC<C>
    (channel-interleaved float32); inverse: image_msg_to_heatmaps."""
    from sensor_msgs.msg import Image

    f = heatmap_image_fields(heatmaps)
    msg = Image(header=_header(stamp, frame_id), height=f['height'], width=f['width'],
                encoding=f['encoding'], is_bigendian=0, step=f['step'])
    msg.data = _bytes_array(f['data'])
    return msg


def empty_crop_messages(num_keypoints, stamp, frame_id):
    """(Image, CameraInfo) of a crop slot without a crop at that instant (subjects >= 2):
    a 0 x 0 heatmap of encoding 32FC<num_keypoints> and a 0 x 0 camera_info, same stamp."""
    from sensor_msgs.msg import CameraInfo, Image

    header = _header(stamp, frame_id)
    return (Image(header=header, height=0, width=0, encoding=f'32FC{int(num_keypoints)}',
                  is_bigendian=0, step=0),
            CameraInfo(header=_header(stamp, frame_id)))


def keypoints3d_to_cloud(stamp, frame_id, X, confidence=None, reprojection_error=None,
                         num_views=None, *, units, keypoint=None, subject=None):
    """(N, 3) keypoints in the rig's length unit `units` (required) -> sensor_msgs.msg.
    PointCloud2 in metres with fields x y z confidence reprojection_error (FLOAT32),
    num_views keypoint (UINT32), point_step 28; with subject (N,) identities, one more
    UINT32 field `subject` (point_step 32; io.fields.keypoint_cloud_fields); inverse:
    cloud_to_keypoints3d."""
    from sensor_msgs.msg import PointCloud2, PointField

    f = keypoint_cloud_fields(X, confidence, reprojection_error, num_views, units=units,
                              keypoint=keypoint, subject=subject)
    msg = PointCloud2(header=_header(stamp, frame_id), height=f['height'], width=f['width'],
                      fields=[PointField(name=n, offset=o, datatype=d, count=c)
                              for n, o, d, c in f['fields']],
                      is_bigendian=f['is_bigendian'], point_step=f['point_step'],
                      row_step=f['row_step'], is_dense=f['is_dense'])
    msg.data = _bytes_array(f['data'])
    return msg


def skeleton_marker_array(stamp, frame_id, X, bone_indices, ns='monet', scale=0.03,
                          lifetime_ns=0, names=None, *, units, subject=0):
    """(N, 3) keypoints in the rig's length unit `units` (required) + (B, 2) bone index
    pairs -> visualization_msgs.msg.MarkerArray in metres (a SPHERE_LIST of the finite
    joints and a LINE_LIST of bones with both ends finite; with `names`, a text marker per
    finite joint). scale: joint size (m). lifetime_ns: how long a viewer shows them without
    an update (0 = forever). subject: the identity whose colours are used
    (io.markers.SUBJECT_COLOURS)."""
    return marker_array(stamp, frame_id,
                        skeleton_marker_specs(keypoints_to_metres(X, units), bone_indices,
                                              ns=ns, scale=scale, names=names,
                                              subject=subject),
                        lifetime_ns)


def marker_array(stamp, frame_id, specs, lifetime_ns=0):
    """Marker specs (monet_ros.io.markers) -> visualization_msgs.msg.MarkerArray."""
    from builtin_interfaces.msg import Duration
    from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker, MarkerArray

    header = _header(stamp, frame_id)
    markers = []
    for spec in specs:
        position = spec.get('position', (0.0, 0.0, 0.0))
        m = Marker(header=header, ns=spec['ns'], id=spec['id'], type=spec['type'],
                   action=Marker.ADD,
                   pose=Pose(position=Point(x=float(position[0]), y=float(position[1]),
                                            z=float(position[2])),
                             orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                   scale=Vector3(x=spec['scale'][0], y=spec['scale'][1], z=spec['scale'][2]),
                   color=ColorRGBA(r=spec['color'][0], g=spec['color'][1],
                                   b=spec['color'][2], a=spec['color'][3]),
                   lifetime=Duration(sec=int(lifetime_ns) // 1_000_000_000,
                                     nanosec=int(lifetime_ns) % 1_000_000_000),
                   text=spec.get('text', ''))
        m.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in spec['points']]
        markers.append(m)
    return MarkerArray(markers=markers)


def delete_all_markers(stamp, frame_id):
    """A MarkerArray with one DELETEALL marker: viewers drop every marker of the topic."""
    from visualization_msgs.msg import Marker, MarkerArray
    return MarkerArray(markers=[Marker(header=_header(stamp, frame_id), action=Marker.DELETEALL)])
