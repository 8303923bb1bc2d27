"""Pure-numpy halves of the message conversions (no rclpy): stamps, CameraInfo,
heatmap images and keypoint clouds as plain field dicts, and their inverse on any
message-like object (rclpy, mcap_ros2 or rosbags decoded messages share attribute names).

Lengths in messages are metres (ROS REP 103), whatever the rig's unit: the keypoint cloud
is built from points in the rig's unit and read back into it (the `units` argument of
keypoint_cloud_fields / cloud_to_keypoints3d, required, which the builders of convert.py and
writer.py pass on, the skeleton markers included), and a TF transform (camera_pose_transform)
is in metres, as are the camera frustum markers (markers.frustum_marker_specs).
"""
import numpy as np

from monet_ros.geometry.units import convert

from .images import ImageDecodeError, image_fields, raw_image_array

# sensor_msgs/PointField datatypes
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)
_POINTFIELD_DTYPE = {INT8: 'i1', UINT8: 'u1', INT16: 'i2', UINT16: 'u2', INT32: 'i4',
                     UINT32: 'u4', FLOAT32: 'f4', FLOAT64: 'f8'}

# /monet/keypoints3d layout (PROTOCOL.md): one point per keypoint, point_step 28.
KEYPOINT_CLOUD_FIELDS = (
    ('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32), ('confidence', 12, FLOAT32),
    ('reprojection_error', 16, FLOAT32), ('num_views', 20, UINT32), ('keypoint', 24, UINT32),
)
KEYPOINT_POINT_STEP = 28
# With several subjects (the fusion node's `subjects` >= 2): one more field, the subject's
# identity, after the others (whose offsets are unchanged); point_step 32.
SUBJECT_FIELD = ('subject', 28, UINT32)
SUBJECT_POINT_STEP = 32


def split_stamp(stamp_ns):
    """Nanoseconds -> (sec, nanosec) of a builtin_interfaces/Time: sec is a signed int32
    (a stamp before 1970, e.g. sec = -1, is a valid header stamp), nanosec in [0, 1e9).
    ValueError outside the int32 seconds range."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    if not -2**31 <= sec < 2**31:
        raise ValueError(f'stamp {stamp_ns} ns is outside the int32 seconds of a ROS time')
    return sec, nanosec


def stamp_to_ns(stamp):
    """builtin_interfaces/Time (sec, nanosec) -> int nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def header_stamp_ns(msg):
    """header.stamp of a message in nanoseconds."""
    return stamp_to_ns(msg.header.stamp)


# ---------------------------------------------------------------- CameraInfo <-> Camera

def camera_info_fields(camera):
    """Fields of a sensor_msgs/CameraInfo (no header) for a Camera: K, D (OpenCV order),
    R = I, P = [K | 0], plumb_bob for <= 5 coefficients else rational_polynomial."""
    dist = np.asarray(camera.dist, np.float64).reshape(-1)
    if dist.size <= 5:
        model, d = 'plumb_bob', np.concatenate([dist, np.zeros(5 - dist.size)])
    elif dist.size <= 8:
        model, d = 'rational_polynomial', np.concatenate([dist, np.zeros(8 - dist.size)])
    else:
        model, d = 'rational_polynomial', dist
    K = np.asarray(camera.K, np.float64).reshape(3, 3)
    P = np.hstack([K, np.zeros((3, 1))])
    return dict(height=int(camera.height), width=int(camera.width), distortion_model=model,
                d=d, k=K.reshape(-1).copy(), r=np.eye(3).reshape(-1), p=P.reshape(-1))


def camera_from_camera_info(msg, name, R=None, t=None, topic=None):
    """sensor_msgs/CameraInfo -> monet_ros.geometry.Camera (intrinsics from K and D,
    extrinsics world -> camera R, t given; identity / zero when None).

    The camera is that of the images the driver publishes: a region of interest (roi,
    full-resolution pixels) and binning_x / binning_y (0 = 1) are applied to K and the size
    (REP 104: the image is (roi or width x height) / binning). Distortion models follow the
    one rule of monet_ros.geometry.rig.opencv_distortion (plumb_bob, rational_polynomial
    with any OpenCV count, or none); anything else is a ValueError naming the camera."""
    from monet_ros.geometry import Camera
    from monet_ros.geometry.rig import opencv_distortion

    d = opencv_distortion(msg.distortion_model, msg.d, f'camera {name}')
    if d.size == 0:
        d = np.zeros(5)
    K = np.asarray(msg.k, np.float64).reshape(3, 3)
    if not np.all(np.isfinite(K)) or K[2, 2] == 0 or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f'camera {name}: CameraInfo has no valid intrinsics (K = {K.tolist()})')
    width, height = int(msg.width), int(msg.height)
    roi = getattr(msg, 'roi', None)
    if roi is not None and int(roi.width) > 0 and int(roi.height) > 0:
        K = K.copy()
        K[0, 2] -= int(roi.x_offset)
        K[1, 2] -= int(roi.y_offset)
        width, height = int(roi.width), int(roi.height)
    bx = max(int(getattr(msg, 'binning_x', 0)), 1)
    by = max(int(getattr(msg, 'binning_y', 0)), 1)
    if bx > 1 or by > 1:      # as ROS image_geometry: fx / b, (cx - roi offset) / b
        K = np.diag([1 / bx, 1 / by, 1.0]) @ K
        width, height = width // bx, height // by
    R = np.eye(3) if R is None else np.asarray(R, np.float64)
    t = np.zeros(3) if t is None else np.asarray(t, np.float64)
    return Camera(name=name, K=K, dist=d, R=R, t=t, width=width, height=height, topic=topic)


