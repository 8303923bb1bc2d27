"""The rig on /tf_static: one transform per camera, rig frame -> `<camera>_optical` (the
camera's pose: translation = centre, rotation = R^T), as tf2's static broadcaster sends it
(tf2_msgs/TFMessage, reliable + transient-local). tf2_msgs has no pip wheel: in the pip
environment `make venv` builds it from its definition (tools/build_tf2_msgs.sh); where it
is missing, `tf_message_class()` is None and the nodes say so once and go on without TF.
"""
from monet_ros.io.fields import camera_pose_transform

OPTICAL_SUFFIX = '_optical'


def tf_message_class():
    """tf2_msgs.msg.TFMessage, or None when tf2_msgs is not installed."""
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    return TFMessage


def rig_tf_message(cameras, frame_id, stamp_msg, suffix=OPTICAL_SUFFIX):
    """TFMessage with frame_id -> <camera.name><suffix> for every camera (ImportError when
    tf2_msgs is missing). stamp_msg: builtin_interfaces/Time."""
    from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Vector3
    from std_msgs.msg import Header

    TFMessage = tf_message_class()
    if TFMessage is None:
        raise ImportError('tf2_msgs is not installed (make venv builds it: '
                          'tools/build_tf2_msgs.sh)')
    transforms = []
    for cam in cameras:
        trans, quat = camera_pose_transform(cam)
        transforms.append(TransformStamped(
            header=Header(stamp=stamp_msg, frame_id=frame_id),
            child_frame_id=f'{cam.name}{suffix}',
            transform=Transform(
                translation=Vector3(x=float(trans[0]), y=float(trans[1]), z=float(trans[2])),
                rotation=Quaternion(x=float(quat[0]), y=float(quat[1]), z=float(quat[2]),
                                    w=float(quat[3])))))
    return TFMessage(transforms=transforms)
