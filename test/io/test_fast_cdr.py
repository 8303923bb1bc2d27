"""The zero-copy Image / CompressedImage decoders equal mcap_ros2's generic decoder."""
from mcap_ros2._dynamic import generate_dynamic
import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from monet_ros.io.fast_cdr import fast_decoder

STORE = get_typestore(Stores.ROS2_JAZZY)


def random_message(name, rng):
    T = STORE.types
    hdr = T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=int(rng.integers(0, 2**31)),
                                               nanosec=int(rng.integers(0, 10**9))),
        frame_id='f' * int(rng.integers(0, 7)))
    data = rng.integers(0, 256, int(rng.integers(0, 50)), dtype=np.uint8)
    if name.endswith('/Image'):
        return T[name](header=hdr, height=int(rng.integers(0, 9)), width=int(rng.integers(0, 9)),
                       encoding='e' * int(rng.integers(0, 9)),
                       is_bigendian=int(rng.integers(0, 2)), step=int(rng.integers(0, 99)),
                       data=data)
    return T[name](header=hdr, format='j' * int(rng.integers(0, 9)), data=data)


@pytest.mark.parametrize('name', ['sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage'])
def test_fast_decoder_equals_generic(name):
    text = STORE.generate_msgdef(name, ros_version=2)[0]
    fast = fast_decoder(name, text)
    generic = generate_dynamic(name, text)[name]
    assert fast is not None
    fields = (['height', 'width', 'encoding', 'is_bigendian', 'step'] if name.endswith('/Image')
              else ['format'])
    rng = np.random.default_rng(0)
    for _ in range(300):        # all string lengths mod 4 and odd payload sizes
        raw = bytes(STORE.serialize_cdr(random_message(name, rng), name))
        a, g = fast(memoryview(raw)), generic(raw)
        for f in fields:
            assert getattr(a, f) == getattr(g, f), f
        assert isinstance(a.data, memoryview) and bytes(a.data) == g.data
        assert (a.header.stamp.sec, a.header.stamp.nanosec, a.header.frame_id) == \
            (g.header.stamp.sec, g.header.stamp.nanosec, g.header.frame_id)


def test_non_standard_schema_is_not_taken():
    text = STORE.generate_msgdef('sensor_msgs/msg/Image', ros_version=2)[0]
    assert fast_decoder('sensor_msgs/msg/Image', text.replace('uint32 step', 'uint64 step')) \
        is None
    assert fast_decoder('my_msgs/msg/Image', text) is None
    with pytest.raises(ValueError, match='runs past'):
        fast_decoder('sensor_msgs/msg/Image', text)(b'\x00\x01\x00\x00' + b'\x00' * 8 +
                                                    b'\xff\x00\x00\x00')


def test_live_bytes_from_rclpy_decode_in_place():
    """What a raw subscription hands over (rclpy's serialization of real messages) decodes
    to rclpy's own deserialization, pixels without a copy; every header is read alone."""
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2

    from monet_ros.io import camera_info_from_camera, keypoints3d_to_cloud, numpy_to_image_msg
    from monet_ros.io.fast_cdr import decode_header, decode_image
    from monet_ros.synth.rig import RigConfig, make_rig

    pixels = np.random.default_rng(1).integers(0, 256, (5, 7, 3), np.uint8)
    raw = serialize_message(numpy_to_image_msg(pixels, 1_700_000_000_123_456_789, 'cam_7'))
    fast, ref = decode_image(raw), deserialize_message(raw, Image)
    for field in ('height', 'width', 'encoding', 'is_bigendian', 'step'):
        assert getattr(fast, field) == getattr(ref, field), field
    assert bytes(fast.data) == bytes(ref.data) == pixels.tobytes()
    assert np.shares_memory(np.frombuffer(fast.data, np.uint8), np.frombuffer(raw, np.uint8))
    camera = make_rig(RigConfig(num_cameras=2))[0]
    for msg, kind in [(camera_info_from_camera(camera, -1_000_000_000, 'x'), CameraInfo),
                      (keypoints3d_to_cloud(42, 'world_frame', np.zeros((3, 3)), units='m'),
                       PointCloud2)]:
        header = decode_header(serialize_message(msg))
        ref = deserialize_message(serialize_message(msg), kind).header
        assert (header.stamp.sec, header.stamp.nanosec, header.frame_id) == \
            (ref.stamp.sec, ref.stamp.nanosec, ref.frame_id)


def test_every_truncation_is_a_value_error():
    """A live node counts a malformed message as bad: every cut of a valid message raises
    ValueError (never struct.error or IndexError)."""
    from monet_ros.io.fast_cdr import decode_compressed_image, decode_header, decode_image

    rng = np.random.default_rng(3)
    for name, decode in [('sensor_msgs/msg/Image', decode_image),
                         ('sensor_msgs/msg/CompressedImage', decode_compressed_image)]:
        raw = bytes(STORE.serialize_cdr(random_message(name, rng), name))
        decode(raw)
        for cut in range(len(raw)):
            with pytest.raises(ValueError, match='^malformed CDR'):
                decode(raw[:cut])
    for bad in (b'', b'\x00\x01', None, b'\x01\x00' + b'\x00' * 20):
        with pytest.raises(ValueError, match='malformed CDR'):
            decode_header(bad)
