"""player node: replay a recording (rosbag2 folder or bare .mcap) on ROS topics.

Publishes the bag's image, compressed image and camera_info topics and /tf_static (or the
`topics` given) as their raw CDR bytes, so any message type whose Python package is
installed can be replayed unchanged, plus /clock (the bag time). Messages go out in the
reader's log-time order (deterministic), at the recorded pace scaled by `rate` (0 = as fast
as possible), from `start_offset_s` into the bag, optionally looping. Topic names are
remapped with ordinary ROS remapping (`--ros-args -r /cam0/image_raw:=/left/image_raw`).

For `monet pipeline` (which runs it in its own process: monet_ros.nodes.child) two options:
`lockstep` publishes a frame only once the keypoints3d of the previous one arrived (every
frame processed, pace = processing speed), and `announce_frames` publishes on
`played_frames` (std_msgs/Int64MultiArray) [header stamp ns, wall time ns (CLOCK_REALTIME)]
just before each frame's first image goes out, and an empty array when a pass ends the
replay (no loop): what the pipeline times latency from and knows the end by, without
receiving a single image.
"""
from dataclasses import dataclass
import importlib
import struct
import sys
import threading
import time
from types import SimpleNamespace

from builtin_interfaces.msg import Time
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Int64MultiArray

from monet_ros.config import ConfigError, setting, validate_config
from monet_ros.io import camera_name_for_topic, open_bag
from monet_ros.io.fast_cdr import decode_header
from monet_ros.io.fields import stamp_to_ns
from monet_ros.nodes.names import KEYPOINTS3D, PLAYED_FRAMES, node_namespace
from monet_ros.nodes.params import declare_config
from monet_ros.nodes.qos import IMAGE_OUT, LATCHED, STREAM_IN, STREAM_OUT
from monet_ros.nodes.runner import run_node

DEFAULT_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage',
                 'sensor_msgs/msg/CameraInfo', 'tf2_msgs/msg/TFMessage')
IMAGE_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage')
CAMERA_INFO = ('sensor_msgs/msg/CameraInfo',)
LATCHED_TOPICS = ('/tf_static',)


@dataclass(frozen=True)
class PlayerConfig:
    bag: str = setting('', 'recording: rosbag2 folder (metadata.yaml + .mcap) or a bare .mcap; '
                       'required')
    topics: tuple[str, ...] = setting((), 'topics to replay (default: every image, '
                                      'compressed image and camera_info topic, and /tf_static)')
    rate: float = setting(1.0, 'playback speed factor (0 = as fast as possible)', minimum=0.0)
    loop: bool = setting(False, 'start again at the end; every pass after the first shifts the '
                         'header stamps (and /clock) by the recording length plus one frame, '
                         'so time keeps running forward')
    start_offset_s: float = setting(0.0, 'skip this many seconds from the start of the bag',
                                    minimum=0.0)
    clock: bool = setting(True, 'publish /clock with the bag time')
    wait_for_subscribers: int = setting(1, 'before playing, wait until every replayed image '
                                        'and camera_info topic has this many subscribers '
                                        '(0 = do not wait)', minimum=0)
    wait_for_topics: tuple[str, ...] = setting((), 'also wait until these topics have '
                                               'wait_for_subscribers subscribers ({camera} = '
                                               'each camera of the recording; relative names '
                                               'are in the node namespace), e.g. '
                                               '{camera}/heatmaps for a fusion node')
    wait_for_subscribers_s: float = setting(30.0, 'give up waiting for subscribers after this '
                                            'long and play anyway, with a warning (0 = wait '
                                            'forever)', minimum=0.0)
    start_delay_s: float = setting(1.0, 'wait this long before playing (after the subscribers): '
                                   'lets late discovery finish so no first frame is lost',
                                   minimum=0.0)
    shutdown_when_done: bool = setting(False, 'exit when the bag has been played (no loop)')
    lockstep: bool = setting(False, 'publish a frame only once the keypoints3d (node-relative) '
                             'of the previous frame arrived, at most lockstep_timeout_s '
                             '(then it goes anyway, counted and logged); also waits for a '
                             'keypoints3d publisher before playing. Use with rate 0')
    lockstep_timeout_s: float = setting(5.0, "lockstep: longest wait for the previous frame's "
                                        'keypoints3d', minimum=0.001)
    announce_frames: bool = setting(False, 'publish played_frames (Int64MultiArray [stamp ns, '
                                    'wall ns] before each frame, [] at the end of the replay)')

    def __post_init__(self):
        validate_config(self)


