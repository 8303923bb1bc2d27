"""`monet pipeline`: player + detector + fusion as ROS nodes, player and detector in child
processes.

    monet pipeline                           # demo: synthetic recording + a model for it
    monet pipeline --bag REC --model CKPT [--rig RIG] [--rate 0.5] [--loop] [--lockstep]
    monet pipeline --bag REC --model CKPT --loop --learn    # + online learner (hot reload)
    monet pipeline --bag REC --model CKPT --subjects 2      # several subjects (subjects.md)

This process runs the fusion node (and the learner, which trains in its own thread) in
one SingleThreadedExecutor (pipeline_executor); the player (replaying REC) and the detector
(every camera in one batched forward; or --detector-processes N, each a share of the
cameras, the CPU cores shared out between them: detector_threads) each run in a child process
(monet_ros.nodes.child: with its own interpreter lock each is as fast as its executable;
sharing this process, the detector's short GIL-free calls waited behind the other nodes'
Python, 3-4x slower, and the player's publishing put a tail on fusion's latency: p95 106 /
312 ms float32 / bfloat16 at 8 cameras @ 30 Hz against 48 / 28 ms in three processes),
started with this command's --ros-args and stopped with it (SIGKILLed if it dies). The
player announces each frame on played_frames ([stamp, wall time], a few bytes: this
process times latency from it without receiving any image) and, with --lockstep, waits for
the previous frame's keypoints3d itself. Other processes see the usual topics
(/monet/keypoints3d, /monet/skeleton, /diagnostics, ...). A summary line is printed every
second: frames fused, fps, latency (player publish -> 3D keypoints, median / p95) and the
mean reprojection error; a final summary when the recording ends (or Ctrl-C, or
--duration).
"""
from collections import deque
from dataclasses import dataclass
import math
import sys
import threading
import time

import numpy as np

from monet_ros.commands.pipeline_learn import add_learn_arguments, learner_node
from monet_ros.config import ConfigError, setting, validate_config
from monet_ros.cores import threads_each, usable_cores

# --detector-processes 0 (auto): two detector processes from this many cameras on when the
# network runs in float32 or int8 on the CPU, else one. bench/pipeline.py
# --detector-processes 1 2 at 16 cameras @ 30 Hz, 128 px, quiet 2-core AMX Xeon
# (bench/results/pipeline.md, 2026-12-05 10:53 UTC): float32 two 24.5 keypoints3d/s against
# 16.0 with one (one cannot keep up: 53 ms of work per 33 ms instant); bfloat16 one 28.8 /s,
# p95 81 ms against two 30.2 /s, p95 119 ms: one keeps up with the instants (22 ms of work
# each), and two, each skipping instants at its own phase, leave frames with half the views
# that wait for the next instant (2026-12-04, one: p95 89 / 96 ms; 2026-12-05 06:11, two:
# 121-124 ms). At 8 cameras one did as well as two (bfloat16, loaded: 28 / 18 against 28 / 19
# keypoints3d/s, three-process / pipeline).
TWO_DETECTORS_FROM = 16
SPLIT_PRECISIONS = ('float32', 'int8')
HELP = ('live all-in-one: player + detector + fusion as ROS nodes (player and detector in '
        'child processes)')


