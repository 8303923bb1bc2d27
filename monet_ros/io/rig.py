"""rig_from_bag: the cameras of a recording from its CameraInfo topics and /tf_static
(or from a rig file)."""
import numpy as np

from .fields import camera_from_camera_info, quaternion_to_matrix
from .multiview import camera_name_for_topic
from .reader import BagError, BagReader, open_bag

CAMERA_INFO = 'sensor_msgs/msg/CameraInfo'
IMAGE_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage')
TF_TYPE = 'tf2_msgs/msg/TFMessage'


class RigFromBagError(BagError):
    """The bag does not define a complete rig (the message names what is missing)."""


def _pose_in_root(frame, tree, world_frame):
    """Pose (R, t) of `frame` in the root of its TF chain (or in world_frame):
    x_root = R x_frame + t. Returns (R, t, root)."""
    R, t = np.eye(3), np.zeros(3)
    seen = {frame}
    while frame in tree and frame != world_frame:
        parent, Rp, tp = tree[frame]
        R, t = Rp @ R, Rp @ t + tp
        frame = parent
        if frame in seen:
            raise RigFromBagError(f'/tf_static has a cycle through frame {frame!r}')
        seen.add(frame)
    return R, t, frame


def _image_topic(reader, name):
    """The image topic of camera `name` (same first name; raw preferred over compressed)."""
    candidates = [t for t in reader.topics_of_type(*IMAGE_TYPES)
                  if camera_name_for_topic(t) == name]
    candidates.sort(key=lambda t: (reader.topics[t].msgtype != 'sensor_msgs/msg/Image', t))
    return candidates[0] if candidates else None


def recording_image_size(path):
    """(width, height) shared by the first image of every image topic of a recording, or
    None when the recording has no image or its cameras differ in size."""
    from .images import any_image_to_numpy
    reader = path if isinstance(path, BagReader) else open_bag(path)
    topics = reader.topics_of_type(*IMAGE_TYPES)
    sizes = {}
    for m in reader.messages(topics=topics):
        if m.topic not in sizes:
            try:
                if hasattr(m.msg, 'width') and hasattr(m.msg, 'height'):
                    sizes[m.topic] = (int(m.msg.width), int(m.msg.height))
                else:
                    shape = any_image_to_numpy(m.msg).shape
                    sizes[m.topic] = (int(shape[1]), int(shape[0]))
            except (AttributeError, TypeError, ValueError):
                continue
        if len(sizes) == len(topics):
            break
    return next(iter(sizes.values())) if len(set(sizes.values())) == 1 else None


def _rig_file_sized_by(path, rig_file, units=None):
    """load_rig(rig_file, units=units); a calibration file that stores no image size
    (OpenCV's stereo_calib intrinsics.yml) takes the size of the recording's images."""
    from monet_ros.geometry import RigError, load_rig
    try:
        return load_rig(rig_file, units=units)
    except RigError as error:
        if error.field != 'image_width' or 'stores no image size' not in error.message:
            raise
        size = recording_image_size(path) if path is not None else None
        if size is None:
            raise RigError(error.path, error.field, error.message + '; the recording does '
                           'not give one either (no images, or cameras of different sizes)') \
                from None
        return load_rig(rig_file, image_size=size, units=units)


def _why_unread(report, topics):
    """' (why: ...)' from a read's report: the first skip reason of `topics`, then the
    first file-level damage (a truncated file, a bad record), so that a damaged bag is
    named as damaged and not only as lacking messages; '' when the report holds neither."""
    reasons = [f'{t}: {report.skip_reasons[t]}' for t in topics if t in report.skip_reasons]
    reasons = reasons[:1] + report.errors[:1]
    return f' (why: {"; ".join(reasons)})' if reasons else ''


def rig_from_bag(path, rig_file=None, world_frame=None, camera_info_topics=None, units=None):
    """list[Camera] of a bag, sorted by name (see rig_and_frame_from_bag)."""
    return rig_and_frame_from_bag(path, rig_file, world_frame, camera_info_topics, units)[0]


