"""Zero-copy CDR decoders for the two hot message types of a recording,
sensor_msgs/msg/Image and sensor_msgs/msg/CompressedImage: the pixel payload stays a
memoryview into the chunk (mcap_ros2's generic decoder copies it twice). Used only when a
bag's schema has exactly the standard fields; anything else goes to mcap_ros2.
Little-endian CDR only (what ROS 2 writes on every common platform).

decode_header reads only the header of a raw subscription's bytes (`create_subscription(...,
raw=True)`: bench/pipeline.py times keypoints3d that way without decoding them).
Malformed bytes raise ValueError.
(CDR: OMG DDS-XTYPES 1.3, 7.4.3 "Extended CDR", encoding version 1, as ROS 2 writes it.)"""
import functools
import re
import struct

_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')

IMAGE_FIELDS = [('std_msgs/Header', 'header'), ('uint32', 'height'), ('uint32', 'width'),
                ('string', 'encoding'), ('uint8', 'is_bigendian'), ('uint32', 'step'),
                ('uint8[]', 'data')]
COMPRESSED_FIELDS = [('std_msgs/Header', 'header'), ('string', 'format'), ('uint8[]', 'data')]
HEADER_FIELDS = [('builtin_interfaces/Time', 'stamp'), ('string', 'frame_id')]


class Stamp:
    __slots__ = ('sec', 'nanosec')

    def __init__(self, sec, nanosec):
        self.sec, self.nanosec = sec, nanosec


class Header:
    __slots__ = ('stamp', 'frame_id')

    def __init__(self, stamp, frame_id):
        self.stamp, self.frame_id = stamp, frame_id


class Image:
    __slots__ = ('header', 'height', 'width', 'encoding', 'is_bigendian', 'step', 'data')


class CompressedImage:
    __slots__ = ('header', 'format', 'data')


def _fields(text):
    """[(type, name)] of the top-level message of a ros2msg schema text."""
    main = re.split(r'^={10,}\s*$', text, maxsplit=1, flags=re.M)[0]
    out = []
    for line in main.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line or '=' in line.split()[-1] or len(line.split()) < 2:
            continue
        typ, name = line.split()[:2]
        if '=' in name:                       # constant
            continue
        out.append((typ, name))
    return out


def _sub_fields(text, typename):
    m = re.search(r'^MSG: ' + re.escape(typename) + r'\s*$(.*?)(^={10,}\s*$|\Z)', text,
                  flags=re.M | re.S)
    return _fields(m.group(1)) if m else None


def fast_decoder(schema_name, schema_text):
    """A zero-copy decoder for standard Image / CompressedImage schemas, else None."""
    if schema_name not in ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage'):
        return None
    want = IMAGE_FIELDS if schema_name.endswith('/Image') else COMPRESSED_FIELDS
    header = _sub_fields(schema_text, 'std_msgs/Header')
    if _fields(schema_text) != want or header != HEADER_FIELDS:
        return None
    return decode_image if want is IMAGE_FIELDS else decode_compressed_image


def _string(buf, off):
    off = _align(off, 4)
    (n,) = _U32.unpack_from(buf, off)
    off += 4
    if off + n > len(buf):
        raise ValueError('CDR string runs past the end of the message')
    return (bytes(buf[off:off + n - 1]).decode() if n > 1 else ''), off + n


def _align(off, k):
    """CDR alignment is relative to the end of the 4-byte encapsulation header."""
    return 4 + ((off - 4 + k - 1) & ~(k - 1))


def _header(buf):
    if len(buf) < 12 or buf[1] != 1:            # CDR_LE (0x0001) only
        raise ValueError('not little-endian CDR')
    sec, nanosec = _STAMP.unpack_from(buf, 4)
    frame_id, off = _string(buf, 12)
    return Header(Stamp(sec, nanosec), frame_id), off


def _bytes(buf, off):
    off = _align(off, 4)
    (n,) = _U32.unpack_from(buf, off)
    off += 4
    if off + n > len(buf):
        raise ValueError('CDR byte sequence runs past the end of the message')
    return buf[off:off + n], off + n


def _malformed_is_value_error(decode):
    """A decoder whose every failure on short or corrupt bytes is a ValueError."""
    @functools.wraps(decode)
    def wrapped(data):
        try:
            return decode(data)
        except (struct.error, IndexError, TypeError, ValueError) as error:
            raise ValueError(f'malformed CDR: {error}') from None
    return wrapped


@_malformed_is_value_error
def decode_header(data):
    """std_msgs/Header of the CDR bytes of any message whose first field is a Header
    (Image, CameraInfo, PointCloud2, ...), without decoding the rest."""
    return _header(memoryview(data))[0]


@_malformed_is_value_error
def decode_image(data):
    """CDR bytes-like -> Image with .data a memoryview of `data` (no copy)."""
    buf = memoryview(data)
    msg = Image()
    msg.header, off = _header(buf)
    off = _align(off, 4)
    msg.height, msg.width = struct.unpack_from('<II', buf, off)
    msg.encoding, off = _string(buf, off + 8)
    msg.is_bigendian = buf[off]
    off = _align(off + 1, 4)
    (msg.step,) = _U32.unpack_from(buf, off)
    msg.data, _ = _bytes(buf, off + 4)
    return msg


@_malformed_is_value_error
def decode_compressed_image(data):
    """CDR bytes-like -> CompressedImage with .data a memoryview of `data` (no copy)."""
    buf = memoryview(data)
    msg = CompressedImage()
    msg.header, off = _header(buf)
    msg.format, off = _string(buf, off)
    msg.data, _ = _bytes(buf, off)
    return msg