def add_arguments(parser):
    parser.add_argument('--bag', help='recording (rosbag2 folder, .mcap or `monet synth` '
                        'folder); default: a small synthetic recording generated (once) in '
                        '--workdir')
    parser.add_argument('--rig', help="rig file (default: the recording's camera_info + "
                        '/tf_static, or the rig.yaml beside a synthetic recording)')
    from monet_ros.commands.common import (
        add_precision_options,
        add_rig_units_argument,
        subject_only_option,
    )
    add_rig_units_argument(parser)
    parser.add_argument('--model', help='detector checkpoint (default with no --bag: a small '
                        'net trained once for the synthetic recording)')
    parser.add_argument('--skeleton', default='human14',
                        help='skeleton preset or YAML (keypoint order of the model, bones)')
    parser.add_argument('--cameras', nargs='+', help='cameras to use (default: all)')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='playback speed (0 = as fast as possible; default 1)')
    parser.add_argument('--loop', action='store_true', help='replay the recording forever')
    parser.add_argument('--lockstep', action='store_true',
                        help='publish a frame only when the previous one was fused (every '
                        'frame processed, no drops; pace = processing speed)')
    parser.add_argument('--duration', type=float, default=0.0,
                        help='stop after this many seconds (0 = at the end of the recording)')
    parser.add_argument('--threshold-px', type=float, default=15.0,
                        help='fusion inlier threshold in image pixels')
    parser.add_argument('--confidence-threshold', type=float, default=0.1,
                        help='heatmap peak value below which a view is ignored (as in '
                        '`monet process`)')
    parser.add_argument('--no-debug-image', dest='debug_image', action='store_false',
                        help='do not publish <cam>/debug_image (on by default, 2 Hz per camera, '
                        'only drawn while someone subscribes)')
    parser.add_argument('--device', default='', help="torch device ('' = auto)")
    parser.add_argument('--threads', type=int, default=0,
                        help='CPU threads of the network and of decoding and cropping the views '
                        'in each detector process (0 = the backend default and the cores '
                        'with one process, the cores shared out with several)')
    add_precision_options(parser, '--bag')
    parser.add_argument('--workdir', help='where the demo recording and model are cached '
                        '(default: ~/.cache/monet_ros/demo)')
    parser.add_argument('--start-delay', type=float, default=0.5,
                        help='seconds between start-up and the first frame (discovery)')
    parser.add_argument('--subjects', type=int, default=1,
                        help='most subjects tracked (detector and fusion `subjects`; >= 2: '
                        'crop slots, keypoints3d with a subject field; docs/subjects.md)')
    subject_only_option(parser, '--link-mm', type=float, default=600.0,
                        help='--subjects >= 2: largest distance (mm) between two linked '
                        'keypoints of one subject (fusion link_mm)')
    subject_only_option(parser, '--discovery-tiles', type=int, default=None,
                        help='--subjects >= 2: discovery tiles along the shorter image side '
                        "(0: the whole frame); the fusion node's discovery_tiles (default its "
                        "parameter's, 2), given to the detectors too: their discovery crop "
                        'slots agree')
    subject_only_option(parser, '--discovery-period-s', type=float, default=None,
                        help='--subjects >= 2: while fewer subjects are tracked, the '
                        'detectors send discovery maps in the first frame of each window of '
                        "this many seconds of the stamps (0: every frame; default the "
                        "detector's discovery_period_s, 0.25)")
    parser.add_argument('--quiet', action='store_true', help='no per-second summary lines')
    parser.add_argument('--detector-processes', type=int, default=0,
                        help='detector processes, each batching its share of the cameras '
                        f'(default 0 = auto: 2 from {TWO_DETECTORS_FROM} cameras on in float32 '
                        'or int8, else 1; measured with bench/pipeline.py)')
    add_learn_arguments(parser)


@dataclass(frozen=True)
class PipelineOptions:
    """The numeric options of `monet pipeline` (validated; errors name the option)."""
    rate: float = setting(1.0, 'playback speed (0 = as fast as possible)', minimum=0.0,
                          maximum=1000.0)
    duration: float = setting(0.0, 'stop after this many seconds (0 = at the end)',
                              minimum=0.0)
    start_delay: float = setting(0.5, 'seconds between start-up and the first frame',
                                 minimum=0.0, maximum=3600.0)
    detector_processes: int = setting(0, 'detector processes (cameras split between them; '
                                      f'0 = 2 from {TWO_DETECTORS_FROM} cameras in float32 or '
                                      'int8, else 1)',
                                      minimum=0, maximum=64)

    def __post_init__(self):
        validate_config(self)


# Samples kept for the latency / error statistics (the last ones: bounded whatever the run
# length; at 30 frames/s, about two minutes).
SUMMARY_SAMPLES = 4096


