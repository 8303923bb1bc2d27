"""detector node: camera images -> /monet/<cam>/heatmaps + /monet/<cam>/camera_info.

One or several cameras per node; the cameras' frames of one instant (the same stamp, or
within `slop_ms`: monet_ros.sync.newest_common_instant, the newest instant every camera has
among its last PENDING_FRAMES) are run through the network in one batched forward pass
(monet_ros.models.Detector), so that a detector running behind its cameras skips whole
instants and never mixes two in one batch; a camera whose frame of that instant did not
come within `batch_wait_ms` is left out (the newest frame of each camera, counted as an
incomplete batch). The crop
follows the subject (projection of the latest /monet/keypoints3d, when the rig gives the
extrinsics; monet_ros.crop_rule, the one crop rule), else `box`, else the full frame. The
topic is in metres (REP 103): its points are read into the rig's length unit before they
are projected with the rig's cameras (the crop, the debug image).
The outputs keep the source stamp; the camera_info is the heatmap's virtual camera
(K_heat = S K). A frame skipped (an older instant than the one processed, or pushed
out of the PENDING_FRAMES) is counted as dropped; a bad
message is counted and logged, never fatal.
The checkpoint is hot-reloaded from /monet/model (std_msgs/String JSON {path, sha256}).

Several subjects (`subjects` N >= 2, with the fusion node's `subjects` and
`discovery_tiles` the same; docs/subjects.md "Live"): per camera and instant, N + D crop
slots are published on `<cam>/crop<k>/heatmaps` + `<cam>/crop<k>/camera_info` (the
`<cam>/heatmaps` topics of one subject are not): slot k < N the crop rule's box around the
k-th subject (by identity) of the latest /monet/keypoints3d (its `subject` field;
crop_rule.TrackedSubjects), slots N..N+D-1 the discovery maps while fewer than N subjects
are in it, in the first frame of each `discovery_period_s` window of the stamps
(crop_rule.discovery_due; 0: every frame): `box` when given, else the maps of
`monet process --subjects`' discovery (subjects.detection.discovery_boxes: the whole frame,
or, where the network would shrink it more than 2 times, its discovery_tiles square tiles,
one slot each; D = subjects.detection.discovery_slots of the rig camera's size). A slot
without a crop in that view at that instant is an empty (0 x 0) heatmap and camera_info.
All crops of the instant go through the network in one batch. JPEG views are decoded in
full (each view has crops of several scales). Not with debug_image; discovery_tiles >= 1
needs the rig (the slots are laid out for its image sizes).
"""
from collections import deque
from dataclasses import dataclass
import json
from pathlib import Path
import sys
import time
from types import SimpleNamespace

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, PointCloud2
from std_msgs.msg import String

from monet_ros.atomic import sha256_file
from monet_ros.config import MAX_THREADS, ConfigError, setting, validate_config
from monet_ros.crop_rule import DISCOVERY_PERIOD_S, TrackedCrops, TrackedRule, TrackedSubjects
from monet_ros.error_text import error_line
from monet_ros.geometry.units import UNITS, rig_units
from monet_ros.int8_calibration import int8_calibration
from monet_ros.io import (
    camera_from_camera_info,
    camera_info_from_camera,
    cloud_to_keypoints3d,
    empty_crop_messages,
    header_stamp_ns,
    heatmaps_to_image_msg,
    numpy_to_image_msg,
)
from monet_ros.io.debug_image import debug_image, heatmap_peaks_in_image
from monet_ros.io.images import raw_to_rgb8, view_for_crop
from monet_ros.io.jpeg_scale import decode_views, is_jpeg, jpeg_size
from monet_ros.models import CheckpointError, Detector
from monet_ros.models.detector import PRECISIONS
from monet_ros.models.device import check_device
from monet_ros.models.onnx_backend import BACKEND_CHOICES
from monet_ros.nodes.names import (
    DEBUG_CAMERA_INFO,
    DEBUG_IMAGE,
    DIAGNOSTICS,
    HEATMAP_CAMERA_INFO,
    HEATMAPS,
    KEYPOINTS3D,
    MODEL,
    crop_slots,
    node_namespace,
)
from monet_ros.nodes.params import declare_config
from monet_ros.nodes.qos import IMAGE_IN, LATCHED, STREAM_IN, STREAM_OUT
from monet_ros.nodes.runner import log_bad_once, run_node
from monet_ros.rig_select import load_node_rig, select_cameras
from monet_ros.subjects.detection import SubjectsConfig, discovery_boxes, discovery_slots
from monet_ros.sync import newest_common_instant
from monet_ros.timing import StageTimer

# Parameters that may change while running (`ros2 param set`), effective next frame.
LIVE = ('track', 'track_margin', 'track_timeout_s', 'min_track_keypoints', 'batch_wait_ms',
        'slop_ms')
# Unprocessed frames kept per camera: the newest instant common to every camera is looked
# for among these (a camera one or two frames ahead of another still meets it).
PENDING_FRAMES = 3


