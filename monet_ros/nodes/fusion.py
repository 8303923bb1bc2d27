"""fusion node: heatmaps of every rig camera -> /monet/keypoints3d, /monet/skeleton,
/diagnostics.

Subscribes /monet/<cam>/heatmaps (Image 32FC<C>) + /monet/<cam>/camera_info (the heatmap's
virtual camera, same stamp) for each camera, pairs them per camera by exact stamp, groups
the cameras by stamp (exact or within `slop_ms`), and calls the fusion core
(monet_ros.fusion.fuse_heatmaps). A silent camera is waited for `timeout_s`, then left out
(fewer views) and reported in /diagnostics; after `silent_after_s` frames no longer wait.

With `filter:=true` (settable live) the keypoints go through the causal per-joint Kalman
filter of monet_ros.temporal.live (no frames of delay, outliers gated, reset on a stamp
jump): the filtered ones on keypoints3d (and the skeleton markers), the raw ones on
keypoints3d_raw. A bridged joint (predicted, no accepted measurement this frame) keeps
num_views of the raw fusion (0 when not triangulated), so it stays recognisable.

Units: fusion and the live filter run in the rig's length unit (`rig_units`, the rig
file's `units`, else the rule of geometry.units), stated in /diagnostics (`units`) and the
start log; the filter's mm and m/s^2 parameters are converted into it. Everything
published is in metres (ROS REP 103), whatever the rig's unit: keypoints3d,
keypoints3d_raw, the skeleton and rig markers and /tf_static are converted at publish by
monet_ros.io (the `units` argument of its builders; /diagnostics `topic_units`: m).

When the node falls behind (more heatmaps arrive than it fuses, e.g. 16 cameras on 2 cores),
it keeps its outputs fresh instead of queueing: a frame any of whose heatmaps or camera_info
waited longer than `max_queue_ms` in the input queue (from its reception by the middleware,
MessageInfo received_timestamp, to its callback) is not decoded or fused but counted stale,
and the newer frames behind it are fused in time (0 = fuse every frame however late).

Several subjects (`subjects` N >= 2; docs/subjects.md "Live"): the detector nodes publish,
per camera and instant, N + D crop slots `<cam>/crop<k>/heatmaps` +
`<cam>/crop<k>/camera_info` (the heatmap_topic / camera_info_topic templates with camera =
`<cam>/crop<k>`): k < N the crops around the subjects of the latest keypoints3d, k >= N the
discovery maps while fewer than N subjects were published (the whole frame, or its tiles: D
= subjects.detection.discovery_slots of the camera's size and `discovery_tiles`, which must
be the detector nodes'); a slot without a crop at that instant carries an empty (0 x 0)
heatmap and camera_info, so every slot has one message per instant. The node runs the same
algorithm as `monet process --subjects` (subjects.detection.SubjectsCore.live_frame: crops
matched to the tracks, discovery on the discovery maps, a view's tiles merged as offline,
association across views, the identity tracker) and publishes keypoints3d with one more
UINT32 field `subject` (the identity; one point per keypoint and subject, ordered by
identity), skeleton markers per subject (namespace <skeleton>/subject<id>, colours
io.markers.SUBJECT_COLOURS) and a /diagnostics status per tracked subject. Its source
counters are per slot. With `filter:=true` each identity has its own live filter
(temporal.live.SubjectFilters: one LiveFilter per identity, started at its birth, dropped
at its death, all dropped when the identities restart): the filtered points on keypoints3d,
the raw ones on keypoints3d_raw, both with the `subject` field and the same points (the
skeleton markers are the filtered ones).
A detector whose `discovery_tiles` (or `subjects`) differs sends another number of slots
than this node subscribes. Every SLOT_CHECK_S the node reads from the ROS graph how many
slots each publisher node sends per camera (its highest `<cam>/crop<k>/heatmaps` + 1; the
messages carry no count); a count that differs and held for `silent_after_s` is logged
once per detector (ERROR: the parameter, the detector's value read back from its count,
subjects.detection.discovery_tiles_for, and this node's, the nodes and cameras) and counted
per camera in /diagnostics (summary `discovery_slot_mismatch`: {camera: instants received
since}; `detector_discovery_slots`: {camera: [its discovery slots]}; the slot statuses
WARN). Nothing stalls: the slots it never sends (fewer tiles) are no longer waited for
and make no frame partial; of more slots than this node's, the ones beyond are not
subscribed, so discovery works on the first D of its maps only (each map with its own
virtual camera, so what is found is right, but a subject only in the maps left out is
not found until it enters the others). The safe fix is the same value on both nodes
(`monet pipeline` and the launch file give both one value).
With N = 1 (the default) nothing of this exists: the topics and fields are the one-subject
ones, byte for byte.

Every heatmap received ends in exactly one per-camera counter of /diagnostics and of the
stop summary (OUTCOMES): received = fused + bad_messages + unpaired + repeated + late +
dropped + stale + waiting. A heatmap or camera_info whose partner (same stamp) has not come
within `silent_after_s` is unpaired and let go.
"""
from collections import OrderedDict
import copy
from dataclasses import dataclass
import sys
import time
from types import SimpleNamespace
import warnings

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from visualization_msgs.msg import MarkerArray

from monet_ros.config import MAX_THREADS, ConfigError, config_subset, derive_checked, setting
from monet_ros.fusion import FusionConfig, crop_scales, fuse_heatmaps
from monet_ros.geometry.units import UNITS, rig_units
from monet_ros.io import (
    header_stamp_ns,
    image_msg_to_heatmaps,
    keypoints3d_to_cloud,
    skeleton_marker_array,
)
from monet_ros.io.convert import delete_all_markers, marker_array
from monet_ros.io.markers import frustum_marker_specs
from monet_ros.jit import warm_up
from monet_ros.nodes.names import (
    CROP_SLOT,
    DIAGNOSTICS,
    HEATMAP_CAMERA_INFO,
    HEATMAPS,
    KEYPOINTS3D,
    KEYPOINTS3D_RAW,
    RIG_MARKERS,
    SKELETON,
    TF_STATIC,
    crop_slots,
    heatmap_sources,
    node_namespace,
)
from monet_ros.nodes.params import declare_config, duration_msg_ns
from monet_ros.nodes.qos import HEATMAPS_IN, LATCHED, STREAM_OUT
from monet_ros.nodes.runner import log_bad_once, run_node
from monet_ros.nodes.tf import rig_tf_message, tf_message_class
from monet_ros.rig_select import load_node_rig, select_cameras
from monet_ros.skeleton import load_skeleton
from monet_ros.subjects.association import AssociationConfig
from monet_ros.subjects.detection import (
    SubjectsConfig,
    SubjectsCore,
    discovery_slots,
    discovery_tiles_for,
    subject_keypoints,
)
from monet_ros.subjects.tracking import SubjectTracker, TrackerConfig
from monet_ros.sync import StampSynchronizer
from monet_ros.temporal.live import LiveFilter, LiveFilterConfig, SubjectFilters
from monet_ros.timing import StageTimer