class Summary:
    """Live figures from the player and fusion listeners (thread-safe, bounded state: the
    per-frame samples are the last `samples` ones, the totals running counts)."""

    def __init__(self, samples=SUMMARY_SAMPLES):
        self.lock = threading.Lock()
        self.published = {}       # frame stamp -> wall time of its first image
        self.latencies = deque(maxlen=samples)   # (wall time, seconds)
        self.errors = deque(maxlen=samples)      # (wall time, mean reprojection error px)
        self.first_fused = None   # wall time of the first / last frame with a latency
        self.timed_frames = 0     # frames with a latency (running count)
        self.error_sum, self.error_count = 0.0, 0
        self.frames = 0
        self.frames_published = 0
        self.last_fused = None
        self.last_stamp = -1
        self.replay_ended = threading.Event()   # the player's end of the recording
        self.joint_fused = None   # (C,) frames in which each joint was triangulated
        self.joint_views = None   # (C,) sum of its inlier views over those frames
        self.joint_frames = 0     # frames (with several subjects: subject-frames) counted
        # callable: (identities alive, of them matched in the last frame, births, deaths),
        # subjects >= 2
        self.subject_counts = None
        self.names = None         # keypoint names (the fusion node's skeleton)
        self.stale_frames = None  # callable: frames fusion skipped as stale (max_queue_ms)

    def on_image(self, topic, stamp_ns, wall):
        with self.lock:
            if stamp_ns not in self.published:
                self.frames_published += 1
            self.published.setdefault(stamp_ns, wall)
            if len(self.published) > 10000:
                self.published.pop(next(iter(self.published)))

    def on_fused(self, stamp_ns, result, filtered=None):
        """A fused frame (the fusion node's listener; its figures are of the raw
        fusion result: reprojection error and views are not changed by the filter)."""
        now = time.monotonic()
        with self.lock:
            self.frames += 1
            self.last_fused = now
            start = self.published.get(stamp_ns)
            if start is not None:
                self.latencies.append((now, now - start))
                self.first_fused = self.first_fused or now
                self.timed_frames += 1
            error = result.reprojection_error
            if np.isfinite(error).any():
                mean = float(np.nanmean(error))
                self.errors.append((now, mean))
                self.error_sum += mean
                self.error_count += 1
            self.last_stamp = max(self.last_stamp, stamp_ns)
            fused = np.isfinite(result.X).all(axis=1)
            # several subjects: one point per keypoint and subject, `keypoint` its index
            keypoint = getattr(result, 'keypoint', None)
            C = len(fused) if keypoint is None else len(self.names or ()) or \
                int(keypoint.max(initial=-1)) + 1
            if self.joint_fused is None or len(self.joint_fused) != C:
                self.joint_fused = np.zeros(C, np.int64)
                self.joint_views = np.zeros(C, np.int64)
                self.joint_frames = 0
            if keypoint is None:
                keypoint = np.arange(C)
            np.add.at(self.joint_fused, keypoint, fused)
            np.add.at(self.joint_views, keypoint,
                      np.where(fused, result.num_views, 0).astype(np.int64))
            self.joint_frames += len(fused) // max(C, 1)

    def line(self, window=None):
        """The status line: the last `window` seconds, or the whole run (latency percentiles
        over the last samples kept)."""
        now = time.monotonic()
        with self.lock:
            recent = [(t, s) for t, s in self.latencies if window is None or now - t <= window]
            err = [e for t, e in self.errors if window is None or now - t <= window]
            timed, first = self.timed_frames, self.first_fused
            last = self.latencies[-1][0] if self.latencies else None
            error_mean = self.error_sum / self.error_count if self.error_count else math.nan
        lat = [s for _, s in recent]
        parts = [f'frames {self.frames} fused of {self.frames_published} played']
        stale = self.stale_frames() if self.stale_frames is not None else 0
        if stale:
            parts[0] += f' ({stale} skipped as stale: fusion fell behind, max_queue_ms)'
        if window is not None:
            parts.append(f'{len(recent) / window:5.1f} fps')
        elif timed > 1 and last > first:
            parts.append(f'{(timed - 1) / (last - first):5.1f} fps')
        if lat:
            parts.append(f'latency median {1e3 * np.median(lat):5.0f} ms '
                         f'p95 {1e3 * np.percentile(lat, 95):5.0f} ms')
        if window is not None and err:
            parts.append(f'reprojection error {np.mean(err):5.2f} px')
        elif window is None and self.error_count:
            parts.append(f'reprojection error {error_mean:5.2f} px')
        if self.subject_counts is not None:
            alive, last, births, deaths = self.subject_counts()
            # alive: identities the tracker still holds (missed ones until max_missed_s),
            # which can be more than --subjects; at most N are output per frame
            parts.append(f'subjects {last} in the last frame ({alive} identities alive), '
                         f'{births} births, {deaths} deaths')
        if window is None and self.joint_fused is not None and self.joint_frames:
            parts.append(self.joint_line())
        return ' | '.join(parts)

    def joint_line(self, names=None):
        """Per-joint dropout and inlier views, and what reprojection error means."""
        with self.lock:
            fused, views = self.joint_fused.copy(), self.joint_views.copy()
            frames = self.joint_frames
        dropout = 1.0 - fused / max(frames, 1)
        names = names or self.names or [f'joint {c}' for c in range(len(fused))]
        worst = int(np.argmax(dropout))
        mean_views = views.sum() / max(fused.sum(), 1)
        return (f'joints triangulated {100 * (1 - dropout.mean()):.0f}% (most dropped: '
                f'{names[worst]} {100 * dropout[worst]:.0f}%), mean inlier views '
                f'{mean_views:.2f} (reprojection error is agreement between views, not '
                'accuracy)')