@dataclass(frozen=True)
class DetectorConfig:
    model: str = setting('', 'detector checkpoint (.pt); required')
    cameras: tuple[str, ...] = setting((), 'cameras of this node (default: all of the rig); '
                                       'several cameras are batched in one forward pass')
    rig: str = setting('', 'rig file or recording: camera names, image topics and the '
                       'extrinsics used to crop around /monet/keypoints3d (optional)')
    rig_units: str = setting('', "length unit of a rig file that states none (m, cm, mm; "
                             "'' = the file's, else the rule of geometry.units): "
                             '/monet/keypoints3d (m) is read into it', choices=('',) + UNITS)
    image_topic: str = setting('', 'image topic template, {camera} = name (default: the rig '
                               'camera topic, else /{camera}/image_raw)',
                               template_fields=('camera',))
    camera_info_topic: str = setting('', 'camera_info topic template (default: camera_info '
                                     'beside the image topic)', template_fields=('camera',))
    transport: str = setting('auto', 'raw = sensor_msgs/Image; compressed = CompressedImage '
                             'on <image_topic>/compressed; auto = as the rig says (a recording '
                             'with only compressed images, or a rig topic ending in '
                             '/compressed: compressed), else raw',
                             choices=('auto', 'raw', 'compressed'))
    box: tuple[float, ...] = setting((), 'fixed crop box x0 y0 x1 y1 (pixel edges) when no '
                                     'subject is tracked (default: full frame)', length=(0, 4))
    track: bool = setting(True, 'crop around the projection of the latest /monet/keypoints3d')
    track_margin: float = setting(TrackedRule.margin, 'tracked box margin, fraction of its '
                                  'size per side', minimum=0.0)
    track_timeout_s: float = setting(
        TrackedRule.timeout_ns / 1e9, "keypoints3d whose stamp is older than the image's by "
        'more than this are not used for the crop (source stamps, so a replay crops alike at '
        'any speed)', minimum=0.0)
    track_trim: float = setting(
        TrackedRule.trim, 'tracked box: leave out projected keypoints farther than this many '
        'robust sigmas (MAD) from the median (0 = none)', minimum=0.0)
    min_track_keypoints: int = setting(TrackedRule.min_points, 'fewest projected keypoints '
                                       'for a tracked crop', minimum=1)
    batch_wait_ms: float = setting(15.0, 'with several cameras: wait this long for the other '
                                   "cameras' frames of an instant before running an "
                                   "incomplete batch (each camera's newest frame)",
                                   minimum=0.0)
    slop_ms: float = setting(0.0, "stamp tolerance between cameras (0 = exact), as fusion's "
                             'slop_ms: frames within it are one instant, batched together',
                             minimum=0.0)
    debug_image: bool = setting(False, 'also publish <cam>/debug_image (bgr8: the source image '
                                'with the crop box, detected peaks and fused keypoints '
                                'reprojected) and its camera_info, when subscribed')
    debug_image_rate_hz: float = setting(2.0, 'most debug images per second per camera',
                                         minimum=0.0, exclusive_minimum=True)
    debug_image_scale: float = setting(0.5, 'debug image size, fraction of the source image',
                                       minimum=0.0, exclusive_minimum=True, maximum=1.0)
    lockstep: bool = setting(False, 'process a frame only once the /monet/keypoints3d of the '
                             'previous processed frame arrived (at most lockstep_timeout_s), so '
                             "that every crop follows the previous frame's 3D whatever order "
                             'the messages arrive in (`monet pipeline --lockstep`)')
    lockstep_timeout_s: float = setting(2.0, 'lockstep: longest wait for the previous '
                                        "frame's keypoints3d (then counted in /diagnostics)",
                                        minimum=0.0)
    device: str = setting('', "torch device ('' = CUDA when available, else CPU)")
    threads: int = setting(0, 'CPU threads of the network (torch and onnxruntime; 0 = their '
                           'default) and of decoding and cropping the views of an instant (0 = '
                           'the cores the process may use)', minimum=0, maximum=MAX_THREADS)
    backend: str = setting('auto', 'inference backend: auto (onnxruntime for float32 and int8 '
                           'on a CPU, torch for bfloat16 and on a GPU; the start-up line says '
                           'which), torch, or onnxruntime (the network exported to ONNX once, '
                           'cached beside the checkpoint)', choices=BACKEND_CHOICES)
    precision: str = setting('auto', 'network arithmetic: auto (bfloat16 with torch where '
                             'native, else float32; never int8, measured slower; the start-up '
                             'line says which and why), float32, bfloat16 (torch backend, 2-3x '
                             'faster on CPUs with AVX512-BF16 / AMX and on CUDA; peaks ~0.05 '
                             "input px (median) from float32's), or int8 (backend onnxruntime, "
                             'CPU with VNNI / AMX-INT8; needs calibration or a cached quant)',
                             choices=PRECISIONS)
    calibration: str = setting('', 'precision int8: a recording (rosbag2 folder or .mcap) to '
                               'calibrate the quantisation on, with the crops this node makes '
                               '(track true: tracked crops made by the float32 network with '
                               "the track_* rule, which needs the recording's rig; false: "
                               "box's crops, else full-frame crops), or a cached "
                               '<model>.<sha>.<crops>.int8.onnx quant of those crops; '
                               'checked, but not read, when the checkpoint has a cached '
                               'quant of those crops')
    subjects: int = setting(1, "most subjects cropped per view (as the fusion node's "
                            'subjects); 1 = the one-subject topics; N >= 2 publishes the '
                            'crop slots <cam>/crop<k>/heatmaps (docs/subjects.md)',
                            minimum=1)
    discovery_tiles: int = setting(
        SubjectsConfig.discovery_tiles, "subjects >= 2 (as the fusion node's "
        'discovery_tiles): the discovery maps of a camera whose whole frame the network '
        'would shrink more than 2 times are square tiles, this many along the shorter image '
        'side, overlapping by half, one crop slot each (as `monet process --subjects`; 0: '
        'the whole frame; needs the rig)', minimum=0)
    discovery_period_s: float = setting(
        DISCOVERY_PERIOD_S, 'subjects >= 2: while fewer than `subjects` subjects are tracked, the '
        'discovery maps are sent in the first frame of each window of this many seconds of '
        'the stamp clock (the same frames on every detector of the rig; '
        'crop_rule.discovery_due), their slots empty in the other frames: a new or '
        'lost subject waits at most this long, and a missing one does not cost the '
        'discovery crops of every frame (0: every frame)', minimum=0.0)

    def __post_init__(self):
        validate_config(self)