# Parameters that may change while running (`ros2 param set`), effective next frame.
FILTER_PARAMETERS = tuple(f for f in LiveFilterConfig.__dataclass_fields__)
LIVE = ('confidence_threshold', 'threshold_px', 'min_views', 'peaks_per_view', 'max_queue_ms',
        *FILTER_PARAMETERS)
# Unpaired heatmaps / camera_info kept per camera while waiting for their partner.
_PAIR_BACKLOG = 30
# subjects >= 2: how often (s) the ROS graph is read for the crop slots each detector
# publishes (FusionNode.check_detector_slots)
SLOT_CHECK_S = 0.5
# Where a received heatmap ends (one per heatmap): in a fused frame; rejected (decoding,
# validation, or the fusion core refused the view); no camera_info of its stamp came;
# its stamp repeated one the camera gave; its instant was already released; its frame had
# fewer than min_views views or its fusion failed; its frame was stale (the node was behind,
# max_queue_ms); still waiting (for a camera_info or for the other cameras).
OUTCOMES = ('fused', 'bad_messages', 'unpaired', 'repeated', 'late', 'dropped', 'stale',
            'waiting')
# The item a stale view holds in the synchroniser (not decoded): its frame is not fused.
STALE = object()
# The item of a crop slot without a crop at that instant (subjects >= 2: an empty heatmap).
EMPTY = object()


@dataclass(frozen=True)
class FusionNodeConfig(LiveFilterConfig, FusionConfig, SubjectsConfig, TrackerConfig):
    rig: str = setting('', 'rig file (any format load_rig reads) or a recording whose '
                       'camera_info + /tf_static give the rig; required')
    rig_units: str = setting('', "length unit of a rig file that states none (m, cm, mm; "
                             "'' = the file's, else the rule of geometry.units): fusion "
                             'and the filter run in it; the topics are in m (REP 103)',
                             choices=('',) + UNITS)
    cameras: tuple[str, ...] = setting((), 'rig cameras to fuse (default: all of the rig)')
    skeleton: str = setting('human14', 'skeleton preset or YAML path: heatmap channel order '
                            'and bones of /monet/skeleton')
    frame_id: str = setting('', 'frame of the outputs (default: the rig frame)')
    heatmap_topic: str = setting(HEATMAPS, 'heatmap topic per camera (relative names are in '
                                  'the node namespace, default /monet)',
                                  template_fields=('camera',))
    camera_info_topic: str = setting(HEATMAP_CAMERA_INFO,
                                     'heatmap virtual camera_info topic per camera',
                                     template_fields=('camera',))
    input_reliability: str = setting('best_effort', 'QoS of the heatmap and camera_info '
                                     'subscriptions: best_effort matches every publisher; '
                                     'reliable only reliable ones, but a lost view is sent again',
                                     choices=('best_effort', 'reliable'))
    slop_ms: float = setting(0.0, 'stamp tolerance between cameras (0 = exact)', minimum=0.0)
    max_queue_ms: float = setting(
        100.0, 'a frame any of whose heatmaps or camera_info waited longer than this (ms) in '
        'the input queue (the node fell behind) is skipped and counted stale, so that the '
        'outputs stay fresh (0 = fuse every frame however late)', minimum=0.0)
    timeout_s: float = setting(0.3, 'wait this long for missing cameras of a frame, then '
                               'fuse the others', minimum=0.0)
    silent_after_s: float = setting(2.0, 'a camera without heatmaps this long is silent: '
                                    'frames stop waiting for it', minimum=0.0,
                                    exclusive_minimum=True)
    diagnostics_period_s: float = setting(1.0, 'period of /diagnostics', minimum=0.0,
                                          exclusive_minimum=True)
    marker_lifetime_s: float = setting(0.5, 'skeleton markers vanish this long after the last '
                                       'fused frame (0 = never)', minimum=0.0)
    marker_labels: bool = setting(False, 'also label the skeleton joints with their names')
    camera_markers: bool = setting(True, 'publish the rig cameras as frustums on rig_markers '
                                   '(latched)')
    camera_marker_depth: float = setting(0.2, 'frustum depth of the camera markers (m, '
                                         'whatever the rig unit)',
                                         minimum=0.0, exclusive_minimum=True)
    publish_tf: bool = setting(True, 'publish the rig on /tf_static (frame_id -> '
                               '<camera>_optical) when tf2_msgs is installed')
    threads: int = setting(1, 'torch CPU threads for heatmap decoding (0 = leave as is); one '
                           'thread is fastest for these small tensors', minimum=0,
                           maximum=MAX_THREADS)
    association_px: float = setting(
        15.0, 'subjects >= 2: largest median symmetric epipolar distance (px) between two '
        'instances of one subject (threshold_px is the triangulation inlier error)',
        minimum=0.0, exclusive_minimum=True)


def derive(config, units='m'):
    """What the parameters of a FusionNodeConfig feed (no ROS), built before they are used
    at start and before a live change is applied (monet_ros.nodes.params): the core's
    FusionConfig, the live filter in the rig's length unit `units` ('m', 'cm', 'mm'; built
    even while it is off, so switching it on cannot fail), the camera markers' depth (m:
    the markers are published in metres), the durations in ns and the outlier score's
    scale, and an identity tracker in `units` (subjects.tracking.SubjectTracker: its noise
    and acceleration squared in the rig's unit must be finite; built whatever `subjects`, so
    switching subjects on cannot fail). units None (the rig not loaded yet: the node's
    first check) leaves out what depends on it (filter and tracker None). Raises
    ConfigError naming a field (the filter's numbers in `units`), ArithmeticError or
    ValueError (a duration beyond what a float or int64 holds); derive_checked
    turns those into an error naming the parameter."""
    known = units is not None
    return SimpleNamespace(
        core=config_subset(config, FusionConfig),
        filter=LiveFilter(config_subset(config, LiveFilterConfig), units) if known else None,
        tracker=SubjectTracker(1, config_subset(config, TrackerConfig), units=units)
        if known else None,
        marker_depth=float(config.camera_marker_depth),      # m, as the markers are
        slop_ns=int(config.slop_ms * 1e6),
        max_queue_ns=config.max_queue_ms * 1e6,
        diagnostics_period_ns=int(config.diagnostics_period_s * 1e9),     # rclpy's timer
        marker_lifetime_ns=duration_msg_ns(config.marker_lifetime_s),
        outlier_scale=config.threshold_px * 2)      # triangulation's tie-break divides by it