# ---------------------------------------------------------------- heatmaps <-> Image

def heatmap_image_fields(heatmaps):
    """(C, h, w) heatmaps -> Image fields with encoding 32FC<C>: h x w pixels,
    channel-interleaved little-endian float32 (pixel (v, u) holds all C channels)."""
    hm = np.asarray(heatmaps, np.float32)
    if hm.ndim != 3 or hm.shape[0] < 1:
        raise ValueError(f'heatmaps must be (C, h, w), got shape {hm.shape}')
    return image_fields(np.moveaxis(hm, 0, -1), f'32FC{hm.shape[0]}')


def image_msg_to_heatmaps(msg):
    """Image with encoding 32FC<C> -> (C, h, w) float32 (a copy)."""
    enc = str(msg.encoding).upper()
    if not enc.startswith('32FC'):
        raise ImageDecodeError(f'heatmap image must have encoding 32FC<C>, got {msg.encoding!r}')
    arr = raw_image_array(msg)
    return np.ascontiguousarray(np.moveaxis(arr, -1, 0), dtype=np.float32)


# ---------------------------------------------------------------- keypoints3d <-> PointCloud2

def keypoints_to_metres(X, units):
    """(N, 3) points in the rig's length unit `units` -> in metres, as float64 (the one
    conversion of 3D points into messages)."""
    X = np.asarray(X, np.float64)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f'X must be (N, 3), got shape {X.shape}')
    return convert(X, units, 'm')


def keypoints_from_metres(X, units):
    """(N, 3) points read from a message (metres) -> in the rig's length unit `units`
    (float64; the one conversion of 3D points out of messages)."""
    return convert(np.asarray(X, np.float64), 'm', units)