def waitable_s(seconds):
    """`seconds` as a threading wait timeout; ValueError beyond threading.TIMEOUT_MAX."""
    if not 0 <= seconds <= threading.TIMEOUT_MAX:
        raise ValueError(f'{seconds!r} s is beyond the longest wait ({threading.TIMEOUT_MAX:.3g}'
                         ' s)')
    return seconds


def derive(config):
    """What the parameters of a PlayerConfig feed (no ROS), checked at start
    (monet_ros.nodes.params): the start offset in ns, the start delay as a wait, the wall
    seconds per recorded second (0 = as fast as possible). Raises ArithmeticError or
    ValueError where a value overflows; derive_checked names the parameter."""
    return SimpleNamespace(offset_ns=int(config.start_offset_s * 1e9),
                           start_delay_s=waitable_s(config.start_delay_s),
                           pace=1.0 / config.rate if config.rate > 0 else 0.0)


_CDR_STAMP = struct.Struct('<iI')


def cdr_header_stamp_ns(data):
    """header.stamp (ns) of a little-endian CDR message that starts with a std_msgs/Header
    (Image, CompressedImage, CameraInfo, ...): 4 bytes of encapsulation, then sec, nanosec."""
    if len(data) < 12 or bytes(data[:2]) != b'\x00\x01':
        return None
    sec, nanosec = _CDR_STAMP.unpack_from(data, 4)
    return sec * 1_000_000_000 + nanosec