class CameraStats:
    """Per-camera counters reported in /diagnostics (the synchroniser keeps the rest of the
    outcomes: FusionNode.outcomes)."""

    def __init__(self):
        self.received = 0
        self.bad = 0
        self.unpaired = 0         # heatmaps whose camera_info never came
        self.repeated = 0         # heatmaps replaced, before pairing, by one of the same stamp
        self.dropped = 0          # views of frames whose fusion failed
        self.stale = 0            # views of frames skipped as stale (max_queue_ms)
        self.fused = 0
        self.info_received = 0
        self.info_paired = 0
        self.info_unpaired = 0    # camera_info whose heatmap never came (or replaced)
        self.last_seen = None
        self.errors = []          # recent per-frame mean reprojection errors (px)
        self.last_bad = ''

    def mean_error(self):
        finite = [e for e in self.errors if np.isfinite(e)]
        return float(np.mean(finite)) if finite else float('nan')


class FusionNode(Node):
    def __init__(self, overrides=None, node_name='fusion', announce=True, **kwargs):
        """announce: log the start-up line (announce()) once built; False leaves it to
        the caller (monet pipeline: said once all its other start checks passed)."""
        super().__init__(node_name, **node_namespace(kwargs))
        self.units = None    # the rig's length unit, known once the rig is loaded
        self.config = config = declare_config(self, FusionNodeConfig, overrides, live=LIVE,
                                              on_change=self.apply_live, derive=self.derive)
        self.filter_counts = dict(resets=0, restarts=0, gated=0)  # of replaced filters
        self.timer = StageTimer()  # per-stage wall time, reported in /diagnostics
        if config.threads:
            import torch
            torch.set_num_threads(config.threads)
        if not config.rig:
            raise ConfigError(self.get_name(), 'rig', 'is required (a rig file or recording)')
        rig, rig_frame = load_node_rig(config.rig, config.rig_units)
        self.cameras = select_cameras(self.get_name(), rig, config.cameras, minimum=2)
        self.units = rig_units(self.cameras)
        # checked again with the rig unit: the filter and marker depth in it (ConfigError
        # naming the parameter, as a live change would be refused)
        self.derived = derived = derive_checked(self.get_name(), config, self.derive)
        self.core_config = derived.core
        self.live_filter = self.make_filter(config, derived)
        if config.min_views > len(self.cameras):
            raise ConfigError(self.get_name(), 'min_views',
                              f'{config.min_views} > the {len(self.cameras)} cameras fused')
        self.names = [cam.name for cam in self.cameras]
        self.skeleton = load_skeleton(config.skeleton)
        self.frame_id = config.frame_id or rig_frame
        self.subjects = self.subjects_core(config) if config.subjects > 1 else None
        # the compiled kernels (undistortion, association) now, not on the first frame
        # (said in the start-up line: nothing is logged before every start check passed)
        self.kernel_seconds = warm_up()
        # the message sources: the cameras, or with subjects >= 2 their crop slots
        sources = [heatmap_sources(cam.name, config.subjects, discovery_slots(
            cam.width, cam.height, config.discovery_tiles)) for cam in self.cameras]
        self.key_camera = {key: i for i, keys in enumerate(sources) for key in keys}
        # with subjects >= 2 the discovery slots (k >= N: the whole frame or its tiles)
        self.discovery_keys = {key for keys in sources for key in keys[config.subjects:]} \
            if config.subjects > 1 else set()
        self.keys = list(self.key_camera)
        self.sources = sources
        # subjects >= 2: the crop slots the detectors publish, read from the ROS graph
        # (check_detector_slots): camera index -> {publisher node: [slots, since]}; the
        # cameras whose detector publishes another count than `sources` (confirmed: the
        # same count for silent_after_s) -> {node: slots}; the instants of each camera
        # received while so; the slots no detector publishes (not waited for)
        self.detector_slots = {}
        self.slot_mismatch = {}
        self.mismatch_frames = [0] * len(self.cameras)
        self.unpublished = set()
        self.slot_logged = set()
        self.subject_counts = dict(resets=0, duplicates=0, discoveries=0, shared=0, detached=0,
                                   extra=0, weak=0, foreign=0, settled=0)
        self.subject_stats = {}   # identity -> {frames, keypoints, error, last_stamp_ns}
        self.stats = {name: CameraStats() for name in self.keys}
        self.frames = 0
        self.partial_frames = 0
        self.stale_frames = 0
        self.fusion_seconds = []
        self.last_result = None
        self.last_stamp_ns = None
        # callables(stamp_ns, result, filtered) (the pipeline's summary and score):
        # filtered (C, 3) the live filter's keypoints (rig unit: not the topic's m), None
        # with it off; with subjects >= 2 result holds the published points (X (K C, 3),
        # confidence, reprojection_error, num_views, keypoint, subject; X raw) and filtered
        # (K C, 3) the per-identity filters' keypoints, in the same order (None when off)
        self.listeners = []
        self.first_heard = None   # monotonic time of the first heatmap (of any camera)
        self.sync = StampSynchronizer(self.keys, slop_ns=derived.slop_ns,
                                      timeout_s=config.timeout_s, min_keys=config.min_views)
        self.pending = {name: (OrderedDict(), OrderedDict()) for name in self.keys}
        inputs = copy.copy(HEATMAPS_IN)
        if config.input_reliability == 'reliable':
            inputs.reliability = ReliabilityPolicy.RELIABLE
        for name in self.keys:
            self.create_subscription(
                Image, config.heatmap_topic.format(camera=name),
                lambda msg, info, n=name: self.on_message(n, 0, msg, info), inputs)
            self.create_subscription(
                CameraInfo, config.camera_info_topic.format(camera=name),
                lambda msg, info, n=name: self.on_message(n, 1, msg, info), inputs)
        self.pub_points = self.create_publisher(PointCloud2, KEYPOINTS3D, STREAM_OUT)
        self.pub_raw = self.create_publisher(PointCloud2, KEYPOINTS3D_RAW, STREAM_OUT)
        self.pub_skeleton = self.create_publisher(MarkerArray, SKELETON, STREAM_OUT)
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS, STREAM_OUT)
        if config.publish_tf:
            self.publish_rig_tf()
        self.marker_ns = f'{self.skeleton.name}/subject0'    # one subject per fusion node
        if config.camera_markers:
            self.pub_rig = self.create_publisher(MarkerArray, RIG_MARKERS, LATCHED)
            self.pub_rig.publish(marker_array(
                self.get_clock().now().nanoseconds, self.frame_id,
                frustum_marker_specs(self.cameras, derived.marker_depth, scale=0.005)))
        self.create_timer(0.02, self.on_poll)
        if self.subjects is not None:
            self.create_timer(SLOT_CHECK_S, self.check_detector_slots)
        self.create_timer(config.diagnostics_period_s, self.publish_diagnostics)
        if announce:
            self.announce()

    def announce(self):
        """Log the start-up line: the cameras, skeleton, frame and units fused."""
        config = self.config
        slots = [sum(self.key_camera[key] == i for key in self.keys)
                 for i in range(len(self.names))]
        self.get_logger().info(
            f'fusing {len(self.names)} cameras {self.names} with {self.skeleton.name} '
            f'({self.skeleton.num_keypoints} keypoints) into frame {self.frame_id!r}, '
            f'3D in {self.units} (the rig unit), published in m'
            + (f'; up to {config.subjects} subjects from the crop slots '
               f'{self.config.heatmap_topic.format(camera=crop_slots("<camera>", 1)[0])}'
               f'..crop<k> (k < {"/".join(map(str, sorted(set(slots))))} per camera: '
               f'{config.subjects} subject crops, then the discovery maps of '
               f'discovery_tiles {config.discovery_tiles})' if self.subjects is not None
               else '')
            + f'; compiled kernels ready in {self.kernel_seconds:.1f} s')

    @staticmethod
    def make_filter(config, derived):
        """The live filter of a config (None when `filter` is off): derived.filter (a
        LiveFilter) with one subject, a SubjectFilters of its config and unit (one per
        identity) with subjects >= 2."""
        if not config.filter:
            return None
        if config.subjects > 1:
            return SubjectFilters(derived.filter.config, derived.filter.units)
        return derived.filter

    def subjects_core(self, config):
        """The several-subject core (subjects >= 2) of a config."""
        association = AssociationConfig(
            threshold_px=config.association_px, confidence_threshold=config.confidence_threshold,
            min_views=config.min_views, triangulation_px=config.threshold_px,
            method=config.method)
        return SubjectsCore(self.skeleton.num_keypoints, self.units,
                            config_subset(config, SubjectsConfig), association,
                            config_subset(config, TrackerConfig))

    def derive(self, config):
        """derive(config) in this node's rig unit (None before the rig is loaded: the start
        check of declare_config, without the filter; checked again once it is)."""
        return derive(config, self.units)

    def apply_live(self, config):
        """Use a changed config (a live parameter was set) from the next frame on."""
        if config.min_views > len(self.cameras):
            raise ConfigError(self.get_name(), 'min_views',
                              f'{config.min_views} > the {len(self.cameras)} cameras fused')
        derived = self.derive(config)    # checked already (declare_config): cannot fail
        self.core_config = derived.core
        self.sync.min_keys = config.min_views
        if self.live_filter is None or self.live_filter.config != derived.filter.config:
            # switched on, off or retuned: a fresh state from the next frame
            self.keep_filter_counts()
            self.live_filter = self.make_filter(config, derived)
        self.config, self.derived = config, derived

    def keep_filter_counts(self):
        if self.live_filter is not None:
            for key in self.filter_counts:
                self.filter_counts[key] += getattr(self.live_filter, key)

    # ------------------------------------------------------------------ input
    def queued_too_long(self, info):
        """True when the message of MessageInfo `info` (rclpy's dict) waited longer than
        max_queue_ms between its reception by the middleware and its callback (the node is
        behind). False when off (0) or when the middleware gives no reception time (0)."""
        received = (info or {}).get('received_timestamp') or 0
        limit_ns = self.derived.max_queue_ns
        return bool(limit_ns and received) and time.time_ns() - received > limit_ns

    def on_message(self, name, kind, msg, info=None):
        """kind 0 = heatmaps, 1 = camera_info: pair the two by exact stamp, then sync.
        info: the subscription's MessageInfo (received_timestamp, ns, system clock)."""
        stats = self.stats[name]
        stamp = header_stamp_ns(msg)
        mine, other = self.pending[name][kind], self.pending[name][1 - kind]
        now = time.monotonic()
        stale = self.queued_too_long(info)
        if kind == 0:
            stats.received += 1
            stats.last_seen = now
            self.first_heard = self.first_heard or stats.last_seen
        else:
            stats.info_received += 1
        if stamp in other:
            partner, _, partner_stale = other.pop(stamp)
            heat_msg, info_msg = (msg, partner) if kind == 0 else (partner, msg)
            stats.info_paired += 1
            self.on_pair(name, stamp, heat_msg, info_msg, stale or partner_stale)
        else:
            if stamp in mine:               # a second message of this stamp replaces the first
                self.let_go(stats, kind, repeated=True)
                del mine[stamp]
            mine[stamp] = (msg, now, stale)
            while len(mine) > _PAIR_BACKLOG:
                mine.popitem(last=False)
                self.let_go(stats, kind)
        for group in self.sync.poll():
            self.fuse(group)

    @staticmethod
    def let_go(stats, kind, repeated=False):
        """Count a heatmap (kind 0) or camera_info (1) given up before pairing."""
        if kind == 1:
            stats.info_unpaired += 1
        elif repeated:
            stats.repeated += 1
        else:
            stats.unpaired += 1

    def expire_unpaired(self, now):
        """Let go of the heatmaps / camera_info waiting for their partner longer than
        silent_after_s (oldest first: the backlogs are in arrival order)."""
        for name, backlogs in self.pending.items():
            for kind, backlog in enumerate(backlogs):
                while backlog and now - next(iter(backlog.values()))[1] \
                        >= self.config.silent_after_s:
                    backlog.popitem(last=False)
                    self.let_go(self.stats[name], kind)

    def outcomes(self, name):
        """{outcome: count} of camera `name`'s received heatmaps (OUTCOMES order); their sum
        is stats.received."""
        stats, sync = self.stats[name], self.sync.stats
        return {'fused': stats.fused, 'bad_messages': stats.bad, 'unpaired': stats.unpaired,
                'repeated': stats.repeated + sync.repeated_by_key[name],
                'late': sync.late_by_key[name],
                'dropped': stats.dropped + sync.dropped_by_key[name],
                'stale': stats.stale,
                'waiting': len(self.pending[name][0]) + self.sync.open_items(name)}

    def camera_info_counts(self, name):
        stats = self.stats[name]
        return {'camera_info_received': stats.info_received,
                'camera_info_paired': stats.info_paired,
                'camera_info_unpaired': stats.info_unpaired,
                'camera_info_waiting': len(self.pending[name][1])}

    def on_pair(self, name, stamp, heat_msg, info_msg, stale=False):
        # not decoded: its frame is skipped (fuse), the view counted there; a limit switched
        # off (0) since its first half arrived applies at once
        if stale and self.config.max_queue_ms:
            for group in self.sync.add(name, stamp, STALE):
                self.fuse(group)
            return
        start = time.perf_counter()
        if self.subjects is not None and not (heat_msg.width and heat_msg.height) \
                and not (info_msg.width and info_msg.height):
            for group in self.sync.add(name, stamp, EMPTY):    # a slot without a crop
                self.fuse(group)
            return
        try:
            heat = image_msg_to_heatmaps(heat_msg)
            if heat.shape[0] != self.skeleton.num_keypoints:
                raise ValueError(f'{heat.shape[0]} channels, the skeleton '
                                 f'{self.skeleton.name} has {self.skeleton.num_keypoints}')
            if (info_msg.width, info_msg.height) != (heat.shape[2], heat.shape[1]):
                raise ValueError(f'camera_info is {info_msg.width}x{info_msg.height}, the '
                                 f'heatmap {heat.shape[2]}x{heat.shape[1]}')
            K = np.asarray(info_msg.k, np.float64).reshape(3, 3)
            if not np.all(np.isfinite(heat)) or not np.all(np.isfinite(K)) or K[2, 2] != 1:
                raise ValueError('non-finite heatmap values or invalid K')
        except ValueError as error:
            self.bad_message(name, error)
            return
        self.timer.add('receive', time.perf_counter() - start)
        for group in self.sync.add(name, stamp, (heat, K)):
            self.fuse(group)

    def bad_message(self, name, error):
        stats = self.stats[name]
        stats.bad += 1
        stats.last_bad = str(error)
        topic = self.resolve_topic_name(self.config.heatmap_topic.format(camera=name))
        log_bad_once(self, topic, error, stats.bad)

    def on_poll(self):
        now = time.monotonic()
        self.expire_unpaired(now)
        # a camera not heard from yet counts as live until silent_after_s after the first
        # heatmap of any camera (it may still be starting up): the first frames wait for it
        starting = self.first_heard is None or now - self.first_heard < \
            self.config.silent_after_s
        live = [n for n, s in self.stats.items()
                if (s.last_seen is None and starting)
                or (s.last_seen is not None and now - s.last_seen < self.config.silent_after_s)]
        self.sync.set_expected([n for n in live if n not in self.unpublished])
        for group in self.sync.poll():
            self.fuse(group)

    def slot_topic_parts(self, camera):
        """(prefix, suffix) of the resolved heatmap topic of `camera`'s crop slots: a slot
        topic is prefix + k + suffix."""
        marker = 'Xslotnumber'
        topic = self.resolve_topic_name(self.config.heatmap_topic.format(
            camera=CROP_SLOT.format(camera=camera, slot=marker)))
        prefix, _, suffix = topic.partition(marker)
        return prefix, suffix

    def check_detector_slots(self):
        """subjects >= 2, every SLOT_CHECK_S: the crop slots each node publishes for each
        camera, from the ROS graph (its highest `<cam>/crop<k>/heatmaps` topic + 1), against
        the N + D this node subscribes (D from its discovery_tiles). A count held for
        silent_after_s (the detector's publishers all discovered) that differs is a
        discovery_tiles mismatch: logged once per publisher node (ERROR, naming the
        parameter, both values, the nodes and cameras), counted per camera in /diagnostics
        (discovery_slot_mismatch: instants received since), and the slots it never sends
        are no longer waited for (unpublished). Slots it sends beyond this node's are not
        subscribed: discovery sees only the first D of its maps."""
        now = time.monotonic()
        N = self.config.subjects
        topics = [name for name, _ in self.get_topic_names_and_types()]
        found = {}                                   # (camera index, node) -> slots
        for i, camera in enumerate(self.cameras):
            prefix, suffix = self.slot_topic_parts(camera.name)
            slots = {}                                      # k -> its topic
            for topic in topics:
                middle = topic[len(prefix):len(topic) - len(suffix)]
                if topic.startswith(prefix) and topic.endswith(suffix) and middle.isdigit():
                    slots[int(middle)] = topic
            expected = len(self.sources[i])
            # the publishers of crop0, of this node's last slot and of any beyond (a few
            # graph queries per camera); all of them where a node stops short of the last
            first = self.slot_publishers(slots, [0, expected - 1]
                                         + [k for k in slots if k >= expected])
            if any(k < expected - 1 for k in first.values()):
                first = self.slot_publishers(slots, sorted(slots))
            for node, k in first.items():
                found[i, node] = k + 1
        for i in range(len(self.cameras)):
            seen = self.detector_slots.setdefault(i, {})
            for node in [n for n in seen if (i, n) not in found]:
                del seen[node]                      # gone: its slots are no longer known
        for (i, node), slots in found.items():
            entry = self.detector_slots[i].get(node)
            if entry is None or entry[0] != slots:
                self.detector_slots[i][node] = [slots, now]
        unpublished, new = set(), {}
        for i, seen in self.detector_slots.items():
            expected = len(self.sources[i])
            held = {node: slots for node, (slots, since) in seen.items()
                    if now - since >= self.config.silent_after_s}
            wrong = {node: slots for node, slots in held.items() if slots != expected}
            if wrong:
                self.slot_mismatch[i] = wrong
            else:
                self.slot_mismatch.pop(i, None)
            if held and len(held) == len(seen):     # every publisher's count is settled
                most = max(held.values())
                unpublished.update(self.sources[i][max(most, N):])
            for node, slots in wrong.items():
                if (node, i) not in self.slot_logged:
                    self.slot_logged.add((node, i))
                    new.setdefault((node, slots, expected), []).append(i)
        self.unpublished = unpublished
        for (node, slots, expected), cams in new.items():
            self.get_logger().error(self.mismatch_line(node, slots, expected, cams))

    def slot_publishers(self, topics, ks):
        """{publisher node (fully qualified): its highest slot k} among the slot topics
        `topics` ({k: topic}) of the slots `ks`."""
        out = {}
        for k in ks:
            if k not in topics:
                continue
            for info in self.get_publishers_info_by_topic(topics[k]):
                node = '/' + '/'.join(p for p in (info.node_namespace.strip('/'),
                                                  info.node_name) if p)
                out[node] = max(out.get(node, -1), k)
        return out

    def mismatch_line(self, node, slots, expected, cams):
        """The one line logged for a publisher `node` sending `slots` crop slots per instant
        for the cameras `cams` (indices) where this node expects `expected`."""
        N, tiles = self.config.subjects, self.config.discovery_tiles
        camera = self.cameras[cams[0]]
        theirs = discovery_tiles_for(camera.width, camera.height, slots - N)
        value = (' or '.join(map(str, theirs)) if theirs else 'unknown')
        if slots > expected:
            effect = (f'its slots crop{expected}..crop{slots - 1} are not subscribed: '
                      f'discovery uses only the first {expected - N} of its maps')
        else:
            effect = (f'frames no longer wait for the slots crop{max(slots, N)}..'
                      f'crop{expected - 1} it never sends')
        return (f'discovery_tiles differs between {node} and {self.get_fully_qualified_name()}'
                f': for camera(s) {", ".join(self.names[i] for i in cams)} '
                f'({camera.width}x{camera.height}) {node} publishes {slots - N} discovery '
                f'crop slot(s) (its discovery_tiles {value}), this node expects '
                f'{expected - N} (its discovery_tiles {tiles}); set the parameter '
                f'discovery_tiles (and subjects, {N} here) the same on both nodes. '
                f'Meanwhile {effect}; counted per camera in /diagnostics '
                '(discovery_slot_mismatch)')

    # ------------------------------------------------------------------ fusion
    def fuse(self, group):
        if self.subjects is not None:
            self.fuse_subjects(group)
            return
        views = [i for i, name in enumerate(self.names) if name in group.items]
        if any(group.items[self.names[i]] is STALE for i in views):
            self.skip_stale(group, views)
            return
        cameras = [self.cameras[i] for i in views]
        heat = [group.items[self.names[i]][0] for i in views]
        K_heat = np.stack([group.items[self.names[i]][1] for i in views])
        try:
            result = fuse_heatmaps(heat, K_heat, cameras, self.core_config, self.timer)
        except ValueError as error:
            # e.g. a camera_info whose K is not a crop of the rig camera: name the view.
            message = str(error)
            index = None
            if message.startswith('view '):
                index = int(message.split()[1].rstrip(':'))
                self.bad_message(cameras[index].name, message)
            else:
                self.get_logger().error(f'fusion failed at stamp {group.stamp_ns}: {error}')
            for k, cam in enumerate(cameras):
                if k != index:
                    self.stats[cam.name].dropped += 1
            return
        for index, reason in result.skipped_views.items():  # e.g. a 2x2 heatmap grid
            self.bad_message(cameras[index].name, reason)
        self.frames += 1
        self.partial_frames += bool(group.missing)
        self.fusion_seconds = (self.fusion_seconds + [result.seconds])[-100:]
        errors = result.view_mean_errors()
        for k, i in enumerate(views):
            if k in result.skipped_views:      # counted as a bad message above
                continue
            stats = self.stats[self.names[i]]
            stats.fused += 1
            stats.errors = (stats.errors + [float(errors[k])])[-100:]
        self.last_result, self.last_stamp_ns = result, group.stamp_ns
        X = result.X
        if self.live_filter is not None:
            start = time.perf_counter()
            X, _ = self.live_filter.update(group.stamp_ns, result.X)
            self.timer.add('filter', time.perf_counter() - start)
        start = time.perf_counter()
        if self.live_filter is not None:
            self.pub_raw.publish(keypoints3d_to_cloud(
                group.stamp_ns, self.frame_id, result.X, result.confidence,
                result.reprojection_error, result.num_views, units=self.units))
        self.pub_points.publish(keypoints3d_to_cloud(
            group.stamp_ns, self.frame_id, X, result.confidence,
            result.reprojection_error, result.num_views, units=self.units))
        # the skeleton markers (~2 ms a frame to build and serialize) only while someone
        # (RViz, a recorder) subscribes
        if self.pub_skeleton.get_subscription_count():
            self.pub_skeleton.publish(skeleton_marker_array(
                group.stamp_ns, self.frame_id, X, self.skeleton.bone_indices,
                ns=self.marker_ns, lifetime_ns=self.derived.marker_lifetime_ns, scale=0.03,
                names=self.skeleton.keypoints if self.config.marker_labels else None,
                units=self.units))
        self.timer.add('publish', time.perf_counter() - start)
        for listener in self.listeners:
            listener(group.stamp_ns, result, X if self.live_filter is not None else None)

    def fuse_subjects(self, group):
        """subjects >= 2: the crops of one instant (every slot of every camera present)
        through SubjectsCore.live_frame, the tracked subjects published."""
        keys = [key for key in self.keys if key in group.items]
        for i in {self.key_camera[key] for key in keys}:
            if i in self.slot_mismatch:
                self.mismatch_frames[i] += 1
        if any(group.items[key] is STALE for key in keys):
            self.skip_stale(group, keys)
            return
        filled = [key for key in keys if group.items[key] is not EMPTY]
        present = sorted({self.key_camera[key] for key in filled})
        cameras = [self.cameras[i] for i in present]
        view = {camera: v for v, camera in enumerate(present)}
        crops, full, sources = [], [], []
        for key in filled:
            heat, K = group.items[key]
            v = view[self.key_camera[key]]
            _, bad = crop_scales(K, cameras[v].K)
            if bad[0]:
                self.bad_message(key, 'heatmap K is not a crop/scale of the rig camera '
                                 f'{cameras[v].name}')
                continue
            sources.append(key)
            (full if key in self.discovery_keys else crops).append((v, heat, K))
        tracker = self.subjects.tracker
        if tracker.stamp is not None and group.stamp_ns <= tracker.stamp:
            # time went back (a replay looped, a new recording): identities start again
            self.subjects = self.subjects_core(self.config)
            self.subject_counts['resets'] += 1
            self.subject_stats.clear()
            if self.live_filter is not None:    # identity 0 is now another subject
                self.live_filter.clear()
        start = time.perf_counter()
        try:
            result = self.subjects.live_frame(cameras, group.stamp_ns, crops, full)
        except ValueError as error:
            self.get_logger().error(f'fusion failed at stamp {group.stamp_ns}: {error}')
            for key in keys:
                if key in sources or group.items[key] is EMPTY:
                    self.stats[key].dropped += 1
            return
        self.timer.add('subjects', time.perf_counter() - start)
        self.frames += 1
        # a slot its detector never sends (a discovery_tiles mismatch) makes no frame partial
        self.partial_frames += any(key not in self.unpublished for key in group.missing)
        self.fusion_seconds = (self.fusion_seconds + [time.perf_counter() - start])[-100:]
        for key in ('duplicates', 'shared', 'detached', 'extra', 'weak', 'foreign', 'settled'):
            self.subject_counts[key] += getattr(result, key)
        self.subject_counts['discoveries'] += result.discovered >= 0
        a = result.association
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)         # views without inliers
            errors = np.nanmean(np.where(a.inliers[result.keep], a.view_errors[result.keep],
                                         np.nan), axis=(0, 2)) if len(result.keep) \
                else np.full(len(cameras), np.nan)
        for key in keys:
            if key in sources or group.items[key] is EMPTY:
                stats = self.stats[key]
                stats.fused += 1
                if key in sources:
                    error = errors[view[self.key_camera[key]]]
                    stats.errors = (stats.errors + [float(error)])[-100:]
        ids, X, score, error, views = subject_keypoints(result)
        self.last_stamp_ns = group.stamp_ns
        for k, ident in enumerate(ids.tolist()):
            entry = self.subject_stats.setdefault(ident, dict(frames=0))
            entry.update(frames=entry['frames'] + 1, last_stamp_ns=group.stamp_ns,
                         keypoints=int(np.isfinite(X[k]).all(-1).sum()),
                         error=float(np.nanmean(error[k])) if np.isfinite(error[k]).any()
                         else float('nan'))
        alive = set(self.subjects.tracker.ids.tolist())
        for ident in [i for i in self.subject_stats if i not in alive]:
            del self.subject_stats[ident]                 # died (or the identities restarted)
        filtered = None
        if self.live_filter is not None:     # one filter per identity, the dead ones dropped
            start = time.perf_counter()
            filtered, _ = self.live_filter.update(group.stamp_ns, ids, X,
                                                  alive=self.subjects.tracker.ids)
            self.timer.add('filter', time.perf_counter() - start)
        start = time.perf_counter()
        C = self.skeleton.num_keypoints
        fields = dict(units=self.units, keypoint=np.tile(np.arange(C), len(ids)),
                      subject=np.repeat(ids, C))
        if filtered is not None:
            self.pub_raw.publish(keypoints3d_to_cloud(
                group.stamp_ns, self.frame_id, X.reshape(-1, 3), score.reshape(-1),
                error.reshape(-1), views.reshape(-1), **fields))
        shown = X if filtered is None else filtered
        self.pub_points.publish(keypoints3d_to_cloud(
            group.stamp_ns, self.frame_id, shown.reshape(-1, 3), score.reshape(-1),
            error.reshape(-1), views.reshape(-1), **fields))
        if self.pub_skeleton.get_subscription_count() and len(ids):
            markers = []
            for k, ident in enumerate(ids.tolist()):
                markers += skeleton_marker_array(
                    group.stamp_ns, self.frame_id, shown[k], self.skeleton.bone_indices,
                    ns=f'{self.skeleton.name}/subject{ident}',
                    lifetime_ns=self.derived.marker_lifetime_ns, scale=0.03,
                    names=self.skeleton.keypoints if self.config.marker_labels else None,
                    units=self.units, subject=ident).markers
            self.pub_skeleton.publish(MarkerArray(markers=markers))
        self.timer.add('publish', time.perf_counter() - start)
        if self.listeners:                # e.g. monet pipeline's summary: every subject
            frame = SimpleNamespace(
                X=X.reshape(-1, 3), confidence=score.reshape(-1),
                reprojection_error=error.reshape(-1), num_views=views.reshape(-1),
                keypoint=np.tile(np.arange(C), len(ids)), subject=np.repeat(ids, C))
            for listener in self.listeners:
                listener(group.stamp_ns, frame,
                         None if filtered is None else filtered.reshape(-1, 3))

    def skip_stale(self, group, views):
        """A frame with a view that waited too long in the input queue: not fused, each of
        its views (indices into names, or with subjects >= 2 crop slot names) counted
        stale; logged once."""
        self.stale_frames += 1
        for i in views:
            self.stats[i if isinstance(i, str) else self.names[i]].stale += 1
        if self.stale_frames == 1:
            self.get_logger().warning(
                f'falling behind: frame {group.stamp_ns} had input queued longer than '
                'max_queue_ms and is skipped to keep the outputs fresh; further ones are '
                'counted (stale) in /diagnostics')

    def publish_rig_tf(self):
        """The rig on /tf_static (latched), or one log line saying why not."""
        TFMessage = tf_message_class()
        if TFMessage is None:
            self.get_logger().warning('tf2_msgs is not installed: the rig is not published on '
                                      '/tf_static')
            return
        self.pub_tf = self.create_publisher(TFMessage, TF_STATIC, LATCHED)
        self.pub_tf.publish(rig_tf_message(self.cameras, self.frame_id,
                                           self.get_clock().now().to_msg()))

    def on_stop(self):
        """Before the node goes: log where every received message ended (one line per
        camera), clear the viewers' skeleton (DELETEALL), waiting briefly for the
        subscribers to acknowledge it."""
        for line in self.summary_lines():
            self.get_logger().info(line)
        msg = delete_all_markers(self.get_clock().now().nanoseconds, self.frame_id)
        self.pub_skeleton.publish(msg)
        self.pub_skeleton.wait_for_all_acked(Duration(seconds=1.0))

    # ------------------------------------------------------------------ diagnostics
    def filter_totals(self):
        """Time resets, joint restarts and gated measurements of the live filter(s) since
        start."""
        live = self.live_filter
        return {key: value + (getattr(live, key) if live is not None else 0)
                for key, value in self.filter_counts.items()}

    def summary_lines(self):
        """One line per camera: received heatmaps = the sum of their outcomes, and the
        camera_info counts."""
        lines = []
        for name, stats in self.stats.items():
            parts = ', '.join(f'{k} {v}' for k, v in self.outcomes(name).items())
            info = self.camera_info_counts(name)
            lines.append(f'{name}: {stats.received} heatmaps received: {parts}; '
                         f'{info["camera_info_received"]} camera_info received: '
                         f'paired {info["camera_info_paired"]}, unpaired '
                         f'{info["camera_info_unpaired"]}, waiting {info["camera_info_waiting"]}')
        return lines

    def subject_values(self):
        """subjects >= 2: the summary's several-subject counts (none with one subject)."""
        if self.subjects is None:
            return []
        tracker = self.subjects.tracker
        return [('subjects', self.config.subjects),
                ('subjects_tracked', len(self.subject_stats)),
                ('identities', sorted(self.subject_stats)),
                ('births', tracker.births), ('deaths', tracker.deaths),
                ('untracked', tracker.untracked),
                ('identity_resets', self.subject_counts['resets']),
                # per camera: the discovery slots its detector publishes (the ROS graph) and,
                # where that is not this node's count (discovery_tiles), the instants since
                ('detector_discovery_slots', {
                    self.names[i]: sorted({slots - self.config.subjects
                                           for slots, _ in seen.values()})
                    for i, seen in self.detector_slots.items() if seen}),
                ('discovery_slot_mismatch', {self.names[i]: self.mismatch_frames[i]
                                             for i in sorted(self.slot_mismatch)}),
                *((f'subject_{key}', value) for key, value in self.subject_counts.items()
                  if key != 'resets')]

    def subject_statuses(self):
        """subjects >= 2: one status per tracked identity ('monet fusion: subject <id>')."""
        statuses = []
        for ident, entry in sorted(self.subject_stats.items()):
            current = entry['last_stamp_ns'] == self.last_stamp_ns
            statuses.append(DiagnosticStatus(
                level=DiagnosticStatus.OK if current else DiagnosticStatus.WARN,
                name=f'monet fusion: subject {ident}', hardware_id=f'subject{ident}',
                message=(f'{entry["keypoints"]} keypoints, mean reprojection error '
                         f'{entry["error"]:.2f} px' if current else 'not seen in the last '
                         'frame (kept until max_missed_s)'),
                values=[KeyValue(key=k, value=str(v)) for k, v in (
                    ('subject', ident), ('frames', entry['frames']),
                    ('keypoints', entry['keypoints']),
                    ('mean_reprojection_error_px', f'{entry["error"]:.4f}'),
                    ('last_stamp_ns', entry['last_stamp_ns']))]))
        return statuses

    def publish_diagnostics(self):
        now = time.monotonic()
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        fusion_ms = 1e3 * float(np.median(self.fusion_seconds)) if self.fusion_seconds else 0.0
        summary = DiagnosticStatus(
            level=DiagnosticStatus.OK, name='monet fusion', hardware_id=self.frame_id,
            message=f'{self.frames} frames fused ({self.partial_frames} with missing cameras)',
            values=[KeyValue(key=k, value=str(v)) for k, v in (
                ('frames', self.frames), ('partial_frames', self.partial_frames),
                ('units', self.units), ('topic_units', 'm'),
                ('dropped_frames', self.sync.stats.dropped), ('stale_frames', self.stale_frames),
                ('late_views', self.sync.stats.late),
                ('time_resets', self.sync.stats.resets),
                ('repeated_stamps', dict(self.sync.stats.repeated_by_key)),
                ('fusion_ms_median', f'{fusion_ms:.3f}'),
                ('filter', 'on' if self.live_filter is not None else 'off'),
                *((f'filter_{key}', value) for key, value in self.filter_totals().items()),
                # mean ms per call since start: receive (per view), decode, undistort,
                # triangulate, errors, publish (per frame)
                *self.timer.summary().items(),
                *self.subject_values())])
        msg.status.append(summary)
        msg.status.extend(self.subject_statuses())
        for name, stats in self.stats.items():
            silent_for = None if stats.last_seen is None else now - stats.last_seen
            error = stats.mean_error()
            if name in self.unpublished:
                level, text = DiagnosticStatus.WARN, ('not published by the detector: '
                                                      'discovery_tiles differs (the log)')
            elif stats.last_seen is None:
                level, text = DiagnosticStatus.WARN, 'silent: no heatmaps received yet'
            elif silent_for >= self.config.silent_after_s:
                level, text = DiagnosticStatus.WARN, f'silent for {silent_for:.1f} s'
            else:
                level, text = DiagnosticStatus.OK, f'mean reprojection error {error:.2f} px'
            outcomes = self.outcomes(name)
            if stats.bad and level == DiagnosticStatus.OK:
                text += f'; {stats.bad} bad messages'
            if stats.unpaired:
                text += f'; {stats.unpaired} heatmaps without a camera_info of their stamp'
                if not stats.fused:
                    level = DiagnosticStatus.WARN
            if (name in self.discovery_keys and name not in self.unpublished
                    and self.key_camera[name] in self.slot_mismatch):
                level = DiagnosticStatus.WARN
                text += "; the detector's discovery slots differ: discovery_tiles (the log)"
            msg.status.append(DiagnosticStatus(
                level=level, name=f'monet fusion: {name}', hardware_id=name, message=text,
                values=[KeyValue(key=k, value=str(v)) for k, v in (
                    ('mean_reprojection_error_px', f'{error:.4f}'),
                    ('received', stats.received), *outcomes.items(),
                    *self.camera_info_counts(name).items(),
                    ('silent_for_s', 'never seen' if silent_for is None
                     else f'{silent_for:.2f}'),
                    ('last_bad_message', stats.last_bad))]))
        self.pub_diag.publish(msg)


def main(args=None):
    return run_node(FusionNode, 'fusion', args)


if __name__ == '__main__':
    sys.exit(main())