# The widest image side a crop box is checked against (px): what a margin feeds must stay
# finite for any camera.
WIDEST_IMAGE_PX = 2.0 ** 16


def derive(config):
    """What the parameters of a DetectorConfig feed (no ROS), built before they are used at
    start and before a live change is applied (monet_ros.nodes.params): the crop rule, the
    flush timer's period, the stamp tolerance in ns, the widest tracked box and trim
    distance (px) for an image WIDEST_IMAGE_PX wide, the debug image period (s). Raises
    ArithmeticError or ValueError where a value overflows; derive_checked names the
    parameter."""
    return SimpleNamespace(
        rule=DetectorNode.tracked_rule(config),
        flush_period_ns=int(DetectorNode.flush_period_s(config) * 1e9),
        batch_wait_s=config.batch_wait_ms / 1e3,
        slop_ns=int(round(config.slop_ms * 1e6)),
        widest_box_px=WIDEST_IMAGE_PX * (1.0 + 2.0 * config.track_margin),
        widest_trim_px=WIDEST_IMAGE_PX * config.track_trim,
        debug_period_s=1.0 / config.debug_image_rate_hz,
        lockstep_timeout_s=config.lockstep_timeout_s)


class CameraSlot:
    """Per-camera state: the newest unprocessed frame, intrinsics and counters."""

    def __init__(self, name, rig_camera, image_topic, info_topic):
        self.name = name
        self.rig_camera = rig_camera
        self.image_topic = image_topic
        self.info_topic = info_topic
        # unprocessed frames in arrival order: (stamp ns, msg, arrival monotonic)
        self.frames = deque(maxlen=PENDING_FRAMES)
        self.info_key = None
        self.camera = None           # Camera from the latest camera_info (rig extrinsics)
        self.received = self.processed = self.dropped = self.bad = 0
        self.last_debug = -float('inf')   # monotonic time of the last debug image
        self.last_bad = ''


def camera_slots(config, owner='detector'):
    """The CameraSlot of every camera of a DetectorConfig (names, rig cameras, image and
    camera_info topics; no network is loaded), as the detector node subscribes them.
    Raises ConfigError (no rig and no cameras, unknown camera) or OSError (rig file)."""
    if config.rig:
        rig, _ = load_node_rig(config.rig, config.rig_units)
        rig_cameras = select_cameras(owner, rig, config.cameras)
        names = [c.name for c in rig_cameras]
    elif not config.cameras:
        raise ConfigError(owner, 'cameras', 'is required when no rig is given')
    else:
        names, rig_cameras = list(config.cameras), [None] * len(config.cameras)
    slots = []
    for name, rig_camera in zip(names, rig_cameras):
        base = (config.image_topic.format(camera=name) if config.image_topic
                else (rig_camera.topic if rig_camera is not None and rig_camera.topic
                      else f'/{name}/image_raw'))
        compressed = (config.transport == 'compressed' or config.transport == 'auto'
                      and base.endswith('/compressed'))
        base = base[:-len('/compressed')] if base.endswith('/compressed') else base
        image_topic = base + '/compressed' if compressed else base
        info_topic = (config.camera_info_topic.format(camera=name) if config.camera_info_topic
                      else base.rsplit('/', 1)[0] + '/camera_info')
        slots.append(CameraSlot(name, rig_camera, image_topic, info_topic))
    return slots