def rig_and_frame_from_bag(path, rig_file=None, world_frame=None, camera_info_topics=None,
                           units=None):
    """(list[Camera] sorted by name, root frame) of a bag; the root frame is the TF frame
    the camera poses are expressed in (None with rig_file).

    With rig_file: monet_ros.geometry.load_rig(rig_file) (the recording's image size when
    the file stores none, as stereo_calib's intrinsics.yml). Otherwise intrinsics from the
    first message of each CameraInfo topic (camera name = the topic's first name, e.g.
    /cam01/camera_info -> cam01) and extrinsics from the /tf_static transforms that chain
    the CameraInfo's header.frame_id to world_frame (default: the common root frame). A
    TF transform parent -> child is the child's pose: x_parent = R x_child + t; the camera
    gets world -> camera R_c = R^T, t_c = -R^T t. Camera.topic = the camera's image topic.
    path: a bag path or a BagReader. units: the rig's length unit ('m', 'cm', 'mm') when
    the rig file states none (see geometry.read_rig); a rig from /tf_static is in metres
    (ROS REP 103) unless units says otherwise. Raises RigFromBagError naming what is missing.
    """
    if rig_file is not None:
        return _rig_file_sized_by(path, rig_file, units), None
    reader = path if isinstance(path, BagReader) else open_bag(path)
    info_topics = sorted(camera_info_topics or reader.topics_of_type(CAMERA_INFO))
    if not info_topics:
        raise RigFromBagError(f'bag {reader.path} has no CameraInfo topic; pass a rig file')
    tf_topics = reader.topics_of_type(TF_TYPE)
    static_topics = [t for t in tf_topics if t.endswith('tf_static')]
    infos, tree = {}, {}

    def resolved():
        """All CameraInfos seen and every camera frame chains to one (the wanted) root."""
        if len(infos) < len(info_topics):
            return False
        roots = set()
        for m in infos.values():
            if str(m.header.frame_id) not in tree:
                return False
            roots.add(_pose_in_root(str(m.header.frame_id), tree, world_frame)[2])
        return len(roots) == 1 and (world_frame is None or roots == {world_frame})

    for m in reader.messages(topics=info_topics + static_topics):
        try:
            if m.topic in info_topics:
                str(m.msg.header.frame_id)      # usable CameraInfo (fields checked later)
                infos.setdefault(m.topic, m.msg)
            else:
                for tr in m.msg.transforms:
                    q, p = tr.transform.rotation, tr.transform.translation
                    tree[str(tr.child_frame_id)] = (
                        str(tr.header.frame_id), quaternion_to_matrix(q.x, q.y, q.z, q.w),
                        np.array([p.x, p.y, p.z], np.float64))
        except (AttributeError, TypeError, ValueError) as exc:
            reader.report.skip(m.topic, f'unusable for the rig: {exc}')
            continue
        if resolved():
            break
    missing = [t for t in info_topics if t not in infos]
    if missing:
        raise RigFromBagError(f'bag {reader.path}: no readable CameraInfo message on '
                              f'{", ".join(missing)}{_why_unread(reader.report, missing)}')
    cameras, roots = [], {}
    for topic in info_topics:
        msg = infos[topic]
        name = camera_name_for_topic(topic)
        frame = str(msg.header.frame_id)
        if frame not in tree:
            raise RigFromBagError(
                f'bag {reader.path}: camera {name} (frame {frame!r}, {topic}) has no '
                f'transform in {static_topics or "/tf_static (absent)"}'
                f'{_why_unread(reader.report, static_topics)}; pass a rig file')
        Rwc, twc, root = _pose_in_root(frame, tree, world_frame)
        if world_frame is not None and root != world_frame:
            raise RigFromBagError(f'bag {reader.path}: frame {frame!r} of camera {name} does '
                                  f'not chain to {world_frame!r} (its root is {root!r})')
        roots[name] = root
        camera = camera_from_camera_info(msg, name, Rwc.T, -Rwc.T @ twc,
                                         topic=_image_topic(reader, name))
        cameras.append(camera.replace(units=units) if units else camera)
    if len(set(roots.values())) > 1:
        raise RigFromBagError(f'bag {reader.path}: cameras are in different TF trees '
                              f'{roots}; pass world_frame or a rig file')
    return sorted(cameras, key=lambda c: c.name), next(iter(roots.values()))