def image_transport(bag, cameras):
    """'compressed' when the recording holds only CompressedImage topics for the cameras
    (the one image-topic rule of `monet process` and `monet train`:
    io.multiview.image_topics), else 'raw'."""
    from monet_ros.io import open_bag
    from monet_ros.io.multiview import image_topics
    from monet_ros.io.multiview import image_transport as transport_of

    return transport_of(image_topics(open_bag(bag), cameras, bag))


def check_skeleton(fusion, model_names, skeleton, model):
    """ConfigError naming both when the skeleton's keypoints are not the model's."""
    names = list(fusion.skeleton.keypoints)
    model_names = list(model_names)
    if names != model_names:
        raise ConfigError('monet pipeline', 'skeleton',
                          f'{skeleton} has keypoints {names}, the model {model} has '
                          f'{model_names}; give --skeleton matching the model')


def detector_connected(fusion):
    """True once the detector process is discovered: something publishes every heatmap and
    camera_info topic that `fusion` subscribes to, and subscribes to its keypoints3d (so
    the first frames are not lost to discovery)."""
    return (fusion.pub_points.get_subscription_count() > 0
            and all(fusion.count_publishers(sub.topic_name) for sub in fusion.subscriptions))


def tf_topics(bag):
    """['/tf_static'] when the recording has it (the player replays it, latched, so that
    viewers see the rig's frames; it says so when tf2_msgs is not installed), else []."""
    from monet_ros.io import open_bag
    return [t for t in ('/tf_static',) if t in open_bag(bag).topics]


def detector_groups(slots, processes, precision):
    """The camera names of `slots` in `processes` contiguous groups of near-equal size (one
    detector process each). processes 0: auto, two from TWO_DETECTORS_FROM cameras on when
    `precision` (the one that runs: 'float32', 'bfloat16' or 'int8') is in SPLIT_PRECISIONS,
    else one. ConfigError naming --detector-processes when there are fewer cameras than
    processes."""
    names = [slot.name for slot in slots]
    processes = processes or (2 if len(names) >= TWO_DETECTORS_FROM
                              and precision in SPLIT_PRECISIONS else 1)
    if processes > len(names):
        raise ConfigError('monet pipeline', 'detector_processes',
                          f'{processes} detector processes for {len(names)} cameras; give at '
                          f'most {len(names)}')
    bounds = np.linspace(0, len(names), processes + 1).round().astype(int)
    return [names[a:b] for a, b in zip(bounds[:-1], bounds[1:])]