def keypoint_cloud_fields(X, confidence=None, reprojection_error=None, num_views=None, *,
                          units, keypoint=None, subject=None):
    """PointCloud2 fields (no header) for N keypoints, in PROTOCOL.md's layout.

    X (N, 3) world points in the rig's length unit `units` ('m', 'cm', 'mm'; required),
    NaN where not triangulated: written in metres (REP 103); confidence,
    reprojection_error (px) (N,) float (NaN when None); num_views (N,) int (0 when None);
    keypoint (N,) int (None: 0..N-1); subject (N,) int >= 0: each point's subject identity,
    written as one more UINT32 field `subject` (point_step 32; None: no such field, the
    one-subject layout). `fields` is a list of (name, offset, datatype, count) tuples."""
    X = keypoints_to_metres(X, units)
    n = X.shape[0]

    def column(value, fill, name):
        if value is None:
            return np.full(n, fill)
        value = np.asarray(value).reshape(-1)
        if value.size != n:
            raise ValueError(f'{name} must have {n} values, got {value.size}')
        return value

    layout = KEYPOINT_CLOUD_FIELDS + ((SUBJECT_FIELD,) if subject is not None else ())
    step = SUBJECT_POINT_STEP if subject is not None else KEYPOINT_POINT_STEP
    rec = np.zeros(n, dtype=keypoint_cloud_dtype(subject is not None))
    rec['x'], rec['y'], rec['z'] = X[:, 0], X[:, 1], X[:, 2]
    rec['confidence'] = column(confidence, np.nan, 'confidence')
    rec['reprojection_error'] = column(reprojection_error, np.nan, 'reprojection_error')
    nv = column(num_views, 0, 'num_views')
    if np.any(nv < 0):
        raise ValueError('num_views must be >= 0')
    rec['num_views'] = nv
    rec['keypoint'] = np.arange(n) if keypoint is None else column(keypoint, 0, 'keypoint')
    if subject is not None:
        subject = column(subject, 0, 'subject')
        if np.any(subject < 0):
            raise ValueError('subject must be >= 0')
        rec['subject'] = subject
    return dict(height=1, width=n,
                fields=[(name, off, dt, 1) for name, off, dt in layout],
                is_bigendian=False, point_step=step,
                row_step=step * n, data=rec.view(np.uint8).reshape(-1),
                is_dense=bool(np.isfinite(X).all()))


def keypoint_cloud_dtype(subject=False):
    """numpy structured dtype of one /monet/keypoints3d point (itemsize 28; with
    `subject`, the several-subject layout: itemsize 32)."""
    layout = KEYPOINT_CLOUD_FIELDS + ((SUBJECT_FIELD,) if subject else ())
    return np.dtype({'names': [f[0] for f in layout],
                     'formats': ['<' + _POINTFIELD_DTYPE[f[2]] for f in layout],
                     'offsets': [f[1] for f in layout],
                     'itemsize': SUBJECT_POINT_STEP if subject else KEYPOINT_POINT_STEP})


def cloud_to_arrays(msg):
    """Any PointCloud2 -> dict field name -> (N,) array (count-1 fields; N = width*height),
    read by the message's own field offsets and datatypes."""
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    order = '>' if msg.is_bigendian else '<'
    names, formats, offsets = [], [], []
    for f in msg.fields:
        if int(f.datatype) not in _POINTFIELD_DTYPE:
            raise ValueError(f'PointCloud2 field {f.name!r} has unknown datatype {f.datatype}')
        count = max(int(f.count), 1)
        names.append(str(f.name))
        formats.append((order + _POINTFIELD_DTYPE[int(f.datatype)], (count,)) if count > 1
                       else order + _POINTFIELD_DTYPE[int(f.datatype)])
        offsets.append(int(f.offset))
    dtype = np.dtype({'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': step})
    raw = np.frombuffer(msg.data, np.uint8)
    row_step = int(msg.row_step) or step * int(msg.width)
    if raw.size < row_step * (int(msg.height) - 1) + step * int(msg.width):
        raise ValueError(f'PointCloud2 data has {raw.size} bytes, too few for {n} points')
    rows = [raw[r * row_step: r * row_step + step * int(msg.width)]
            for r in range(int(msg.height))]
    rec = np.concatenate(rows).view(dtype) if rows else np.zeros(0, dtype)
    return {name: np.array(rec[name]).astype(rec[name].dtype.newbyteorder('='))
            for name in names}


