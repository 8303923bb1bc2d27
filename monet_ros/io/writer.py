"""BagWriter: a rosbag2 bag folder (metadata.yaml + <folder>_0.mcap) that `ros2 bag info`,
`ros2 bag play` and Foxglove open.

MCAP records are written by the `mcap` library (chunks, message indexes, summary,
statistics, CRCs); messages are serialised to CDR with rosbags' ROS 2 Jazzy typestore,
which also gives the ros2msg schemas (incl. tf2_msgs, absent from the pip wheels).
No rclpy needed; rclpy messages are accepted by `write` too.
"""
from collections import OrderedDict
import io
import os
from pathlib import Path

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
import numpy as np
import yaml

from .fields import (
    camera_info_fields,
    camera_pose_transform,
    heatmap_image_fields,
    keypoint_cloud_fields,
    keypoints_to_metres,
    split_stamp,
)
from .images import encode_compressed, image_fields
from .markers import skeleton_marker_specs

_COMPRESSION = {'none': CompressionType.NONE, 'zstd': CompressionType.ZSTD,
                'lz4': CompressionType.LZ4}
_INFINITE = {'sec': 9223372036, 'nsec': 854775807}


def _qos_yaml(transient_local):
    """offered_qos_profiles string of rosbag2 metadata version 8 (reliable; latched for
    transient-local topics such as /tf_static)."""
    profile = [{'history': 3, 'depth': 0, 'reliability': 1,
                'durability': 1 if transient_local else 2, 'deadline': dict(_INFINITE),
                'lifespan': dict(_INFINITE), 'liveliness': 1,
                'liveliness_lease_duration': dict(_INFINITE),
                'avoid_ros_namespace_conventions': False}]
    return yaml.safe_dump(profile, sort_keys=False).strip()


class BagWriterError(ValueError):
    """Bad use of BagWriter (existing output, unknown type, topic type clash, closed bag)."""