def groups_line(groups, processes, precision):
    """The line saying how many detector processes run and, for auto, why."""
    cameras = sum(len(group) for group in groups)
    line = f'{len(groups)} detector process{"es" * (len(groups) > 1)} for {cameras} cameras'
    if not processes:
        line += (f' (--detector-processes auto: 2 from {TWO_DETECTORS_FROM} cameras in '
                 f'{" or ".join(SPLIT_PRECISIONS)}, else 1; precision {precision})')
    return line


def prepare_int8(model, bag, calibration=None, backend='onnxruntime', threads=0,
                 fusion=None, subjects=None):
    """precision int8 of `monet pipeline`, once, before the detector processes start: the
    network of checkpoint `model` quantised on the tracked crops (the detector nodes track,
    with the default rule: monet_ros.int8_calibration) of `calibration` or else of the
    recording `bag`, and cached beside the checkpoint; a cached quant of those crops is
    used as it is (nothing calibrated). fusion: the FusionConfig of the run (None = the
    defaults). Returns (what the detector nodes get as their calibration parameter: the
    cached quant's path, or `calibration` / `bag` where it could not be cached, the one
    line saying which quant: calibrated on what crops of what, or the cached one used).
    Raises ValueError (models.quantize.Int8Error: one line) as Detector.from_checkpoint
    does for precision int8. bench/pipeline.py --precision int8 prepares its runs with
    this. subjects: the detectors' subjects.detection.SubjectsConfig with subjects >= 2
    (--subjects N): the crops of a several-subject run (int8_calibration.subject_crops),
    under the crops key the detector nodes look for."""
    from monet_ros.int8_calibration import int8_calibration
    from monet_ros.models import Detector
    from monet_ros.models.quantize import cached_int8
    int8_crops, given = int8_calibration(calibration or bag, True, fusion=fusion,
                                         subjects=subjects)
    detector = Detector.from_checkpoint(model, device='cpu', backend=backend,
                                        threads=threads, precision='int8',
                                        calibration=given, int8_crops=int8_crops)
    return (str(cached_int8(model, crops=int8_crops) or calibration or bag),
            detector.int8_note)


def detector_threads(threads, processes, cores):
    """CPU threads of each detector process's network: `threads` when given (> 0); with
    one process 0 (the backend's default: every core); with several, the cores shared out
    (at least 1 each): two processes of two threads each on 2 cores oversubscribe them
    (bench/pipeline.py, 16 cameras @ 30 Hz, 2 detector processes, 128 px bfloat16: 1 thread
    each gave 26.5 keypoints3d/s, see bench/results/pipeline.md)."""
    if threads > 0 or processes <= 1:
        return threads
    return threads_each(processes, cores)