class DetectorNode(Node):
    def __init__(self, overrides=None, node_name='detector', **kwargs):
        super().__init__(node_name, **node_namespace(kwargs))
        self.config = config = declare_config(self, DetectorConfig, overrides, live=LIVE,
                                              on_change=self.apply_live, derive=derive)
        self.derived = derive(config)
        if config.threads:
            import torch
            torch.set_num_threads(config.threads)
        if not config.model:
            raise ConfigError(self.get_name(), 'model', 'is required (a checkpoint path)')
        # 'cuda' where there is none: named, before any network is built
        self.device = check_device(self.get_name(), config.device)
        if config.box:
            x0, y0, x1, y1 = config.box
            if not (x1 > x0 and y1 > y0):
                raise ConfigError(self.get_name(), 'box', f'needs x1 > x0 and y1 > y0, got '
                                  f'{list(config.box)}')
        if config.subjects > 1 and config.debug_image:
            raise ConfigError(self.get_name(), 'debug_image', 'is not available with subjects '
                              '>= 2')
        self.slots = camera_slots(config, self.get_name())
        if (config.subjects > 1 and config.discovery_tiles and not config.box
                and any(s.rig_camera is None for s in self.slots)):
            raise ConfigError(self.get_name(), 'discovery_tiles', 'needs the rig (its crop '
                              "slots are laid out for the cameras' image sizes): give rig, "
                              'or set discovery_tiles 0')
        self.detector = self.load_detector(config.model)
        self.model_sha256 = sha256_file(config.model)
        self.pubs = {}
        for slot in self.slots:
            if slot.image_topic.endswith('/compressed'):
                self.create_subscription(CompressedImage, slot.image_topic,
                                         lambda m, s=slot: self.on_image(s, m), IMAGE_IN)
            else:
                self.create_subscription(Image, slot.image_topic,
                                         lambda m, s=slot: self.on_image(s, m), IMAGE_IN)
            self.create_subscription(CameraInfo, slot.info_topic,
                                     lambda m, s=slot: self.on_camera_info(s, m), STREAM_IN)
            if config.subjects > 1:      # the crop slots (fusion.crop_slots)
                self.pubs[slot.name] = [
                    (self.create_publisher(Image, HEATMAPS.format(camera=key), STREAM_OUT),
                     self.create_publisher(CameraInfo, HEATMAP_CAMERA_INFO.format(camera=key),
                                           STREAM_OUT))
                    for key in crop_slots(slot.name, config.subjects,
                                          self.discovery_count(slot))]
                continue
            self.pubs[slot.name] = (
                self.create_publisher(Image, HEATMAPS.format(camera=slot.name), STREAM_OUT),
                self.create_publisher(CameraInfo, HEATMAP_CAMERA_INFO.format(camera=slot.name),
                                      STREAM_OUT),
                (self.create_publisher(Image, DEBUG_IMAGE.format(camera=slot.name),
                                       STREAM_OUT),
                 self.create_publisher(CameraInfo, DEBUG_CAMERA_INFO.format(camera=slot.name),
                                       STREAM_OUT))
                if config.debug_image else None)
        # keypoints3d (m) read into the rig's unit, that of the cameras they are projected with
        self.units = rig_units([s.rig_camera for s in self.slots if s.rig_camera is not None])
        self.tracker = TrackedCrops(self.derived.rule, self.units)
        self.subject_tracks = TrackedSubjects(self.derived.rule, self.units,
                                              self.config.discovery_period_s)
        self.create_subscription(PointCloud2, KEYPOINTS3D, self.on_keypoints,
                                 STREAM_IN)
        self.create_subscription(String, MODEL, self.on_model, LATCHED)
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS, STREAM_OUT)
        self.unpublished = set()      # image topics already reported as without publisher
        self.published = set()        # image topics that had a publisher once
        self.lost_since = {}          # image topic -> when it lost its publisher (monotonic)
        self.started = time.monotonic()
        self.flush_timer = self.create_timer(self.derived.flush_period_ns / 1e9, self.flush)
        self.create_timer(1.0, self.publish_diagnostics)
        self.batches = self.incomplete_batches = 0
        self.awaiting_keypoints = None    # lockstep: stamp of the frame whose 3D is awaited
        self.awaiting_since = 0.0         # lockstep: when that frame was processed (monotonic)
        self.lockstep_timeouts = 0
        self.forward_seconds = []
        self.timer = StageTimer()  # convert, publish (crop, forward: self.detector.timer)
        self.model_reloads = self.model_rejects = 0
        self.get_logger().info(
            f'detecting {len(self.slots)} camera(s) '
            f'{[(s.name, self.resolve_topic_name(s.image_topic)) for s in self.slots]} with '
            f'{self.detector.metadata.get("architecture")} ({len(self.detector.keypoints)} '
            f'keypoints, heatmaps {self.detector.heatmap_size}) on {self.detector.device}, '
            f'{self.detector.backend}, {self.detector.precision_note}; decode and crop on '
            f'{self.detector.view_threads.threads} thread(s){self.subjects_note()}')

    def subjects_note(self):
        """The start line's several-subject part: '' with one subject."""
        c = self.config
        if c.subjects < 2:
            return ''
        when = ('every frame' if c.discovery_period_s == 0 else
                f'the first frame of each {c.discovery_period_s:g} s window')
        return (f'; subjects {c.subjects}: discovery maps (discovery_tiles '
                f'{c.discovery_tiles}) in {when} with fewer tracked')

    def discovery_count(self, slot):
        """subjects >= 2: the discovery crop slots of a camera (module docstring): 1 with
        `box` or discovery_tiles 0, else subjects.detection.discovery_slots of its rig
        camera's size."""
        if self.config.box or not self.config.discovery_tiles:
            return 1
        camera = slot.rig_camera
        return discovery_slots(camera.width, camera.height, self.config.discovery_tiles)

    @staticmethod
    def tracked_rule(config):
        """The crop rule's settings (monet_ros.crop_rule.TrackedRule) of a DetectorConfig."""
        return TrackedRule(margin=config.track_margin, min_points=config.min_track_keypoints,
                           trim=config.track_trim,
                           timeout_ns=int(round(config.track_timeout_s * 1e9)))

    @staticmethod
    def flush_period_s(config):
        """Period of the timer that runs incomplete batches: batch_wait_ms, at least 1 ms and
        at most 20 ms (a longer wait is still checked often enough to be kept to ~20 ms)."""
        return min(max(config.batch_wait_ms, 1.0), 20.0) / 1e3

    def apply_live(self, config):
        """Use a changed config (a live parameter was set) from the next frame."""
        derived = derive(config)     # checked already (declare_config): cannot fail here
        self.tracker.rule = derived.rule
        self.subject_tracks.rule = derived.rule
        self.flush_timer.timer_period_ns = derived.flush_period_ns
        self.config, self.derived = config, derived

    def load_detector(self, path):
        """The Detector of checkpoint `path`; precision int8 calibrates on the crops this
        node makes (monet_ros.int8_calibration): tracked crops with the track_* rule when
        it tracks (track true and every camera has rig extrinsics; with subjects >= 2 the
        subject crops and discovery maps of a several-subject run, subject_crops, with the
        default association and tracker settings), else `box`'s crops,
        else full-frame crops; the quant is cached under that crop mode's name. Set at
        load: changing track live keeps the loaded quant."""
        if not Path(path).is_file():
            raise CheckpointError(f'{path}: checkpoint file not found (parameter model)')
        if self.config.calibration and self.config.precision != 'int8':   # nothing uses it
            raise ConfigError(self.get_name(), 'calibration', f'{self.config.calibration}: '
                              'calibration data of precision int8 only; this node runs '
                              f'precision {self.config.precision} (set precision int8, or '
                              'leave calibration empty)')
        track = self.config.track and all(s.rig_camera is not None for s in self.slots)
        subjects = SubjectsConfig(subjects=self.config.subjects,
                                  discovery_tiles=self.config.discovery_tiles) \
            if self.config.subjects > 1 else None
        int8_crops, calibration = int8_calibration(
            self.config.calibration or None, track, self.tracked_rule(self.config),
            slop_ns=int(round(self.config.slop_ms * 1e6)), box=self.config.box or None,
            subjects=subjects)
        detector = Detector.from_checkpoint(path, device=self.device,
                                            backend=self.config.backend,
                                            threads=self.config.threads,
                                            precision=self.config.precision,
                                            calibration=calibration, int8_crops=int8_crops)
        if detector.int8_note:        # what int8 calibrated on, or the cached quant it uses
            self.get_logger().info(f'{path}: {detector.int8_note}')
        return detector

    # ------------------------------------------------------------------ input
    def bad_message(self, slot, topic, error):
        topic = self.resolve_topic_name(topic)      # the name it listens on (namespace, remaps)
        slot.bad += 1
        slot.last_bad = f'{topic}: {error}'
        log_bad_once(self, topic, error, slot.bad)

    def on_camera_info(self, slot, msg):
        key = (tuple(msg.k), tuple(msg.d), msg.width, msg.height, msg.distortion_model)
        if key == slot.info_key:
            return
        try:
            R = slot.rig_camera.R if slot.rig_camera is not None else None
            t = slot.rig_camera.t if slot.rig_camera is not None else None
            slot.camera = camera_from_camera_info(msg, slot.name, R, t)
            if slot.rig_camera is not None:        # the rig's extrinsics: its length unit
                slot.camera = slot.camera.replace(units=slot.rig_camera.units)
            slot.info_key = key
        except ValueError as error:
            self.bad_message(slot, slot.info_topic, error)

    def on_image(self, slot, msg):
        slot.received += 1
        if len(slot.frames) == slot.frames.maxlen:
            slot.dropped += 1          # the oldest unprocessed frame gives way
        slot.frames.append((header_stamp_ns(msg), msg, time.monotonic()))
        self.process()

    def on_keypoints(self, msg):
        try:
            stamp = header_stamp_ns(msg)
            points = cloud_to_keypoints3d(msg, units=self.units)
            if self.config.subjects > 1:
                self.subject_tracks.update(points['X'], points['subject'], points['keypoint'],
                                           stamp, len(self.detector.keypoints))
            else:
                if len(np.unique(points['subject'])) > 1:
                    self.get_logger().warning(
                        f'{self.resolve_topic_name(KEYPOINTS3D)} has several subjects: this '
                        'detector crops around all of them as one (set subjects as on the '
                        'fusion node)', throttle_duration_sec=60.0)
                self.tracker.update(points['X'], stamp)
        except ValueError as error:
            self.get_logger().warning(f'{self.resolve_topic_name(KEYPOINTS3D)}: bad message '
                                      f'({error})',
                                      throttle_duration_sec=5.0)
            return
        if self.awaiting_keypoints is not None and stamp >= self.awaiting_keypoints:
            self.awaiting_keypoints = None
            self.process()        # the next frame arrived first and waited for this

    def oldest_arrival(self):
        """Monotonic arrival time of the oldest unprocessed frame, or None."""
        return min((s.frames[0][2] for s in self.slots if s.frames), default=None)

    def flush(self):
        """Run an incomplete batch when a frame waited longer than batch_wait_ms."""
        oldest = self.oldest_arrival()
        if oldest is not None and time.monotonic() - oldest >= self.derived.batch_wait_s:
            self.process(incomplete=True)

    def take_batch(self, incomplete):
        """The (slot, msg) pairs of the next batch, taken out of the slots (each camera's
        frames that arrived before the taken one are counted as dropped), or [] to wait.
        The newest instant every camera has; with `incomplete` (batch_wait_ms passed) and
        no such instant, the newest frame of each camera that has one."""
        chosen = newest_common_instant([[f[0] for f in s.frames] for s in self.slots],
                                       self.derived.slop_ns)
        if chosen is None:
            if not incomplete:
                return []
            chosen = [len(s.frames) - 1 if s.frames else None for s in self.slots]
            self.incomplete_batches += 1
        batch = []
        for slot, index in zip(self.slots, chosen):
            if index is None:
                continue
            msg = slot.frames[index][1]
            slot.dropped += index
            for _ in range(index + 1):
                slot.frames.popleft()
            batch.append((slot, msg))
        return batch

    def waiting_for_keypoints(self):
        """Lockstep: True while the 3D of the last processed frame has not arrived and less
        than lockstep_timeout_s passed since that frame was processed (a longer wait is
        counted in /diagnostics as lockstep_timeouts, and the next frame goes on without
        it). The wait counts from the processed frame, not from a pending one: under a
        steady stream the pending frames are replaced faster than any timeout, and a lost
        keypoints3d would stall the detector for good."""
        if not self.config.lockstep or self.awaiting_keypoints is None:
            return False
        if time.monotonic() - self.awaiting_since > self.config.lockstep_timeout_s:
            if not self.lockstep_timeouts:
                self.get_logger().warning(
                    f'lockstep: no {self.resolve_topic_name(KEYPOINTS3D)} for stamp '
                    f'{self.awaiting_keypoints} within {self.config.lockstep_timeout_s} s: '
                    'going on without it (counted in /diagnostics as lockstep_timeouts)')
            self.awaiting_keypoints = None
            self.lockstep_timeouts += 1
            return False
        return True

    # ------------------------------------------------------------------ detection
    def decode(self, slot, msg):
        """(image (H, W, ch) uint8, its layout, Camera) of a message, or None (counted as
        bad). Raw rgb8/bgr8/rgba8/bgra8/mono8 images stay the message buffer (no copy): the
        detector converts only the crop (raw_to_rgb8). A JPEG CompressedImage is only
        checked here (its header's size) and given as (None, 'jpeg', Camera): decode_crops
        decodes it at the crop's scale once the box is known (io.jpeg_scale)."""
        topic = slot.image_topic
        try:
            camera = slot.camera or slot.rig_camera
            if isinstance(msg, CompressedImage) and is_jpeg(msg.data) and camera is not None:
                width, height = jpeg_size(msg.data)   # decoded at the crop's scale later
                if (camera.width, camera.height) != (width, height):
                    raise ValueError(f'image is {width}x{height} but the camera is '
                                     f'{camera.width}x{camera.height}')
                return None, 'jpeg', camera
            image, layout = view_for_crop(msg)    # cropped before any colour conversion
            channels = {'rgba8': 4, 'bgra8': 4, 'mono8': 1}.get(layout, 3)
            if image.dtype != np.uint8 or image.shape[2] != channels:
                raise ValueError(f'need an 8-bit colour or mono image, got {image.dtype} '
                                 f'{image.shape}')
            camera = slot.camera or slot.rig_camera
            if camera is None:
                raise ValueError(f'no camera_info on {slot.info_topic} yet')
            if (camera.width, camera.height) != (image.shape[1], image.shape[0]):
                raise ValueError(f'image is {image.shape[1]}x{image.shape[0]} but the camera '
                                 f'is {camera.width}x{camera.height}')
        except ValueError as error:
            self.bad_message(slot, topic, error)
            return None
        return image, layout, camera

    def decode_crops(self, work, boxes, reduce=True):
        """Decode the JPEG views of `work` (decode gave them as 'jpeg') at the scale of their
        crop (io.jpeg_scale.decode_views: 1/2, 1/4 or 1/8 when the crop shrinks that much, the
        views in parallel on the detector's view_threads); their camera and box become the
        reduced image's, so the heatmap camera is unchanged.
        -> (work, cameras, boxes) without the views that fail to decode (counted as bad)."""
        jpegs = [i for i, w in enumerate(work) if w[3] == 'jpeg']
        if not jpegs:
            return work, [w[4] for w in work], boxes
        h_in, w_in = self.detector.input_size
        decoded = dict(zip(jpegs, decode_views(
            [(work[i][1].data, work[i][4], boxes[i]) for i in jpegs], (w_in, h_in),
            self.detector.view_threads, reduce=reduce)))
        kept, kept_boxes = [], []
        for i, ((slot, msg, image, layout, camera), box) in enumerate(zip(work, boxes)):
            if i in decoded:
                if isinstance(decoded[i], ValueError):
                    self.bad_message(slot, slot.image_topic, decoded[i])
                    continue
                image, layout, camera, box, _ = decoded[i]
            kept.append((slot, msg, image, layout, camera))
            kept_boxes.append(box)
        return kept, [w[4] for w in kept], np.asarray(kept_boxes, np.float64).reshape(-1, 4)

    def crop_boxes(self, cameras, stamp_ns):
        """(V, 4) boxes of images stamped stamp_ns: the tracked rule (fresh keypoints3d and
        rig extrinsics), else `box`, else the full frame."""
        track = self.config.track and all(s.rig_camera is not None for s in self.slots)
        if not track:
            return TrackedCrops(self.tracker.rule).boxes(cameras, None, self.config.box or None)
        return self.tracker.boxes(cameras, stamp_ns, self.config.box or None)

    def process(self, incomplete=False):
        """Run the next batch (take_batch) unless lockstep holds it back."""
        if self.waiting_for_keypoints():
            return
        batch = self.take_batch(incomplete)
        if not batch:
            return
        work = []
        with self.timer('convert'):
            for slot, msg in batch:
                decoded = self.decode(slot, msg)
                if decoded is not None:
                    work.append((slot, msg, *decoded))
        if not work:
            return
        cameras = [w[4] for w in work]
        stamp = max(header_stamp_ns(w[1]) for w in work)
        if self.config.lockstep:
            self.awaiting_keypoints, self.awaiting_since = stamp, time.monotonic()
        if self.config.subjects > 1:
            self.process_subjects(work, stamp)
            return
        boxes = self.detector.boxes_for(cameras, self.crop_boxes(cameras, stamp))
        with self.timer('decode'):
            work, cameras, boxes = self.decode_crops(work, boxes)
        if not work:
            return
        start = time.perf_counter()
        heatmaps, heat_cameras = self.detector.predict([w[2] for w in work], cameras, boxes,
                                                       keep_aspect=False,
                                                       encodings=[w[3] for w in work])
        self.forward_seconds = (self.forward_seconds + [time.perf_counter() - start])[-100:]
        self.batches += 1
        start = time.perf_counter()
        outputs = [(w, header_stamp_ns(w[1]), w[1].header.frame_id, heat, heat_cam, box)
                   for w, heat, heat_cam, box in zip(work, heatmaps, heat_cameras, boxes)]
        for (slot, *_), stamp, frame_id, heat, heat_cam, _ in outputs:
            heat_pub, info_pub, _ = self.pubs[slot.name]
            info_pub.publish(camera_info_from_camera(heat_cam, stamp, frame_id))
            heat_pub.publish(heatmaps_to_image_msg(heat, stamp, frame_id))
            slot.processed += 1
        # debug images after every heatmap: a failing drawing never costs fusion its input
        for (slot, _, image, layout, camera), stamp, frame_id, heat, heat_cam, box in outputs:
            debug_pubs = self.pubs[slot.name][2]
            if debug_pubs is None:
                continue
            try:
                self.publish_debug(slot, debug_pubs, image, layout, camera, box, heat,
                                   heat_cam, stamp, frame_id)
            except Exception as error:  # noqa: BLE001 - counted and logged once per kind
                guard = getattr(self, 'callback_guard', None)
                if guard is None:
                    raise
                guard.record(f'{slot.name}/debug_image', error)
        self.timer.add('publish', time.perf_counter() - start)

    def process_subjects(self, work, stamp):
        """subjects >= 2: the crop slots of an instant (module docstring): every crop of
        every view in one forward pass, each slot published (empty where no crop)."""
        N = self.config.subjects
        with self.timer('decode'):          # JPEG views in full: crops of several scales
            work, cameras, _ = self.decode_crops(
                work, np.array([(0, 0, w[4].width, w[4].height) for w in work], np.float64),
                reduce=False)
        if not work:
            return
        track = self.config.track and all(s.rig_camera is not None for s in self.slots)
        boxes = self.subject_tracks.boxes(cameras, stamp, N, self.config.box or None, track)
        v_idx, k_idx = np.nonzero(np.isfinite(boxes[:, :N]).all(-1))
        crop_boxes = self.detector.boxes_for([cameras[v] for v in v_idx],
                                             boxes[v_idx, k_idx]).reshape(-1, 4)
        # the discovery slots N.. (the whole frame or its tiles, as `monet process`), or box
        discover = [v for v in range(len(work)) if np.isfinite(boxes[v, N]).all()]
        if discover and not self.config.box:
            found = discovery_boxes(self.detector, [cameras[v] for v in discover],
                                    self.config.discovery_tiles)
        else:
            found = [self.detector.boxes_for([cameras[v]], boxes[v, N][None])
                     for v in discover]
        for v, tiles in zip(discover, found):
            slots = len(self.pubs[work[v][0].name]) - N
            if len(tiles) > slots:          # camera_info's size is not the rig camera's
                self.bad_message(work[v][0], work[v][0].info_topic, ValueError(
                    f'{len(tiles)} discovery tiles of a {cameras[v].width}x'
                    f'{cameras[v].height} image but {slots} crop slots (laid out for the rig '
                    "camera's size): discovery maps of this view not sent"))
                continue
            v_idx = np.append(v_idx, np.full(len(tiles), v))
            k_idx = np.append(k_idx, N + np.arange(len(tiles)))
            crop_boxes = np.concatenate([crop_boxes, tiles])
        heat, heat_cams = [], []
        if len(v_idx):
            crop_cams = [cameras[v] for v in v_idx]
            start = time.perf_counter()
            heat, heat_cams = self.detector.predict(
                [work[v][2] for v in v_idx], crop_cams, crop_boxes, keep_aspect=False,
                encodings=[work[v][3] for v in v_idx])
            self.forward_seconds = (self.forward_seconds
                                    + [time.perf_counter() - start])[-100:]
            self.batches += 1
        start = time.perf_counter()
        crops = {(int(v), int(k)): n for n, (v, k) in enumerate(zip(v_idx, k_idx))}
        C = len(self.detector.keypoints)
        for v, (slot, msg, *_) in enumerate(work):
            stamp_v, frame_id = header_stamp_ns(msg), msg.header.frame_id
            for k, (heat_pub, info_pub) in enumerate(self.pubs[slot.name]):
                n = crops.get((v, k))
                if n is None:
                    heat_msg, info_msg = empty_crop_messages(C, stamp_v, frame_id)
                else:
                    heat_msg = heatmaps_to_image_msg(heat[n], stamp_v, frame_id)
                    info_msg = camera_info_from_camera(heat_cams[n], stamp_v, frame_id)
                info_pub.publish(info_msg)
                heat_pub.publish(heat_msg)
            slot.processed += 1
        self.timer.add('publish', time.perf_counter() - start)

    def publish_debug(self, slot, pubs, image, layout, camera, box, heat, heat_cam, stamp,
                      frame_id):
        """<cam>/debug_image + its camera_info, at most debug_image_rate_hz, only when
        someone subscribes (so it costs nothing otherwise)."""
        now = time.monotonic()
        if (now - slot.last_debug < self.derived.debug_period_s
                or not (pubs[0].get_subscription_count() or pubs[1].get_subscription_count())):
            return
        slot.last_debug = now
        peaks, confidence = heatmap_peaks_in_image(heat, heat_cam.K, camera.K)
        reprojected = None
        X = self.tracker.current(stamp)          # the fused keypoints the crop follows
        if X is not None and slot.rig_camera is not None:
            reprojected = np.full((len(X), 2), np.nan)
            ok = np.isfinite(X).all(axis=1)
            if ok.any():
                reprojected[ok] = camera.project(X[ok])
        scale = self.config.debug_image_scale
        out = debug_image(raw_to_rgb8(image, layout), box, peaks, confidence, reprojected,
                          scale=scale)
        view = camera if scale == 1.0 else camera.crop(
            (0.0, 0.0, float(camera.width), float(camera.height)), (out.shape[1], out.shape[0]))
        pubs[1].publish(camera_info_from_camera(view, stamp, frame_id))
        pubs[0].publish(numpy_to_image_msg(out, stamp, frame_id, encoding='bgr8'))

    # ------------------------------------------------------------------ hot reload
    def on_model(self, msg):
        """/monet/model: {"path": ..., "sha256": ...}; verify, load, swap; else keep the old
        weights and say why."""
        try:
            info = json.loads(msg.data)
            path = Path(info['path'])
            expected = str(info['sha256']).lower()
        except (ValueError, KeyError, TypeError) as error:
            return self.reject_model(f'not a JSON object with path and sha256 ({error})')
        if not path.is_file():
            return self.reject_model(f'{path}: checkpoint file not found')
        actual = sha256_file(path)
        if actual == self.model_sha256:
            return None   # already running these weights (e.g. the latched announcement)
        if actual != expected:
            return self.reject_model(f'{path}: sha256 {actual[:12]}... does not match the '
                                     f'announced {expected[:12]}...')
        try:
            detector = self.load_detector(path)
        except (CheckpointError, ValueError, OSError) as error:
            return self.reject_model(str(error))
        if list(detector.keypoints) != list(self.detector.keypoints):
            return self.reject_model(f'{path}: keypoints {detector.keypoints} differ from the '
                                     f'running model {self.detector.keypoints}')
        self.detector, self.model_sha256 = detector, actual
        self.model_reloads += 1
        self.get_logger().info(f'loaded new weights {path} (step {info.get("step")}, '
                               f'sha256 {actual[:12]}...)')
        return None

    def reject_model(self, reason):
        self.model_rejects += 1
        reason = error_line(reason)           # torch's texts span lines: a log line is one
        self.get_logger().error(f'{self.resolve_topic_name(MODEL)} rejected, keeping the '
                                f'current weights: {reason}')

    # ------------------------------------------------------------------ diagnostics
    def no_publisher(self, slot):
        """'' when the slot's image topic has a publisher, else the reason (with a hint when
        the other transport has one). Warned once per topic when it never had a publisher
        (3 s after start) or lost it while another image topic of this node still has one
        (a camera gone); when every image topic lost its publishers together (the recording
        ended: the player finished, or the whole source stopped) that is said in one line at
        info level, not warned. A lost publisher is judged 2 s after it went (the graph settled:
        a player's topics go one by one). /diagnostics carry the reason either way."""
        topic = self.resolve_topic_name(slot.image_topic)
        now = time.monotonic()
        if self.count_publishers(topic):
            self.published.add(topic)
            self.lost_since.pop(topic, None)
            self.unpublished.discard(topic)
            return ''
        if now - self.started < 3.0 or (topic in self.published and
                                         now - self.lost_since.setdefault(topic, now) < 2.0):
            return ''
        other = topic[:-len('/compressed')] if topic.endswith('/compressed') \
            else topic + '/compressed'
        reason = f'no publisher on {topic}'
        if self.count_publishers(other):
            reason += (f' (but {other} has one: transport:='
                       f'{"raw" if topic.endswith("/compressed") else "compressed"})')
        if topic not in self.unpublished:
            topics = [self.resolve_topic_name(s.image_topic) for s in self.slots]
            if topic in self.published and not any(map(self.count_publishers, topics)):
                # one line for them all (those not said yet)
                self.get_logger().info(
                    f'no publisher on {", ".join(t for t in topics if t not in self.unpublished)}'
                    ' any more, nor on any image topic of this node: the recording ended or '
                    'the source stopped')
                self.unpublished.update(topics)
            else:
                self.unpublished.add(topic)
                self.get_logger().warning(reason)
        return reason

    def publish_diagnostics(self):
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        forward_ms = 1e3 * float(np.median(self.forward_seconds)) if self.forward_seconds \
            else 0.0
        # per-batch stage times (ms) since start: convert, decode (JPEG views, at the crop's
        # scale), crop, forward, publish
        stages = {**self.timer.summary(), **self.detector.timer.summary()}
        for slot in self.slots:
            level = DiagnosticStatus.OK if slot.processed else DiagnosticStatus.WARN
            text = f'{slot.processed} frames, {slot.dropped} dropped, {slot.bad} bad'
            silent = self.no_publisher(slot)
            if silent:
                level, text = DiagnosticStatus.WARN, f'{silent}; {text}'
            msg.status.append(DiagnosticStatus(
                level=level, name=f'monet detector: {slot.name}', hardware_id=slot.name,
                message=text,
                values=[KeyValue(key=k, value=str(v)) for k, v in (
                    ('received', slot.received), ('processed', slot.processed),
                    ('dropped_stale', slot.dropped), ('bad_messages', slot.bad),
                    ('forward_ms_median', f'{forward_ms:.2f}'),
                    ('model_sha256', self.model_sha256), ('model_reloads', self.model_reloads),
                    ('model_rejects', self.model_rejects), ('last_bad_message', slot.last_bad),
                    ('backend', self.detector.backend),
                    ('precision', self.detector.precision),
                    ('lockstep_timeouts', self.lockstep_timeouts), ('batches', self.batches),
                    ('incomplete_batches', self.incomplete_batches), *stages.items())]))
        self.pub_diag.publish(msg)


def main(args=None):
    return run_node(DetectorNode, 'detector', args, large_data=True)


if __name__ == '__main__':
    sys.exit(main())