class BagWriter:
    """Write a rosbag2 MCAP bag folder.

    with BagWriter('out/recording') as bag:
        bag.write_image('/cam0/image_raw', stamp_ns, rgb, 'cam0_optical')

    path: the bag folder (created; must not exist or be empty). The MCAP file is
    <path>/<folder name>_0.mcap like rosbag2's. compression: 'none' (default, fastest to
    read), 'zstd' or 'lz4' chunk compression. Message log time = the given stamp unless
    log_time_ns is passed. metadata.yaml (version 8, as ROS 2 Jazzy writes) is written
    on close().
    """

    def __init__(self, path, compression='none', chunk_size=4 * 1024 * 1024):
        from rosbags.typesys import Stores, get_typestore

        self.path = Path(path)
        if compression not in _COMPRESSION:
            raise BagWriterError(f'compression must be one of {sorted(_COMPRESSION)}, '
                                 f'got {compression!r}')
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise BagWriterError(f'bag output {self.path} exists already and is not an empty '
                                 'folder; not overwriting')
        self.path.mkdir(parents=True, exist_ok=True)
        self.file_name = f'{self.path.name}_0.mcap'
        self._file = open(self.path / self.file_name, 'wb')
        self._mcap = McapWriter(self._file, chunk_size=int(chunk_size),
                                compression=_COMPRESSION[compression])
        self._mcap.start(profile='ros2', library='monet_ros')
        self._store = get_typestore(Stores.ROS2_JAZZY)
        self._schemas = {}                  # msgtype -> schema id
        self._topics = OrderedDict()        # topic -> dict(channel, type, count, hash)
        self._start = None
        self._end = None
        self._closed = False

    # ------------------------------------------------------------------ generic

    @property
    def message_counts(self):
        """topic -> number of messages written so far."""
        return {t: v['count'] for t, v in self._topics.items()}

    def _channel(self, topic, msgtype):
        if self._closed:
            raise BagWriterError(f'bag {self.path} is closed')
        entry = self._topics.get(topic)
        if entry is not None:
            if entry['type'] != msgtype:
                raise BagWriterError(f'topic {topic} has type {entry["type"]}, cannot write '
                                     f'{msgtype} to it')
            return entry['channel']
        if not topic.startswith('/'):
            raise BagWriterError(f'topic {topic!r} must be absolute (start with /)')
        if msgtype not in self._store.types:
            raise BagWriterError(f'unknown message type {msgtype!r} (not in the ROS 2 Jazzy '
                                 'typestore)')
        if msgtype not in self._schemas:
            msgdef, _ = self._store.generate_msgdef(msgtype, ros_version=2)
            self._schemas[msgtype] = self._mcap.register_schema(
                name=msgtype, encoding='ros2msg', data=msgdef.encode())
        transient = topic in ('/tf_static',) or topic.endswith('/tf_static')
        qos = _qos_yaml(transient)
        channel = self._mcap.register_channel(
            topic=topic, message_encoding='cdr', schema_id=self._schemas[msgtype],
            metadata={'offered_qos_profiles': qos})
        self._topics[topic] = dict(channel=channel, type=msgtype, count=0, qos=qos,
                                   hash=self._store.hash_rihs01(msgtype))
        return channel

    def serialize(self, msgtype, msg):
        """CDR bytes of a message: bytes-like (already CDR), a rosbags typestore message,
        or an rclpy message."""
        if isinstance(msg, (bytes, bytearray, memoryview)):
            return bytes(msg)
        if hasattr(msg, 'get_fields_and_field_types'):       # rclpy message
            from rclpy.serialization import serialize_message
            return serialize_message(msg)
        return bytes(self._store.serialize_cdr(msg, msgtype))

    def write(self, topic, msgtype, msg, log_time_ns, publish_time_ns=None):
        """Write one message (see serialize for what msg may be) at log_time_ns."""
        channel = self._channel(topic, msgtype)
        data = self.serialize(msgtype, msg)
        log_time_ns = int(log_time_ns)
        if log_time_ns < 0:
            raise BagWriterError(f'{topic}: log time must be >= 0 ns, got {log_time_ns}')
        entry = self._topics[topic]
        self._mcap.add_message(channel_id=channel, log_time=log_time_ns, data=data,
                               publish_time=int(log_time_ns if publish_time_ns is None
                                                else publish_time_ns),
                               sequence=entry['count'])
        entry['count'] += 1
        self._start = log_time_ns if self._start is None else min(self._start, log_time_ns)
        self._end = log_time_ns if self._end is None else max(self._end, log_time_ns)

    def message(self, msgtype, **fields):
        """A rosbags typestore message instance (for write)."""
        return self._store.types[msgtype](**fields)

    def _header(self, stamp_ns, frame_id):
        sec, nanosec = split_stamp(stamp_ns)
        T = self._store.types
        return T['std_msgs/msg/Header'](
            stamp=T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec),
            frame_id=str(frame_id))

    # ------------------------------------------------------------------ typed helpers

    def write_image(self, topic, stamp_ns, image, frame_id, encoding='rgb8', log_time_ns=None):
        """(H, W, 3) rgb / (H, W) mono array -> sensor_msgs/Image (see images.image_fields)."""
        f = image_fields(image, encoding)
        msg = self.message('sensor_msgs/msg/Image', header=self._header(stamp_ns, frame_id),
                           **f)
        self.write(topic, 'sensor_msgs/msg/Image', msg, _log(stamp_ns, log_time_ns))

    def write_compressed_image(self, topic, stamp_ns, image, frame_id, fmt='jpeg', quality=90,
                               log_time_ns=None):
        """(H, W, 3) rgb uint8 -> sensor_msgs/CompressedImage (jpeg or png)."""
        fmt, data = encode_compressed(image, fmt, quality)
        msg = self.message('sensor_msgs/msg/CompressedImage',
                           header=self._header(stamp_ns, frame_id), format=fmt, data=data)
        self.write(topic, 'sensor_msgs/msg/CompressedImage', msg, _log(stamp_ns, log_time_ns))

    def write_camera_info(self, topic, stamp_ns, camera, frame_id, log_time_ns=None):
        """monet_ros.geometry.Camera -> sensor_msgs/CameraInfo (K, D, R = I, P = [K|0])."""
        f = camera_info_fields(camera)
        T = self._store.types
        roi = T['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0, width=0,
                                                    do_rectify=False)
        msg = self.message('sensor_msgs/msg/CameraInfo', header=self._header(stamp_ns, frame_id),
                           binning_x=0, binning_y=0, roi=roi, **f)
        self.write(topic, 'sensor_msgs/msg/CameraInfo', msg, _log(stamp_ns, log_time_ns))

    def write_tf_static(self, stamp_ns, cameras, parent='world', child_suffix='_optical',
                        topic='/tf_static', log_time_ns=None):
        """One tf2_msgs/TFMessage with parent -> <camera.name><child_suffix> per camera:
        the camera's pose in the parent frame (translation = centre in metres, whatever
        the camera's unit; rotation = R^T)."""
        T = self._store.types
        transforms = []
        for cam in cameras:
            trans, quat = camera_pose_transform(cam)
            transforms.append(T['geometry_msgs/msg/TransformStamped'](
                header=self._header(stamp_ns, parent),
                child_frame_id=f'{cam.name}{child_suffix}',
                transform=T['geometry_msgs/msg/Transform'](
                    translation=T['geometry_msgs/msg/Vector3'](
                        x=float(trans[0]), y=float(trans[1]), z=float(trans[2])),
                    rotation=T['geometry_msgs/msg/Quaternion'](
                        x=float(quat[0]), y=float(quat[1]), z=float(quat[2]),
                        w=float(quat[3])))))
        msg = self.message('tf2_msgs/msg/TFMessage', transforms=transforms)
        self.write(topic, 'tf2_msgs/msg/TFMessage', msg, _log(stamp_ns, log_time_ns))

    def write_keypoints3d(self, topic, stamp_ns, frame_id, X, confidence=None,
                          reprojection_error=None, num_views=None, log_time_ns=None, *, units,
                          keypoint=None, subject=None):
        """(N, 3) keypoints in the rig's length unit `units` (required) ->
        sensor_msgs/PointCloud2 in the /monet/keypoints3d layout, in metres (REP 103);
        keypoint / subject (N,) int: as io.fields.keypoint_cloud_fields (subject None: the
        one-subject layout, no subject field)."""
        f = keypoint_cloud_fields(X, confidence, reprojection_error, num_views, units=units,
                                  keypoint=keypoint, subject=subject)
        T = self._store.types
        fields = [T['sensor_msgs/msg/PointField'](name=n, offset=o, datatype=d, count=c)
                  for n, o, d, c in f.pop('fields')]
        msg = self.message('sensor_msgs/msg/PointCloud2',
                           header=self._header(stamp_ns, frame_id), fields=fields, **f)
        self.write(topic, 'sensor_msgs/msg/PointCloud2', msg, _log(stamp_ns, log_time_ns))

    def write_heatmaps(self, topic, stamp_ns, heatmaps, frame_id, log_time_ns=None):
        """(C, h, w) heatmaps -> sensor_msgs/Image, encoding 32FC<C>."""
        f = heatmap_image_fields(heatmaps)
        msg = self.message('sensor_msgs/msg/Image', header=self._header(stamp_ns, frame_id),
                           **f)
        self.write(topic, 'sensor_msgs/msg/Image', msg, _log(stamp_ns, log_time_ns))

    def write_skeleton_markers(self, topic, stamp_ns, frame_id, X, bone_indices, ns='monet',
                               scale=0.03, log_time_ns=None, *, units):
        """(N, 3) keypoints in the rig's length unit `units` (required) + (B, 2) bones ->
        visualization_msgs/MarkerArray in metres (joints as a SPHERE_LIST, bones as a
        LINE_LIST; NaN joints left out; scale in m)."""
        T = self._store.types
        header = self._header(stamp_ns, frame_id)
        markers = []
        for spec in skeleton_marker_specs(keypoints_to_metres(X, units), bone_indices, ns=ns,
                                          scale=scale):
            points = [T['geometry_msgs/msg/Point'](x=float(p[0]), y=float(p[1]), z=float(p[2]))
                      for p in spec['points']]
            markers.append(T['visualization_msgs/msg/Marker'](
                header=header, ns=spec['ns'], id=spec['id'], type=spec['type'], action=0,
                pose=T['geometry_msgs/msg/Pose'](
                    position=T['geometry_msgs/msg/Point'](x=0.0, y=0.0, z=0.0),
                    orientation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)),
                scale=T['geometry_msgs/msg/Vector3'](x=spec['scale'][0], y=spec['scale'][1],
                                                     z=spec['scale'][2]),
                color=T['std_msgs/msg/ColorRGBA'](r=spec['color'][0], g=spec['color'][1],
                                                  b=spec['color'][2], a=spec['color'][3]),
                lifetime=T['builtin_interfaces/msg/Duration'](sec=0, nanosec=0),
                frame_locked=False, points=points, colors=[], texture_resource='',
                texture=T['sensor_msgs/msg/CompressedImage'](
                    header=T['std_msgs/msg/Header'](
                        stamp=T['builtin_interfaces/msg/Time'](sec=0, nanosec=0), frame_id=''),
                    format='', data=np.zeros(0, np.uint8)),
                uv_coordinates=[], text='', mesh_resource='',
                mesh_file=T['visualization_msgs/msg/MeshFile'](filename='',
                                                               data=np.zeros(0, np.uint8)),
                mesh_use_embedded_materials=False))
        msg = self.message('visualization_msgs/msg/MarkerArray', markers=markers)
        self.write(topic, 'visualization_msgs/msg/MarkerArray', msg,
                   _log(stamp_ns, log_time_ns))

    # ------------------------------------------------------------------ closing

    def metadata(self):
        """The rosbag2_bagfile_information dict (version 8) for what was written."""
        start = self._start or 0
        duration = (self._end - self._start) if self._start is not None else 0
        total = sum(v['count'] for v in self._topics.values())
        return {
            'version': 8,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': total,
            'topics_with_message_count': [
                {'topic_metadata': {'name': topic, 'type': v['type'],
                                    'serialization_format': 'cdr',
                                    'offered_qos_profiles': v['qos'],
                                    'type_description_hash': v['hash']},
                 'message_count': v['count']}
                for topic, v in self._topics.items()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.file_name],
            'files': [{'path': self.file_name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration},
                       'message_count': total}],
            'custom_data': None,
            'ros_distro': 'jazzy',
        }

    def close(self):
        """Finish the MCAP (summary, indexes) and write metadata.yaml (atomically)."""
        if self._closed:
            return
        info = self.metadata()
        self._mcap.add_metadata('rosbag2', {
            'serialized_metadata': yaml.safe_dump(info, sort_keys=False)})
        self._mcap.finish()
        self._file.close()
        self._closed = True
        text = yaml.safe_dump({'rosbag2_bagfile_information': info}, sort_keys=False)
        tmp = self.path / 'metadata.yaml.tmp'
        with io.open(tmp, 'w', encoding='utf8') as f:
            f.write(text)
        os.replace(tmp, self.path / 'metadata.yaml')

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close()
        return False


def _log(stamp_ns, log_time_ns):
    return stamp_ns if log_time_ns is None else log_time_ns