def frames_listener(node, summary):
    """Subscribe `node` to the player's played_frames: each [stamp ns, wall ns] is the
    frame's publish time for the latency (wall clock, mapped to this process's monotonic
    clock), [] the end of the replay (summary.replay_ended)."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Int64MultiArray

    from monet_ros.nodes.names import PLAYED_FRAMES

    def on_frame(msg):
        if len(msg.data) == 0:
            summary.replay_ended.set()
        elif len(msg.data) >= 2:
            stamp, wall_ns = int(msg.data[0]), int(msg.data[1])
            summary.on_image(PLAYED_FRAMES, stamp,
                             time.monotonic() - (time.time_ns() - wall_ns) / 1e9)

    # reliable and deep: one small message per frame, none (nor the end marker) lost
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE)
    return node.create_subscription(Int64MultiArray, PLAYED_FRAMES, on_frame, qos)


def pipeline_executor():
    """The executor of this process's nodes (fusion, the played_frames listener, the
    learner's services and timers): single-threaded, as every node executable
    (nodes.runner.run_node). A MultiThreadedExecutor costs more Python per callback here
    (its task futures and thread hand-offs, under one interpreter lock) and gave fusion a
    tail: bench/pipeline.py, 8 cameras @ 30 Hz, 128 px bfloat16, p95 418 ms against 135 ms
    single-threaded (three-process 133-232 ms in the same runs)."""
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor()


def run(args):
    from monet_ros.nodes import heap_for_large_buffers, passive_openmp, short_gil_switch
    from monet_ros.nodes.runner import (
        CallbackGuard,
        init_rclpy,
        say_goodbye,
        start_error,
        stop_executor,
        stop_requested,
        until_shutdown,
        use_large_data_profile,
    )
    from monet_ros.stop_signals import ignore_stop_signals
    passive_openmp()               # before torch loads (the fusion's and learner's threads)
    heap_for_large_buffers()       # heatmap buffers reused, not mapped per message
    short_gil_switch()             # fusion's and the learner's callbacks share a GIL
    score = None
    from monet_ros.commands.common import check_subject_only_options
    check_subject_only_options(args, args.subjects > 1, 'monet pipeline')
    from monet_ros.commands.common import options_named
    from monet_ros.fusion import FusionConfig
    with options_named(FusionConfig, {'--threshold-px': 'threshold_px',
                                      '--confidence-threshold': 'confidence_threshold'}):
        FusionConfig(threshold_px=args.threshold_px,   # the option named, before any node
                     confidence_threshold=args.confidence_threshold)
    from monet_ros.subjects.detection import SubjectsConfig
    with options_named(SubjectsConfig, {'--subjects': 'subjects',
                                        '--discovery-tiles': 'discovery_tiles'}):
        SubjectsConfig(subjects=args.subjects, **({} if args.discovery_tiles is None else
                                                  {'discovery_tiles': args.discovery_tiles}))
    if args.discovery_period_s is not None and not args.discovery_period_s >= 0:
        raise ConfigError('monet pipeline', '--discovery-period-s',
                          f'must be >= 0 s, got {args.discovery_period_s}')
    if args.subjects > 1:
        if not args.bag:
            raise ConfigError('monet pipeline', 'subjects', 'the demo is one subject; give '
                              '--bag and --model with --subjects')
        if getattr(args, 'learn', False):
            raise ConfigError('monet pipeline', 'subjects', '--learn trains one subject; '
                              'leave it out with --subjects')
        args.debug_image = False          # not drawn with several subjects
    if not args.bag:
        from monet_ros.commands.pipeline_demo import prepare_demo
        assets = prepare_demo(args.workdir)
        score = assets.scorer()                      # accuracy against the ground truth
        args.bag, args.rig = args.bag or assets.bag, args.rig or assets.rig
        args.model = args.model or assets.model
        args.skeleton = assets.skeleton
        args.loop = True                             # a 3 s recording: show it for a while
        args.lockstep = True       # every frame fused: crops follow the subject, scores hold
        args.duration = args.duration or 20.0
    if not args.model:
        raise ConfigError('monet pipeline', 'model', '--model is required with --bag')
    from monet_ros.models.device import check_device
    options = PipelineOptions(rate=args.rate, duration=args.duration,
                              start_delay=args.start_delay,
                              detector_processes=args.detector_processes)
    device = check_device('monet pipeline', args.device)
    from monet_ros.commands.common import precision_note
    # from the arguments alone; auto: the choice said once, when every start check passed
    precision, precision_line = precision_note('monet pipeline', args.precision, args.backend,
                                               device, args.model,
                                               calibration=args.calibration)
    use_large_data_profile()
    import rclpy
    from rclpy.node import Node

    from monet_ros.models import read_checkpoint
    from monet_ros.nodes.child import ChildNode
    from monet_ros.nodes.detector import DetectorConfig, camera_slots
    from monet_ros.nodes.fusion import FusionNode
    from monet_ros.nodes.names import PLAYED_FRAMES, node_namespace
    from monet_ros.nodes.player import PlayerConfig
    from monet_ros.nodes.runner import EXIT_BAD_START

    rig = args.rig or args.bag
    cameras = list(args.cameras or [])
    summary = Summary()
    ros_args = list(getattr(args, 'ros_args', None) or ['--ros-args'])
    init_rclpy(ros_args)
    nodes = []
    detectors, player, executor = [], None, None
    failed = False
    # Start errors (bad options, files, parameters) print one line and exit 2: every check
    # below runs before anything is said (the precision, the detector processes, the
    # fusion node's start-up line) or done (int8 quantised, child processes started), and
    # the nodes say goodbye (fusion's per-camera summary) only when the player started.
    try:
        with until_shutdown():
            try:
                fusion = FusionNode(overrides=dict(rig=str(rig), cameras=cameras,
                                                   rig_units=args.rig_units or '',
                                                   skeleton=args.skeleton, threads=0,
                                                   # lockstep: every frame, however late
                                                   **({'max_queue_ms': 0.0}
                                                      if args.lockstep else {}),
                                                   threshold_px=args.threshold_px,
                                                   confidence_threshold=args.confidence_threshold,
                                                   subjects=args.subjects,
                                                   link_mm=args.link_mm,
                                                   **({} if args.discovery_tiles is None else
                                                      {'discovery_tiles':
                                                       args.discovery_tiles})),
                                    announce=False)   # said once every check below passed
                nodes.append(fusion)
                # the detectors' and the player's parameters, checked here (one line, exit
                # 2) before their processes start; with lockstep the detector waits for the
                # previous frame's 3D itself
                detector_params = dict(rig=str(rig), cameras=tuple(cameras),
                                       rig_units=args.rig_units or '',
                                       model=str(args.model),
                                       transport=image_transport(args.bag, fusion.cameras),
                                       device=args.device, backend=args.backend,
                                       threads=args.threads, debug_image=args.debug_image,
                                       lockstep=args.lockstep, precision=args.precision,
                                       calibration='', subjects=args.subjects,
                                       # the fusion node's: their crop slots agree
                                       discovery_tiles=fusion.config.discovery_tiles,
                                       **({} if args.discovery_period_s is None else
                                          {'discovery_period_s': args.discovery_period_s}))
                slots = camera_slots(DetectorConfig(**detector_params))
                groups = detector_groups(slots, options.detector_processes, precision)
                check_skeleton(fusion, read_checkpoint(args.model)[0]['keypoints'],
                               args.skeleton, args.model)
                player_params = dict(
                    bag=str(args.bag), rate=0.0 if args.lockstep else options.rate,
                    loop=args.loop, wait_for_subscribers=1, wait_for_topics=(PLAYED_FRAMES,),
                    start_delay_s=options.start_delay, lockstep=args.lockstep,
                    announce_frames=True,
                    topics=tuple(t for s in slots for t in (s.image_topic, s.info_topic))
                    + tuple(tf_topics(args.bag)))
                PlayerConfig(**player_params)         # its errors name the parameter
                if args.learn:
                    nodes.append(learner_node(args, rig, summary))
                # every start check passed: what runs said, once
                print(f'monet pipeline: {precision_line}', flush=True)
                if args.precision == 'int8':  # quantised once here, before the detectors
                    from monet_ros.subjects.detection import SubjectsConfig
                    detector_params['calibration'], note = prepare_int8(
                        args.model, args.bag, args.calibration, backend=args.backend,
                        threads=args.threads, fusion=FusionConfig(
                            threshold_px=args.threshold_px,
                            confidence_threshold=args.confidence_threshold),
                        subjects=SubjectsConfig(
                            subjects=args.subjects, link_mm=args.link_mm,
                            discovery_tiles=fusion.config.discovery_tiles)
                        if args.subjects > 1 else None)
                    print(f'monet pipeline: {note}', file=sys.stderr, flush=True)
                line = groups_line(groups, options.detector_processes, precision)
                print(f'monet pipeline: {line}', flush=True)
                fusion.announce()
            except (ValueError, OSError) as error:
                start_error('monet pipeline', error)
                return 2
            fusion.listeners.append(summary.on_fused)
            if score is not None:
                fusion.listeners.append(score.on_fused)
            summary.names = list(fusion.skeleton.keypoints)
            summary.stale_frames = lambda: fusion.stale_frames
            if fusion.subjects is not None:
                summary.subject_counts = lambda: (
                    len(fusion.subject_stats),
                    sum(e['last_stamp_ns'] == fusion.last_stamp_ns
                        for e in fusion.subject_stats.values()),
                    fusion.subjects.tracker.births, fusion.subjects.tracker.deaths)
            listener = Node('pipeline', **node_namespace({}))
            frames_listener(listener, summary)
            nodes.append(listener)
            for i, group in enumerate(groups):
                # several detector processes: each its cameras, its own node name
                rename = ['-r', f'__node:=detector_{i}'] if len(groups) > 1 else []
                threads = detector_threads(args.threads, len(groups), usable_cores())
                detectors.append(ChildNode('detector', dict(detector_params, cameras=group,
                                                            threads=threads),
                                           ros_args + rename))
            executor = pipeline_executor()
            for node in nodes:
                node.callback_guard = CallbackGuard(node)  # a bad message costs only itself
                executor.add_node(node)
            started = ended = None
            while rclpy.ok() and not stop_requested():
                try:
                    executor.spin_once(timeout_sec=0.05)
                except Exception:  # noqa: BLE001 - a signal shut the context down mid-call
                    if rclpy.ok():
                        raise
                    break
                now = time.monotonic()
                codes = [(child.name, child.exit_code()) for child in detectors + [player]
                         if child is not None]
                code = next(((name, c) for name, c in codes if c is not None), None)
                if code is not None:       # 0: it got the terminal's Ctrl-C first
                    # EXIT_BAD_START: a node executable's start error, whose one line it
                    # printed itself (one line in all); any other code is said here
                    if code[1] not in (0, EXIT_BAD_START):
                        start_error('monet pipeline', f'the {code[0]} process exited with '
                                    f'code {code[1]}')
                    failed = code[1] != 0
                    break
                if player is None:
                    if not detector_connected(fusion):
                        continue           # the detector processes are still starting
                    # the first frame reaches connected detectors: the player waits for
                    # their subscriptions and this process's played_frames listener itself
                    player = ChildNode('player', player_params, ros_args)
                    started = now
                    next_line = started + 1.0
                if now >= next_line:
                    next_line += 1.0
                    if not args.quiet:
                        print(summary.line(window=1.0), flush=True)
                        if score is not None:
                            print(f'  {score.line()}', flush=True)
                if options.duration and now - started >= options.duration:
                    break
                if summary.replay_ended.is_set():
                    # the recording ended: let the frames in flight through, then stop
                    ended = ended or now
                    if now - max(ended, summary.last_fused or ended) > 2.0:
                        break
    finally:
        ignore_stop_signals()
        if player is not None:
            player.stop()                     # no frames into a closing pipeline
            say_goodbye(nodes)    # not before: nothing was received, nothing to sum up
        for child in detectors:
            child.stop()
        if executor is not None:
            stop_executor(executor)
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown()
    if failed:
        return 2
    if summary.replay_ended.is_set() and not summary.frames_published:
        # the whole recording went by without one frame (unreadable, truncated, no image
        # of the rig's cameras): an error, not an empty success
        print(f'monet pipeline: error: {args.bag}: the replay ended without playing a frame '
              "(the player's warnings above say why; `monet info` shows what it holds)",
              file=sys.stderr, flush=True)
        return 2
    if nodes and nodes[0].last_result is not None:
        print(keypoint_table(nodes[0]), flush=True)
    if score is not None:
        print(score.table(), flush=True)
    print(f'monet pipeline: {args.bag}: {summary.line()}', flush=True)   # the last line
    return 0


def keypoint_table(fusion):
    """The last fused frame as text: keypoint, x y z (m), views, reprojection error (px)."""
    result = fusion.last_result
    lines = [f'last frame (stamp {fusion.last_stamp_ns}), frame {fusion.frame_id!r}:',
             f'  {"keypoint":<16}{"x":>8}{"y":>8}{"z":>8}{"views":>7}{"error px":>10}']
    for name, X, views, error in zip(fusion.skeleton.keypoints, result.X, result.num_views,
                                     result.reprojection_error):
        lines.append(f'  {name:<16}{X[0]:8.3f}{X[1]:8.3f}{X[2]:8.3f}{int(views):7d}'
                     f'{error:10.2f}')
    return '\n'.join(lines)


if __name__ == '__main__':
    import argparse
    parser = argparse.ArgumentParser(description=HELP)
    add_arguments(parser)
    sys.exit(run(parser.parse_args()))