def shift_cdr_header_stamp(data, shift_ns):
    """A copy of a header-first CDR message with header.stamp moved by shift_ns (messages
    without a little-endian header are returned unchanged)."""
    stamp = cdr_header_stamp_ns(data)
    if stamp is None:
        return data
    stamp += shift_ns
    out = bytearray(data)
    _CDR_STAMP.pack_into(out, 4, stamp // 1_000_000_000, stamp % 1_000_000_000)
    return bytes(out)


def message_class(msgtype):
    """'pkg/msg/Type' -> the rclpy message class (ImportError when not installed)."""
    package, _, name = msgtype.rpartition('/')
    package = package.replace('/', '.')
    try:
        return getattr(importlib.import_module(package), name)
    except AttributeError:
        raise ImportError(f'{package} has no message {name}') from None


class PlayerNode(Node):
    def __init__(self, overrides=None, node_name='player', **kwargs):
        super().__init__(node_name, **node_namespace(kwargs))
        self.config = config = declare_config(self, PlayerConfig, overrides, derive=derive)
        self.derived = derive(config)
        if not config.bag:
            raise ConfigError(self.get_name(), 'bag', 'is required (a recording path)')
        self.reader = open_bag(config.bag)
        available = self.reader.topics
        if config.topics:
            unknown = [t for t in config.topics if t not in available]
            if unknown:
                raise ConfigError(self.get_name(), 'topics', f'{unknown[0]!r} is not in '
                                  f'{config.bag} (it has {sorted(available)})')
            wanted = list(config.topics)
        else:
            wanted = sorted(t for t, info in available.items() if info.msgtype in DEFAULT_TYPES)
        self.pubs = {}
        self.skipped = {}
        for topic in wanted:
            msgtype = available[topic].msgtype
            try:
                cls = message_class(msgtype)
            except ImportError as error:
                self.skipped[topic] = f'{msgtype} is not installed ({error})'
                continue
            qos = (LATCHED if topic in LATCHED_TOPICS
                   else IMAGE_OUT if msgtype in IMAGE_TYPES else STREAM_OUT)
            self.pubs[topic] = self.create_publisher(cls, topic, qos)
        if not self.pubs:
            raise ConfigError(self.get_name(), 'topics', f'nothing to replay from '
                              f'{config.bag}: {self.skipped or "no matching topics"}')
        for topic, reason in self.skipped.items():
            self.get_logger().warning(f'not replaying {topic}: {reason}')
        self.image_topics = [t for t in self.pubs if available[t].msgtype in IMAGE_TYPES]
        self.image_set = set(self.image_topics)
        self.clock_pub = self.create_publisher(Clock, '/clock', STREAM_OUT) \
            if config.clock else None
        self.published = 0
        self.loops = 0
        self.listeners = []       # callables(topic, stamp_ns, wall_time) per image message
        self.gate = None          # callable(previous_frame_stamp_ns) blocking until the next
        #                           frame may go (lockstep replay in `monet pipeline`)
        self.span = (2 ** 63, 0, 0)   # first, last image log time and frames of pass 1
        self.fused = threading.Condition()
        self.fused_stamp = -1         # lockstep: the newest keypoints3d stamp received
        self.lockstep_timeouts = 0
        self.last_frame_stamp = None
        if config.lockstep:
            # serialized: only the header's stamp is read, never the cloud
            self.create_subscription(PointCloud2, KEYPOINTS3D, self.on_keypoints, STREAM_IN,
                                     raw=True)
            self.gate = self.wait_fused
        self.frames_pub = self.create_publisher(Int64MultiArray, PLAYED_FRAMES, STREAM_OUT) \
            if config.announce_frames else None
        self.done = threading.Event()
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self.play, name='player', daemon=True)
        self.get_logger().info(f'replaying {config.bag}: {sorted(self.pubs)} at rate '
                               f'{config.rate}{" (loop)" if config.loop else ""}')
        self.thread.start()

    # ------------------------------------------------------------------ lockstep
    def on_keypoints(self, data):
        try:
            stamp = stamp_to_ns(decode_header(data).stamp)
        except ValueError as error:
            self.get_logger().warning(f'{self.resolve_topic_name(KEYPOINTS3D)}: bad message '
                                      f'({error})', throttle_duration_sec=5.0)
            return
        with self.fused:
            self.fused_stamp = max(self.fused_stamp, stamp)
            self.fused.notify_all()

    def wait_fused(self, previous_stamp):
        """Block until keypoints3d of `previous_stamp` (or later) arrived, the node stops,
        or lockstep_timeout_s passed (counted; logged once)."""
        deadline = time.monotonic() + self.config.lockstep_timeout_s
        with self.fused:
            while self.fused_stamp < previous_stamp and not self.stopping.is_set():
                left = deadline - time.monotonic()
                if left <= 0:
                    self.lockstep_timeouts += 1
                    if self.lockstep_timeouts == 1:
                        self.get_logger().warning(
                            f'lockstep: no {self.resolve_topic_name(KEYPOINTS3D)} for stamp '
                            f'{previous_stamp} within {self.config.lockstep_timeout_s} s: '
                            'playing on (counted; logged once)')
                    return
                self.fused.wait(min(left, 0.1))

    def announce(self, values):
        if self.frames_pub is not None:
            self.frames_pub.publish(Int64MultiArray(data=values))

    # ------------------------------------------------------------------ playback
    def wait_for_subscribers(self):
        available = self.reader.topics
        topics = [t for t in self.pubs if available[t].msgtype in IMAGE_TYPES + CAMERA_INFO]
        topics = topics or list(self.pubs)
        cameras = sorted({camera_name_for_topic(t) for t in self.image_topics})
        others = [self.resolve_topic_name(t.format(camera=c))
                  for t in self.config.wait_for_topics for c in cameras]
        topics = topics + sorted(set(others))
        wanted = self.config.wait_for_subscribers
        limit = self.config.wait_for_subscribers_s
        start = time.monotonic()
        while not self.stopping.is_set():
            missing = [t for t in topics
                       if (self.pubs[t].get_subscription_count() if t in self.pubs
                           else self.count_subscribers(t)) < wanted]
            if self.config.lockstep and not self.count_publishers(KEYPOINTS3D):
                missing.append(f'{self.resolve_topic_name(KEYPOINTS3D)} (a publisher)')
            if not missing:
                self.get_logger().info(f'{len(topics)} topics have {wanted} subscriber(s) '
                                       f'after {time.monotonic() - start:.1f} s: playing')
                return
            if limit and time.monotonic() - start >= limit:
                self.get_logger().warning(
                    f'playing without waiting longer (wait_for_subscribers_s={limit}): '
                    f'{len(missing)} topics have fewer than {wanted} subscriber(s), e.g. '
                    f'{missing[0]}')
                return
            time.sleep(0.02)

    def play(self):
        try:
            if self.config.wait_for_subscribers:
                self.wait_for_subscribers()
            if self.stopping.wait(self.derived.start_delay_s):
                return
            while not self.stopping.is_set():
                self.play_once(self.loops * self.loop_shift_ns)
                self.loops += 1
                if not self.config.loop:
                    if not self.stopping.is_set():
                        self.announce([])          # the end of the replay
                    break
        except Exception as error:  # noqa: BLE001 - report, never kill the process silently
            if not self.stopping.is_set() and self.context.ok():
                self.get_logger().error(f'playback stopped: {type(error).__name__}: {error}')
        finally:
            self.done.set()
            report = getattr(self.reader, 'report', None)
            if self.context.ok():
                if report is not None and not report.ok:
                    self.get_logger().warning(f'{self.config.bag}: {report.summary()}')
                self.get_logger().info(f'played {self.published} messages ({self.loops} '
                                       'passes)')
            if self.config.shutdown_when_done and not self.stopping.is_set():
                self.context.try_shutdown()

    @property
    def loop_shift_ns(self):
        """Stamp shift per loop pass: the span of the first pass plus one frame period."""
        first, last, frames = self.span
        period = (last - first) // max(frames - 1, 1) if frames > 1 else 1_000_000
        return last - first + period

    def play_once(self, shift_ns=0):
        """One pass over the bag; shift_ns is added to header stamps and /clock."""
        start_wall = None
        first_log = None
        # log time and stamp of the current image frame (the stamp carries over from the
        # previous pass: lockstep gates a pass's first frame on the last one before it)
        frame_log, frame_stamp = None, self.last_frame_stamp
        offset_ns = self.derived.offset_ns
        for item in self.reader.messages(list(self.pubs), decode=False):
            if self.stopping.is_set():
                return
            if first_log is None:
                first_log = item.log_time_ns
            if item.log_time_ns - first_log < offset_ns and item.topic not in LATCHED_TOPICS:
                continue
            if start_wall is None:
                start_wall, start_log = time.monotonic(), item.log_time_ns
            if self.config.rate > 0:
                due = start_wall + (item.log_time_ns - start_log) / 1e9 * self.derived.pace
                delay = due - time.monotonic()
                if delay > 0 and self.stopping.wait(min(delay, threading.TIMEOUT_MAX)):
                    return
            image = item.topic in self.image_set
            if shift_ns == 0 and image:
                self.span = (min(self.span[0], item.log_time_ns),
                             max(self.span[1], item.log_time_ns),
                             self.span[2] + (item.log_time_ns != frame_log))
            data = bytes(item.data)
            if shift_ns and item.topic not in LATCHED_TOPICS:
                data = shift_cdr_header_stamp(data, shift_ns)
            if image and item.log_time_ns != frame_log:
                if self.gate is not None and frame_stamp is not None:
                    self.gate(frame_stamp)
                    if self.stopping.is_set():
                        return
                frame_log = item.log_time_ns
                frame_stamp = cdr_header_stamp_ns(data) or item.log_time_ns
                self.last_frame_stamp = frame_stamp
                self.announce([frame_stamp, time.time_ns()])
            if self.clock_pub is not None:
                clock_ns = item.log_time_ns + shift_ns
                self.clock_pub.publish(Clock(clock=Time(sec=clock_ns // 1_000_000_000,
                                                        nanosec=clock_ns % 1_000_000_000)))
            self.pubs[item.topic].publish(data)
            self.published += 1
            if image:
                now = time.monotonic()
                for listener in self.listeners:
                    listener(item.topic, frame_stamp, now)

    def destroy_node(self):
        self.stopping.set()
        if self.thread.is_alive():
            self.thread.join(timeout=5)
        return super().destroy_node()


def main(args=None):
    return run_node(PlayerNode, 'player', args, large_data=True)


if __name__ == '__main__':
    sys.exit(main())