def cloud_to_keypoints3d(msg, *, units):
    """/monet/keypoints3d PointCloud2 (metres) -> dict: X (N, 3) float64 in the length unit
    `units` ('m', 'cm', 'mm'; required: that of the rig the points are used with),
    confidence, reprojection_error (N,) float64, num_views, keypoint, subject (N,) int64
    (subject: the several-subject field; 0 for every point of a one-subject cloud).
    Missing optional fields come back as NaN / 0; x, y, z are required."""
    cols = cloud_to_arrays(msg)
    missing = [k for k in ('x', 'y', 'z') if k not in cols]
    if missing:
        raise ValueError(f'PointCloud2 lacks field(s) {missing}')
    n = cols['x'].size
    out = {'X': keypoints_from_metres(np.stack([cols['x'], cols['y'], cols['z']], axis=1),
                                      units)}
    for name, fill, dtype in (('confidence', np.nan, np.float64),
                              ('reprojection_error', np.nan, np.float64),
                              ('num_views', 0, np.int64)):
        out[name] = cols[name].astype(dtype) if name in cols else np.full(n, fill, dtype)
    out['keypoint'] = cols['keypoint'].astype(np.int64) if 'keypoint' in cols \
        else np.arange(n, dtype=np.int64)
    out['subject'] = cols['subject'].astype(np.int64) if 'subject' in cols \
        else np.zeros(n, np.int64)
    return out


# ---------------------------------------------------------------- TF

def quaternion_to_matrix(x, y, z, w):
    """Unit quaternion (x, y, z, w) -> (3, 3) rotation matrix (normalised first)."""
    q = np.array([x, y, z, w], np.float64)
    with np.errstate(over='ignore', invalid='ignore'):
        norm = np.linalg.norm(q)
    if not np.isfinite(norm) or norm < 1e-12:
        raise ValueError(f'invalid quaternion {q.tolist()}')
    x, y, z, w = q / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrix_to_quaternion(R):
    """(3, 3) rotation matrix -> (x, y, z, w) unit quaternion with w >= 0."""
    R = np.asarray(R, np.float64)
    m = np.array([
        [R[0, 0] - R[1, 1] - R[2, 2], R[1, 0] + R[0, 1], R[2, 0] + R[0, 2], R[2, 1] - R[1, 2]],
        [R[1, 0] + R[0, 1], R[1, 1] - R[0, 0] - R[2, 2], R[2, 1] + R[1, 2], R[0, 2] - R[2, 0]],
        [R[2, 0] + R[0, 2], R[2, 1] + R[1, 2], R[2, 2] - R[0, 0] - R[1, 1], R[1, 0] - R[0, 1]],
        [R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1], R[0, 0] + R[1, 1] + R[2, 2]],
    ]) / 3.0
    vals, vecs = np.linalg.eigh(m)          # Bar-Itzhack: the eigenvector of the largest value
    q = vecs[:, np.argmax(vals)]
    return q if q[3] >= 0 else -q


def camera_pose_transform(camera):
    """World -> camera (R, t) of a Camera -> the TF transform parent(world) -> camera frame:
    (translation = camera centre (3,) in metres, from the camera's `units`; quaternion
    (x, y, z, w) of R^T)."""
    R = np.asarray(camera.R, np.float64)
    t = np.asarray(camera.t, np.float64).reshape(3)
    return convert(-R.T @ t, getattr(camera, 'units', 'm'), 'm'), matrix_to_quaternion(R.T)


def extrinsics_from_pose(translation, quaternion):
    """TF transform world -> camera frame (the camera's pose) -> world -> camera (R, t)
    in the Camera convention x ~ K (R X + t)."""
    Rwc = quaternion_to_matrix(*quaternion)
    R = Rwc.T
    return R, -R @ np.asarray(translation, np.float64).reshape(3)
