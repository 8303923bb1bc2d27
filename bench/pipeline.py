"""Live pipeline figures: the three process layouts end to end, per-stage profile, fusion and
detector micro-benchmarks, side by side in one run.

    .venv/bin/python bench/pipeline.py                 # the full run (~6 min, quiet machine)
    .venv/bin/python bench/pipeline.py --quick         # every table, tiny sizes (~1-2 min)
    .venv/bin/python bench/pipeline.py --viewable --layouts in-process --extra  # their cost

End to end (`--cameras`, default 4 and 8 at `--rate` 30 Hz, plus `--extra` 4@60): V
camera streams (640x480 rgb8 + camera_info, stamped with the wall clock) go through a real
detector node (all cameras batched, small net, CPU) and a real fusion node, timed from each
image stamp to the arrival of its /monet/keypoints3d (and of each heatmap: the detector's
share of that latency), in three layouts:
  three-process: the camera publisher (this bench, as the player or a camera driver would),
      the detector and the fusion each in their own process, over DDS with the Fast DDS
      shared-memory profile (config/fastdds_profile.xml) given to every publisher;
  pipeline: as `monet pipeline`: the fusion node in one process and executor, the
      detector and the camera publisher (as its player) each in a child process
      (monet_ros.nodes.child);
  in-process: publisher, detector and fusion nodes in ONE process and executor (what
      `monet pipeline` was: the detector's GIL-free calls wait behind the other nodes'
      Python, 3-4x slower on a quiet 2-core machine).
Each run also prints the per-stage profile the nodes report in /diagnostics (mean ms per
batch / frame: detector convert, crop, forward, publish; fusion receive per view, decode,
undistort, triangulate, errors, publish).
Micro-benchmarks (this process, median of --runs): fuse_heatmaps per frame at 4/8/35 views
against plain DLT of the same peaks (geometry.triangulate) with the stage split, the
undistortion's error against cv2.undistortPoints, and Detector.predict images/s with the
torch backend in float32 (channels-last) and bfloat16 (where the CPU has it natively) and
with ONNX Runtime, beside the baseline of the same crops through the network in contiguous
NCHW float32; the receive table (--receive RUNS, two processes):
a subscriber's CPU per 640x480 image taken as an rclpy message with glibc's default
allocator settings (baseline), with large buffers from the heap (as every node), or
serialized and decoded in place. --viewable runs every end-to-end case twice, with the
viewable outputs off and on (the detector's debug_image at its default rate with a subscriber
to every camera's, the fusion node's /tf_static and camera markers), to show what they cost:
throughput and the nodes' CPU time per keypoints3d (/proc/PID/stat of the detector and fusion
processes; in-process: this process, publisher included; pipeline: the fusion process and
the detector children, not the publisher).
--repeat N runs each case N times (off/on interleaved) and shows medians: single 10 s runs
differ by several percent. --second-job N runs N CPU-bound processes beside the end-to-end
runs (the loaded-machine figures); --input-size the small net at another input side;
--precision float32 bfloat16 int8 runs every end-to-end case with each detector precision
(`monet pipeline --backend auto`'s backend: --backend), side by side; int8 as `monet pipeline
--precision int8 --backend onnxruntime` (commands.pipeline.prepare_int8): the network
quantised once before the measured runs, calibrated on the tracked crops of a recording of
the bench's own camera frames and rig, and cached beside the checkpoint; every int8 run's
detectors then get that quant (as a user's second run finds it cached), and the output
says which quant and crop mode (the calibration line);
--detector-processes 1 2 each three-process and pipeline case with one detector process
batching every camera and with two, each batching half (`monet pipeline
--detector-processes`; 0: its default, two from 16 cameras on, else one), e.g.
`--cameras 16 --extra --layouts three-process pipeline --precision bfloat16
--detector-processes 1 2` for 16 cameras on 2 cores.
Prints tables and the load average; never asserts.
"""
import argparse
import contextlib
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / 'test'))

from helpers.domain import held_domain_id  # noqa: E402

from monet_ros.commands.pipeline import detector_groups  # noqa: E402
from monet_ros.cores import usable_cores  # noqa: E402
from monet_ros.fusion import FusionConfig, fuse_heatmaps  # noqa: E402
from monet_ros.geometry import save_rig, triangulate, undistort_views  # noqa: E402
from monet_ros.models import Detector, build_model, save_checkpoint  # noqa: E402
from monet_ros.skeleton import load_skeleton  # noqa: E402
from monet_ros.synth.rig import RigConfig, make_rig  # noqa: E402
from monet_ros.timing import StageTimer  # noqa: E402

WIDTH, HEIGHT = 640, 480
DETECTOR_STAGES = ('convert', 'crop', 'forward', 'publish')
FUSION_STAGES = ('receive', 'decode', 'undistort', 'triangulate', 'errors', 'publish')


def median_time(fn, runs):
    fn()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def keypoint_names():
    return list(load_skeleton('human14').keypoints)


# ----------------------------------------------------------------------------- micro
def synthetic_heatmaps(rig, size=(64, 64)):
    """Heatmaps with one clear Gaussian peak per keypoint (a trained net's output shape) of
    14 points seen by every camera, their virtual cameras and the true peaks (source px)."""
    X = np.random.default_rng(1).uniform([-0.3, -0.3, 0.5], [0.3, 0.3, 1.6], (14, 3))
    h, w = size
    heat_cams = [cam.crop((80, 0, 560, 480), (w, h)) for cam in rig]
    vv, uu = np.mgrid[0:h, 0:w]
    maps = []
    for cam in heat_cams:
        uv = cam.project(X)
        d2 = (uu[None] - uv[:, 0, None, None]) ** 2 + (vv[None] - uv[:, 1, None, None]) ** 2
        maps.append(np.exp(-d2 / 8.0).astype(np.float32))
    peaks = np.stack([cam.project(X) for cam in rig])
    return np.stack(maps), np.stack([c.K for c in heat_cams]), peaks


def fusion_micro(views, runs):
    import torch
    torch.set_num_threads(1)  # as the fusion node (its `threads` parameter, default 1)
    rig = make_rig(RigConfig(num_cameras=views))
    maps, K_heat, peaks = synthetic_heatmaps(rig)
    config = FusionConfig()
    maps = list(maps)  # one (C, h, w) array per view, as the fusion node holds them
    fusion = median_time(lambda: fuse_heatmaps(maps, K_heat, rig, config), runs)
    plain = median_time(lambda: triangulate(peaks, rig), runs)
    timer = StageTimer()
    for _ in range(runs):
        fuse_heatmaps(maps, K_heat, rig, config, timer)
    stages = {k: 1e3 * timer.totals[k] / timer.counts[k] for k in timer.totals}
    # undistortion against OpenCV over every 8th pixel of each image
    import cv2
    u, v = np.meshgrid(np.arange(0, WIDTH, 8.0), np.arange(0, HEIGHT, 8.0))
    grid = np.stack([u.ravel(), v.ravel()], axis=1)
    ours = undistort_views(rig, np.repeat(grid[None], views, axis=0))
    converged = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-16)
    err_conv = err_default = 0.0
    for i, cam in enumerate(rig):
        ref = cv2.undistortPoints(grid[:, None], cam.K, cam.dist, P=cam.K,
                                  criteria=converged)[:, 0]
        default = cv2.undistortPoints(grid[:, None], cam.K, cam.dist, P=cam.K)[:, 0]
        err_conv = max(err_conv, float(np.abs(ours[i] - ref).max()))
        err_default = max(err_default, float(np.abs(ours[i] - default).max()))
    undist = median_time(lambda: undistort_views(rig, peaks), runs)
    return dict(views=views, fusion=fusion, plain=plain, stages=stages, undist=undist,
                err_conv=err_conv, err_default=err_default,
                distorted=any(c.has_distortion for c in rig))


def bench_model(workdir, architecture='small', input_size=None):
    """A randomly initialised checkpoint (weights do not change the speed) of
    `architecture` at its default input or a square `input_size` (px); cached in workdir."""
    import torch
    path = workdir / f'{architecture}{input_size or ""}.pt'
    if not path.exists():
        torch.manual_seed(0)
        options = {} if input_size is None else {'input_size': [input_size, input_size]}
        save_checkpoint(path, build_model(architecture, 14, **options),
                        {'keypoints': keypoint_names()})
    return path


def detector_micro(views, runs, threads, architecture, workdir, input_size=None):
    """images/s of Detector.predict (V 640x480 views, one batch) per backend and precision,
    and the baseline: the same crops through the fused network in contiguous NCHW float32
    (the layout before channels-last)."""
    import torch

    from monet_ros.models.crop import crop_images
    from monet_ros.models.detector import bfloat16_native, images_to_tensor
    torch.set_num_threads(threads)
    rig = make_rig(RigConfig(num_cameras=views))
    path = bench_model(workdir, architecture, input_size)
    images = np.random.default_rng(0).integers(0, 255, (views, HEIGHT, WIDTH, 3), np.uint8)
    boxes = np.array([[160, 60, 480, 420]] * views, float)
    out = {}
    detector = Detector.from_checkpoint(path, device='cpu')
    h, w = detector.input_size
    nchw = detector.model.to(memory_format=torch.contiguous_format)

    def baseline():
        crops = crop_images(images, detector.boxes_for(rig, boxes), (w, h))
        with torch.inference_mode():
            return nchw(images_to_tensor(crops))[-1].numpy()

    out['baseline'] = views / median_time(baseline, runs)
    for key, backend, precision in (('float32', 'torch', 'float32'),
                                    ('bfloat16', 'torch', 'bfloat16'),
                                    ('onnxruntime', 'onnxruntime', 'float32')):
        if precision == 'bfloat16' and not bfloat16_native('cpu'):
            out[key] = 'no native bfloat16'
            continue
        try:
            detector = Detector.from_checkpoint(path, device='cpu', backend=backend,
                                                threads=threads, precision=precision)
        except ValueError as error:  # e.g. onnxruntime not installed
            out[key] = str(error)
            continue
        seconds = median_time(lambda d=detector: d.predict(images, rig, boxes), runs)
        out[key] = views / seconds
    return out


# ----------------------------------------------------------------------------- live
@contextlib.contextmanager
def run_env(workdir):
    """`with run_env(workdir) as env:` the environment of one run's processes, on a
    ROS_DOMAIN_ID held on this machine for the block (test/helpers/domain.py, as the tests
    claim theirs: a test suite beside the bench never meets its nodes)."""
    env = dict(os.environ)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    with held_domain_id() as domain:
        env.update(ROS_DOMAIN_ID=str(domain), ROS_LOG_DIR=str(workdir / 'log'),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONPATH=str(REPO),
                   FASTRTPS_DEFAULT_PROFILES_FILE=str(REPO / 'config' / 'fastdds_profile.xml'),
                   PYTHONUNBUFFERED='1')
        yield env


def live(layout, views, rate, seconds, warmup, threads, backend, workdir, viewable=False,
         input_size=None, precision='float32', detector_processes=1, batch_wait_ms=None,
         calibration=''):
    """One end-to-end run in a fresh process (clean DDS state); returns its figures.
    batch_wait_ms: the detectors' parameter (None: the node's default); calibration: theirs
    (precision int8: the quant prepare_int8 cached)."""
    rig = make_rig(RigConfig(num_cameras=views))
    rig_path = workdir / f'rig{views}.yaml'
    save_rig(rig_path, rig)
    model_path = bench_model(workdir, 'small', input_size)
    spec = dict(layout=layout, views=views, rate=rate, seconds=seconds, warmup=warmup,
                threads=threads, backend=backend, rig=str(rig_path), model=str(model_path),
                workdir=str(workdir), viewable=viewable, precision=precision,
                detector_processes=detector_processes, batch_wait_ms=batch_wait_ms,
                calibration=calibration)
    with run_env(workdir) as env:
        proc = subprocess.run([sys.executable, __file__, '--worker', json.dumps(spec)],
                              env=env, capture_output=True, text=True,
                              timeout=300 + seconds + warmup)
    for line in reversed(proc.stdout.splitlines()):
        if line.startswith('{'):
            return json.loads(line)
    return dict(error=(proc.stderr or proc.stdout).strip().splitlines()[-1:] or
                [f'exit {proc.returncode}'])


# ----------------------------------------------------------------------------- receive
def receive_micro(views, rate, seconds, repeat, workdir):
    """CPU ms a subscriber spends per received 640x480 rgb8 image: taken as an rclpy message
    with glibc's default allocator settings (the baseline: every buffer over 128 KB mapped
    and unmapped per message), the same with large buffers from the heap
    (monet_ros.nodes.heap_for_large_buffers, what every node does: the detector's way), and
    serialized and decoded in place (monet_ros.io.fast_cdr, the bag reader's decoder; no
    faster than the message once the heap serves the buffers, so the nodes take messages).
    The pixels
    reach a numpy array every way (image_for_crop). A publisher process sends `views`
    streams at `rate`; the subscriber process times itself.
    -> {(mode, heap): the `repeat` runs' values}."""
    out = {('message', False): [], ('message', True): [], ('serialized', True): []}
    for _ in range(repeat):
        for mode, heap in out:
            spec = dict(views=views, rate=rate, seconds=seconds, mode=mode, heap=heap)
            with run_env(workdir) as env:
                sub = subprocess.Popen([sys.executable, __file__, '--receive-worker',
                                        json.dumps(dict(spec, role='subscriber'))], env=env,
                                       stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                       text=True)
                subprocess.run([sys.executable, __file__, '--receive-worker',
                                json.dumps(dict(spec, role='publisher'))], env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               timeout=120 + seconds)
                lines = [line for line in sub.communicate(timeout=60)[0].splitlines()
                         if line.startswith('{')]
            result = json.loads(lines[-1]) if lines else {}
            out[mode, heap].append(result.get('cpu_ms', float('nan')))
    return out


def receive_worker(spec):
    """One side of receive_micro (its own process)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from monet_ros.io import numpy_to_image_msg
    from monet_ros.io.fast_cdr import decode_image
    from monet_ros.io.images import image_for_crop
    from monet_ros.nodes import heap_for_large_buffers
    from monet_ros.nodes.qos import IMAGE_IN, IMAGE_OUT

    if spec.get('heap', True):
        heap_for_large_buffers()
    rclpy.init()
    node = Node(spec['role'])
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    topics = [f'/bench_receive/cam{v}' for v in range(spec['views'])]
    warmup = 2.0
    if spec['role'] == 'publisher':
        pubs = [node.create_publisher(Image, topic, IMAGE_OUT) for topic in topics]
        pixels = np.random.default_rng(0).integers(0, 255, (HEIGHT, WIDTH, 3), np.uint8)
        msg = numpy_to_image_msg(pixels, 0, 'cam')
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not all(p.get_subscription_count() for p in pubs):
            executor.spin_once(timeout_sec=0.05)
        start, k = time.monotonic(), 0
        while time.monotonic() - start < warmup + spec['seconds'] + 1.0:
            for pub in pubs:
                pub.publish(msg)
            k += 1
            time.sleep(max(0.0, start + k / spec['rate'] - time.monotonic()))
    else:
        raw = spec['mode'] == 'serialized'
        count, marks = [0], {}

        def on_image(data):
            image, _ = image_for_crop(decode_image(data) if raw else data)
            count[0] += image.shape[0] > 0
            if count[0] == 1:
                marks['first'] = time.monotonic()
            elif 'from' not in marks and time.monotonic() - marks['first'] >= warmup:
                marks['from'] = (count[0], time.process_time())

        for topic in topics:
            node.create_subscription(Image, topic, on_image, IMAGE_IN, raw=raw)
        deadline = time.monotonic() + 60 + spec['seconds']
        while time.monotonic() < deadline and not (
                'first' in marks and time.monotonic() - marks['first'] > warmup
                + spec['seconds']):
            executor.spin_once(timeout_sec=0.1)
        n0, c0 = marks.get('from', (count[0], time.process_time()))
        received = count[0] - n0
        print(json.dumps(dict(received=received, cpu_ms=1e3 * (time.process_time() - c0) /
                              received if received else float('nan'))), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


# A second job on the machine: single-threaded dense arithmetic (as another user's training or
# encoding would be) in N processes, started before and stopped after the end-to-end runs.
_SECOND_JOB = ('import numpy as np\n'
               'a = np.random.default_rng(0).random((256, 256))\n'
               'while True:\n'
               '    a = np.tanh(a @ a)\n')


@contextlib.contextmanager
def second_job(processes):
    """Run `processes` CPU-bound processes (one thread each) for the body's duration."""
    env = dict(os.environ, OMP_NUM_THREADS='1', OPENBLAS_NUM_THREADS='1', MKL_NUM_THREADS='1')
    procs = [subprocess.Popen([sys.executable, '-c', _SECOND_JOB], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for _ in range(processes)]
    try:
        yield
    finally:
        for proc in procs:
            proc.kill()
        for proc in procs:
            proc.wait()


def feed_frames(views):
    """The frames the camera publisher cycles through: 4 of (views, 480, 640, 3) uint8 rgb8
    noise (fixed seed)."""
    rng = np.random.default_rng(2)
    return [rng.integers(0, 255, (views, HEIGHT, WIDTH, 3), np.uint8) for _ in range(4)]


def backend_for(precision, backend=None):
    """The detector backend of the end-to-end runs in `precision`: `backend` when given
    (--backend), else what `monet pipeline`'s default --backend auto runs for it on this
    machine's CPU (models.detector.resolve_backend: onnxruntime for float32 and int8,
    torch for bfloat16), named in the tables."""
    from monet_ros.models.detector import resolve_backend
    return backend or resolve_backend('auto', precision, 'cpu')[0]


def write_feed_recording(path, rig, instants):
    """A rosbag2 MCAP folder `path` of what the camera publisher sends on `rig`: /tf_static,
    then `instants` instants (30 Hz stamps) of every camera's image (the feed_frames in
    turn) and camera_info: the recording int8 calibrates on, as `monet pipeline
    --precision int8` calibrates on the recording it plays."""
    from monet_ros.io import BagWriter

    start, period = 1_767_225_600_000_000_000, 33_333_333
    frames = feed_frames(len(rig))
    with BagWriter(path) as writer:
        writer.write_tf_static(start, rig)
        for i in range(instants):
            stamp = start + i * period
            for cam, image in zip(rig, frames[i % len(frames)]):
                writer.write_image(cam.topic, stamp, image, f'{cam.name}_optical',
                                   encoding='rgb8')
                writer.write_camera_info(f'/{cam.name}/camera_info', stamp, cam,
                                         f'{cam.name}_optical')
    return path


def prepare_int8_runs(workdir, views, threads=0, input_size=None):
    """precision int8's one preparation before the measured runs, outside them: a
    recording of the camera feed on the rig of `views` cameras (write_feed_recording,
    enough instants for models.quantize's calibration set) and `monet pipeline`'s own
    preparation on it (commands.pipeline.prepare_int8: calibrated on its tracked crops and
    cached beside the bench's checkpoint, or the cached quant used). Returns (the
    detectors' calibration parameter: the cached quant, the one line saying which quant
    and crops, seconds it took). ValueError (one line) when int8 cannot run."""
    from monet_ros.commands.pipeline import prepare_int8
    from monet_ros.models.quantize import CALIBRATION_IMAGES

    model = bench_model(workdir, 'small', input_size)
    recording = workdir / f'int8_calibration_{views}'
    if not recording.exists():
        write_feed_recording(recording, make_rig(RigConfig(num_cameras=views)),
                             -(-CALIBRATION_IMAGES // views))
    start = time.perf_counter()
    calibration, note = prepare_int8(model, recording, threads=threads)
    return calibration, note, time.perf_counter() - start


class Feeder:
    """The camera side and the stopwatch: publishes V image streams at `rate` and times
    every /monet/keypoints3d from its image stamp; keeps the nodes' latest /diagnostics."""

    def __init__(self, node, rig, viewable=False):
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import CameraInfo, Image, PointCloud2

        from monet_ros.io import numpy_to_image_msg
        from monet_ros.io.fast_cdr import decode_header
        from monet_ros.io.fields import stamp_to_ns
        from monet_ros.nodes.qos import IMAGE_OUT, STREAM_IN

        self.node, self.rig = node, rig
        # ns from image stamp to this process: each keypoints3d, each heatmap (the
        # detector's share of the latency)
        self.latencies, self.heat_latencies, self.diagnostics = [], [], {}
        self.callback_errors = {}    # source -> 'count x last error'
        self.detector_nodes = {}     # first camera -> that detector node's batch counters
        self.fusion_counts = []      # (arrival monotonic s, frames, partial_frames) of fusion
        # serialized subscriptions (raw=True): this bench shares the CPUs with the nodes it
        # times, so it neither converts images to Python messages nor decodes more than the
        # stamp it needs
        node.create_subscription(
            PointCloud2, '/monet/keypoints3d',
            lambda m: self.latencies.append(time.time_ns() - stamp_to_ns(decode_header(m).stamp)),
            STREAM_IN, raw=True)
        self.debug_count = [0]
        for cam in rig:
            if viewable:      # a debug image is drawn only while someone subscribes
                node.create_subscription(Image, f'/monet/{cam.name}/debug_image',
                                         lambda m: self.debug_count.__setitem__(
                                             0, self.debug_count[0] + 1), STREAM_IN, raw=True)
            node.create_subscription(
                Image, f'/monet/{cam.name}/heatmaps',
                lambda m: self.heat_latencies.append(
                    time.time_ns() - stamp_to_ns(decode_header(m).stamp)), STREAM_IN, raw=True)
        node.create_subscription(DiagnosticArray, '/diagnostics', self.on_diagnostics,
                                 STREAM_IN)
        self.pubs = [(node.create_publisher(Image, cam.topic, IMAGE_OUT),
                      node.create_publisher(CameraInfo, f'/{cam.name}/camera_info',
                                            IMAGE_OUT)) for cam in rig]
        self.messages = [[numpy_to_image_msg(f[v], 0, cam.name) for v, cam in enumerate(rig)]
                         for f in feed_frames(len(rig))]

    def on_diagnostics(self, msg):
        for status in msg.status:
            if ': callback errors: ' in status.name:    # a node's CallbackGuard counts
                values = {kv.key: kv.value for kv in status.values}
                self.callback_errors[status.name.split(': callback errors: ')[-1]] = \
                    f'{values.get("errors")} x {values.get("last_error")}'
            elif status.name.startswith('monet detector') or status.name == 'monet fusion':
                kind = 'detector' if status.name.startswith('monet detector') else 'fusion'
                self.diagnostics[kind] = {kv.key: kv.value for kv in status.values}
                if kind == 'fusion':
                    values = self.diagnostics[kind]
                    self.fusion_counts.append((time.monotonic(), int(values['frames']),
                                               int(values['partial_frames'])))
        cams = [{kv.key: kv.value for kv in status.values} for status in msg.status
                if status.name.startswith('monet detector: ')]
        if cams:    # one detector node's message: its batch counters, its cameras' drops
            self.detector_nodes[msg.status[0].hardware_id] = dict(
                {k: int(cams[0].get(k, 0)) for k in ('batches', 'incomplete_batches')},
                dropped=sum(int(c.get('dropped_stale', 0)) for c in cams))

    def run(self, spin_once, rate, seconds, warmup, cpu_seconds=time.process_time):
        """Publish for warmup + seconds; figures over the measured window. cpu_seconds():
        CPU time (user + system, s) of the processes that run the nodes."""
        from monet_ros.io import camera_info_from_camera

        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not all(
                p[0].get_subscription_count() for p in self.pubs):
            spin_once(0.1)
        published = 0
        start = next_tick = time.monotonic()
        measured_from = None
        while time.monotonic() - start < warmup + seconds:
            now = time.monotonic()
            if now >= next_tick:
                next_tick += 1.0 / rate
                stamp = time.time_ns()
                for v, cam in enumerate(self.rig):
                    image = self.messages[published % len(self.messages)][v]
                    image.header.stamp.sec, image.header.stamp.nanosec = divmod(stamp, 10**9)
                    self.pubs[v][1].publish(camera_info_from_camera(cam, stamp, cam.name))
                    self.pubs[v][0].publish(image)
                published += 1
                if measured_from is None and now - start >= warmup:
                    measured_from = (now, len(self.latencies), len(self.heat_latencies),
                                     published,
                                     cpu_seconds())
            spin_once(max(0.0, min(0.005, next_tick - time.monotonic())))
        end, cpu_end, fused_end = time.monotonic(), cpu_seconds(), len(self.latencies)
        settle = time.monotonic() + 1.5  # the frames in flight, and one more /diagnostics
        while time.monotonic() < settle:
            spin_once(0.05)
        t0, n0, h0, p0, c0 = measured_from
        window = end - t0
        lat = np.array(self.latencies[n0:], float) / 1e6
        heat_lat = np.array(self.heat_latencies[h0:], float) / 1e6
        return dict(published=(published - p0) / window,
                    cpu_ms=1e3 * (cpu_end - c0) / max(1, fused_end - n0),
                    fused=(len(self.latencies) - n0) / window,
                    heat=(len(self.heat_latencies) - h0) / window,
                    complete=complete_rate(self.fusion_counts, t0, end),
                    heat_median=float(np.median(heat_lat)) if heat_lat.size else float('nan'),
                    heat_p95=(float(np.percentile(heat_lat, 95)) if heat_lat.size
                              else float('nan')),
                    median=float(np.median(lat)) if lat.size else float('nan'),
                    p95=float(np.percentile(lat, 95)) if lat.size else float('nan'),
                    diagnostics=self.diagnostics, callback_errors=self.callback_errors,
                    detector_batches={k: sum(n[k] for n in self.detector_nodes.values())
                                      for k in ('batches', 'incomplete_batches', 'dropped')})


def complete_rate(counts, start, end):
    """Frames fused with every camera per second between start and end (monotonic s), from
    the fusion node's cumulative counters: counts is [(arrival s, frames, partial_frames)]
    of its /diagnostics; the rate over the first and last arrivals inside the window
    (exact for that interval), NaN with fewer than two."""
    inside = [c for c in counts if start <= c[0] <= end]
    if len(inside) < 2 or inside[-1][0] <= inside[0][0]:
        return float('nan')
    (t_a, f_a, p_a), (t_b, f_b, p_b) = inside[0], inside[-1]
    return ((f_b - p_b) - (f_a - p_a)) / (t_b - t_a)


def process_cpu_seconds(pid):
    """User + system CPU seconds of process `pid` (all its threads), from /proc/PID/stat
    (proc(5): fields 14 utime and 15 stime, in clock ticks); 0.0 once it has gone."""
    try:
        fields = Path(f'/proc/{pid}/stat').read_text().rpartition(')')[2].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def worker(spec):
    """Body of one live run (in its own process): see live(). Layout 'feed': only the
    camera publisher and stopwatch (the player of the pipeline layout, in a child process),
    node CPU from the processes spec['cpu_pids']."""
    import rclpy
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.node import Node

    from monet_ros.commands.pipeline import detector_threads, pipeline_executor
    from monet_ros.geometry import load_rig
    from monet_ros.nodes import heap_for_large_buffers, short_gil_switch
    from monet_ros.nodes.runner import stop_executor

    rig = load_rig(spec['rig'])
    # 0 processes: monet pipeline's default (two from TWO_DETECTORS_FROM cameras on in
    # SPLIT_PRECISIONS)
    groups = detector_groups(rig, spec.get('detector_processes', 1), spec['precision'])
    detector_params = dict(rig=spec['rig'], model=spec['model'], device='cpu',
                           threads=detector_threads(spec['threads'] or 0, len(groups),
                                                    usable_cores()),
                           backend=spec['backend'],
                           precision=spec['precision'], debug_image=spec['viewable'],
                           calibration=spec.get('calibration', ''))
    if spec.get('batch_wait_ms') is not None:
        detector_params['batch_wait_ms'] = float(spec['batch_wait_ms'])
    fusion_params = dict(rig=spec['rig'], publish_tf=spec['viewable'],
                         camera_markers=spec['viewable'])
    procs, nodes, children, feeder_proc = [], [], [], None
    if spec['layout'] == 'pipeline':
        from monet_ros.nodes.child import ChildNode
        children = [ChildNode('detector', dict(detector_params, cameras=group),
                              ['-r', f'__node:=detector_{i}'] if len(groups) > 1 else [])
                    for i, group in enumerate(groups)]
    if spec['layout'] == 'three-process':
        import yaml
        params = Path(spec['workdir']) / f'params_{os.getpid()}.yaml'
        names = [f'detector_{i}' if len(groups) > 1 else 'detector'
                 for i in range(len(groups))]
        params.write_text(yaml.safe_dump(
            {'/**/fusion': {'ros__parameters': fusion_params},
             **{f'/**/{name}': {'ros__parameters': dict(detector_params, cameras=group)}
                for name, group in zip(names, groups)}}))
        procs = [subprocess.Popen([sys.executable, '-m', f'monet_ros.nodes.{module}',
                                   '--ros-args', '--params-file', str(params),
                                   *(['-r', f'__node:={name}'] if name else [])],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                 for module, name in [('fusion', None)] + [
                     ('detector', n if len(groups) > 1 else None) for n in names]]
    heap_for_large_buffers()      # as `monet pipeline`, the player and every node do
    if spec['layout'] in ('in-process', 'pipeline'):
        short_gil_switch()        # as `monet pipeline` (several busy threads, one GIL)
    rclpy.init()
    executor = None
    try:
        if spec['layout'] in ('in-process', 'pipeline'):
            from monet_ros.nodes.detector import DetectorNode
            from monet_ros.nodes.fusion import FusionNode
            nodes = [FusionNode(overrides=fusion_params)]
            if spec['layout'] == 'in-process':
                nodes.append(DetectorNode(overrides=detector_params))
            # the pipeline layout: `monet pipeline`'s own executor
            executor = (pipeline_executor() if spec['layout'] == 'pipeline'
                        else MultiThreadedExecutor(num_threads=4))
        else:
            executor = SingleThreadedExecutor()
        for node in nodes:
            executor.add_node(node)
        if spec['layout'] == 'pipeline':
            # as `monet pipeline`: the player (here the camera publisher and stopwatch) in
            # its own process; this one runs fusion, and is timed with the detectors
            pids = [os.getpid()] + [c.process.pid for c in children]
            feeder_proc = subprocess.Popen(
                [sys.executable, __file__, '--worker',
                 json.dumps(dict(spec, layout='feed', cpu_pids=pids))],
                stdout=subprocess.PIPE, text=True)
            while feeder_proc.poll() is None:
                executor.spin_once(timeout_sec=0.05)
            result = dict(error=[f'feed exit {feeder_proc.returncode}'])
            for line in reversed(feeder_proc.stdout.read().splitlines()):
                if line.startswith('{'):
                    result = json.loads(line)
                    break
        else:
            bench = Node('bench')
            nodes.append(bench)
            executor.add_node(bench)
            feeder = Feeder(bench, rig, spec['viewable'])
            if procs:     # three-process: the node processes only (not this publisher)
                def cpu():
                    return sum(process_cpu_seconds(p.pid) for p in procs)
            elif spec['layout'] == 'feed':     # the pipeline's processes
                def cpu():
                    return sum(process_cpu_seconds(pid) for pid in spec['cpu_pids'])
            else:         # in-process: this whole process (publisher included)
                cpu = time.process_time
            result = feeder.run(lambda t: executor.spin_once(timeout_sec=t), spec['rate'],
                                spec['seconds'], spec['warmup'], cpu)
    finally:
        if feeder_proc is not None and feeder_proc.poll() is None:
            feeder_proc.kill()
        if executor is not None:
            stop_executor(executor)
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown()
        for child in children:
            child.stop()
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.wait(timeout=30)
    print(json.dumps(result), flush=True)
    return 0


def run_cases(args, runs, workdir, costs):
    """Every end-to-end case (rows printed as they finish); viewable off/on pairs appended to
    costs."""
    for views, rate in runs:
        for layout in args.layouts:
            for precision, processes in [(p, n) for p in args.precision
                                         for n in args.detector_processes]:
                if layout == 'in-process' and (processes > 1 or (
                        processes == 0 and 1 in args.detector_processes)):
                    continue          # one process by definition
                if layout == 'in-process':
                    processes = 1
                backend = backend_for(precision, args.backend)
                label = layout if len(args.precision) == 1 else f'{layout}, {precision}'
                if len(args.detector_processes) > 1 or 0 in args.detector_processes:
                    try:
                        actual = len(detector_groups(make_rig(RigConfig(num_cameras=views)),
                                                     processes, precision))
                    except ValueError:     # more processes than cameras: the row says so
                        actual = processes
                    label += (f', {actual} detector process{"es" * (actual > 1)}'
                              + (' (auto)' if processes == 0 else ''))
                settings = (False, True) if args.viewable else (False,)
                results = {viewable: [] for viewable in settings}
                for _ in range(args.repeat):
                    for viewable in settings:
                        results[viewable].append(live(
                            layout, views, rate, args.seconds, args.warmup, args.threads,
                            backend, workdir, viewable, args.input_size, precision, processes,
                            args.batch_wait_ms,
                            args.int8_calibration if precision == 'int8' else ''))
                combined = {viewable: median_result(rs) for viewable, rs in results.items()}
                ran = {(r.get('diagnostics', {}).get('detector', {}).get('backend', backend),
                        r.get('diagnostics', {}).get('detector', {}).get('precision',
                                                                          precision))
                       for r in combined.values()} - {(backend, precision)}
                if ran:           # what the detector nodes report in /diagnostics
                    label += ' (detector ran ' + ', '.join(' '.join(x) for x in ran) + ')'
                for viewable, r in combined.items():
                    print_live_row(views, rate, label, viewable, r)
                if args.viewable and all('error' not in r for r in combined.values()):
                    costs.append((views, rate, label, combined[False], combined[True]))


def median_result(results):
    """One figure per field: the median over repeated runs of a case (the last run's
    stage profile); the first error if every run failed."""
    good = [r for r in results if 'error' not in r]
    if not good:
        return results[0]
    keys = ('published', 'fused', 'complete', 'heat', 'median', 'p95', 'heat_median', 'heat_p95',
            'cpu_ms')
    out = {k: float(np.median([r[k] for r in good])) for k in keys}
    out['diagnostics'] = good[-1]['diagnostics']
    out['detector_batches'] = good[-1].get('detector_batches')
    out['callback_errors'] = {k: v for r in good for k, v in r['callback_errors'].items()}
    out['runs'] = len(good)
    out['fused_runs'] = [r['fused'] for r in good]
    return out


def print_live_row(views, rate, layout, viewable, r):
    load = os.getloadavg()[0]
    shown = 'on' if viewable else 'off'
    if 'error' in r:
        print(f'| {views} @ {rate:.0f} | {layout} | {shown} | failed: {r["error"]} '
              f'{"|" * 13} {load:.1f} |', flush=True)    # the 17 columns
        return
    d = r['diagnostics']
    print(f'| {views} @ {rate:.0f} | {layout} | {shown} | {r["published"]:.1f} | '
          f'{r["fused"]:.1f} | {r["complete"]:.1f} | {r["heat"]:.1f} | '
          f'{r["median"]:.0f} | {r["p95"]:.0f} | '
          f'{r["heat_median"]:.0f} / {r["heat_p95"]:.0f} | '
          f'{r["cpu_ms"]:.1f} | {frame_counts(d)} | {batch_counts(r)} | '
          f'{stage_text(d, "detector", DETECTOR_STAGES)} | '
          f'{stage_text(d, "fusion", FUSION_STAGES)} | '
          f'{"; ".join(f"{k}: {v}" for k, v in r["callback_errors"].items()) or "none"} | '
          f'{load:.1f} |', flush=True)


def frame_counts(diagnostics):
    """'fused / partial (fewer views) / stale (skipped: fusion fell behind)' frames of the
    fusion node's last /diagnostics (since it started, warm-up included)."""
    values = diagnostics.get('fusion', {})
    return ' / '.join(values.get(k, '?') for k in ('frames', 'partial_frames', 'stale_frames'))


def batch_counts(result):
    """'batches (incomplete) / frames dropped' of every detector node since it started
    (warm-up included), from their last /diagnostics."""
    b = result.get('detector_batches')
    if not b:
        return '?'
    return f'{b["batches"]} ({b["incomplete_batches"]}) / {b["dropped"]}'


def stage_text(diagnostics, kind, stages):
    values = diagnostics.get(kind, {})
    parts = [f'{s} {float(values[f"{s}_ms_mean"]):.2f}' for s in stages
             if f'{s}_ms_mean' in values]
    return ', '.join(parts) or 'n/a'


# ----------------------------------------------------------------------------- main
def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--cameras', type=int, nargs='+', default=[4, 8],
                        help='camera counts of the end-to-end runs at --rate')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate (Hz)')
    parser.add_argument('--extra', nargs='*', default=['4@60'],
                        help='more end-to-end runs as CAMERAS@HZ (default 4@60)')
    parser.add_argument('--layouts', nargs='+',
                        default=['in-process', 'pipeline', 'three-process'],
                        choices=['in-process', 'pipeline', 'three-process'])
    parser.add_argument('--seconds', type=float, default=10.0, help='measured seconds per run')
    parser.add_argument('--warmup', type=float, default=3.0, help='seconds before measuring')
    parser.add_argument('--runs', type=int, default=20, help='micro-benchmark repetitions')
    parser.add_argument('--threads', type=int, default=None,
                        help='network CPU threads (default: the cores; in the live runs as '
                        '`monet pipeline`: the backend default with one detector process, '
                        'the cores shared out with several)')
    parser.add_argument('--backend', choices=('torch', 'onnxruntime'), default=None,
                        help="detector backend of the end-to-end runs (default: `monet "
                        "pipeline`'s --backend auto: onnxruntime for float32 and int8, torch "
                        'for bfloat16)')
    parser.add_argument('--precision', choices=('float32', 'bfloat16', 'int8'), nargs='+',
                        default=['float32'], help='detector precision(s) of the end-to-end '
                        'runs (several: each case with each, side by side); int8 as `monet '
                        'pipeline --precision int8`: quantised once before the runs, '
                        'calibrated on the tracked crops of a recording of the camera feed')
    parser.add_argument('--fusion-views', type=int, nargs='+', default=[4, 8, 35])
    parser.add_argument('--detector-views', type=int, nargs='*', default=[4, 8],
                        help='views of the detector table (none: no detector table)')
    parser.add_argument('--architectures', nargs='+', default=['small'],
                        help='networks of the torch / ONNX Runtime comparison')
    parser.add_argument('--skip-live', action='store_true', help='micro-benchmarks only')
    parser.add_argument('--viewable', action='store_true', help='every end-to-end case with '
                        'the viewable outputs (debug images, TF, camera markers) off and on')
    parser.add_argument('--input-size', type=int, default=None,
                        help='network input side in px (multiple of 8) of the small net; '
                        'default: its own (256)')
    parser.add_argument('--second-job', type=int, default=0, metavar='N',
                        help='N CPU-bound processes beside the end-to-end runs (a loaded '
                        'machine; the load column says how loaded)')
    parser.add_argument('--repeat', type=int, default=1,
                        help='runs per end-to-end case (median shown; with --viewable the '
                        'off/on runs alternate)')
    parser.add_argument('--quick', action='store_true',
                        help='every table at tiny sizes (2 cameras, 2 s runs, few repeats)')
    parser.add_argument('--receive', type=int, default=3, metavar='RUNS',
                        help='runs of the image-receive table (0: none)')
    parser.add_argument('--detector-processes', type=int, nargs='+', default=[1],
                        help='detector processes of the three-process and pipeline layouts '
                        '(several: each case with each; cameras split between them; 0: '
                        "monet pipeline's default, two from 16 cameras on, else one)")
    parser.add_argument('--batch-wait-ms', type=float, default=None,
                        help="the detectors' batch_wait_ms (default: the node's); 0 runs a "
                        'batch of the newest frame of every camera at once when no instant is '
                        'common to all')
    parser.add_argument('--worker', help=argparse.SUPPRESS)
    parser.add_argument('--receive-worker', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        return worker(json.loads(args.worker))
    if args.receive_worker:
        return receive_worker(json.loads(args.receive_worker))
    if args.repeat < 1:
        parser.error(f'--repeat must be >= 1, got {args.repeat}')
    if args.batch_wait_ms is not None and not args.batch_wait_ms >= 0:
        parser.error(f'--batch-wait-ms must be >= 0, got {args.batch_wait_ms}')
    if any(n < 0 for n in args.detector_processes):
        parser.error(f'--detector-processes must be >= 0, got {args.detector_processes}')
    from monet_ros.models.detector import check_precision
    for precision in args.precision:      # what cannot run here: one line, before any run
        try:
            check_precision(precision, backend_for(precision, args.backend), 'cpu')
        except ValueError as error:
            parser.error(f'--precision {precision} with --backend '
                         f'{backend_for(precision, args.backend)}: {error}')
    if args.quick:
        args.cameras, args.extra, args.seconds, args.warmup = [2], ['2@60'], 2.0, 2.0
        args.runs, args.fusion_views, args.detector_views = 3, [4, 35], [2]
        args.receive = min(args.receive, 1)
    print(f'# machine: {os.cpu_count()} CPUs, load average '
          f'{" ".join(f"{x:.1f}" for x in os.getloadavg())} at start; network threads '
          f'{args.threads or "as monet pipeline"}; small net ({HEIGHT}x{WIDTH} images cropped to '
          f'{args.input_size or 256}x{args.input_size or 256}); end-to-end precision '
          f'{" and ".join(args.precision)}; detector batch_wait_ms '
          f'{"default" if args.batch_wait_ms is None else args.batch_wait_ms}')

    print('\n## Fusion per frame (fuse_heatmaps of V separate 14x64x64 heatmaps, as the node '
          'holds them, to 3D; torch threads 1 as the fusion node)')
    print('| views | fuse_heatmaps ms | stages ms: decode / undistort / triangulate / errors |'
          ' baseline: plain DLT ms | undistort_views ms | max error vs cv2.undistortPoints '
          'converged / default 5 iterations (px) |')
    print('|---|---|---|---|---|---|')
    for views in args.fusion_views:
        r = fusion_micro(views, args.runs * 5)
        s = r['stages']
        print(f'| {views} | {1e3 * r["fusion"]:.2f} | {s["decode"]:.2f} / {s["undistort"]:.2f}'
              f' / {s["triangulate"]:.2f} / {s["errors"]:.2f} | {1e3 * r["plain"]:.2f} | '
              f'{1e3 * r["undist"]:.3f} | {r["err_conv"]:.1e} / {r["err_default"]:.1e}'
              f'{"" if r["distorted"] else " (no distortion)"} |', flush=True)
    print('(errors: reprojection errors of the inlier views; the exclusion search has them '
          'already, so they cost ~0 beyond triangulate)')

    micro_threads = args.threads or usable_cores()
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        if args.detector_views:
            print(f'\n## Detector images/s (Detector.predict of V 640x480 views in one '
                  f'batch, {micro_threads} thread(s), median of {args.runs} calls; another '
                  f'job on the machine swings these several-fold)')
            print('| network | views | baseline: torch NCHW float32 | torch float32 '
                  '(channels-last) | torch bfloat16 | onnxruntime | float32 / bfloat16 / '
                  'onnxruntime vs baseline |')
            print('|---|---|---|---|---|---|---|')
        for arch in args.architectures:
            for views in args.detector_views:
                r = detector_micro(views, args.runs, micro_threads, arch, workdir,
                                   args.input_size if arch == 'small' else None)
                cells = [f'{r[k]:.1f}' if isinstance(r[k], float) else r[k] for k in r]
                ratios = ' / '.join(f'{r[k] / r["baseline"]:.2f}x' if isinstance(r[k], float)
                                    else 'n/a' for k in ('float32', 'bfloat16', 'onnxruntime'))
                print(f'| {arch} | {views} | {" | ".join(cells)} | {ratios} |', flush=True)
        if args.receive:
            views, rate = (2, 30.0) if args.quick else (8, 30.0)
            r = receive_micro(views, rate, 3.0 if args.quick else 8.0, args.receive, workdir)
            print(f'\n## Receiving images ({views} streams of {WIDTH}x{HEIGHT} rgb8 at '
                  f'{rate:.0f} Hz from another process; subscriber CPU per image, median of '
                  f'{args.receive} runs)')
            print('| taken as | CPU ms per image | runs | vs rclpy message |')
            print('|---|---|---|---|')
            base = np.median(r['message', False])
            for mode, text in (
                    (('message', False), 'rclpy message, glibc default (baseline)'),
                    (('message', True), 'rclpy message, large buffers from the heap (the '
                     'nodes)'),
                    (('serialized', True), 'serialized, decoded in place, heap')):
                print(f'| {text} | {np.median(r[mode]):.2f} | '
                      f'{"/".join(f"{x:.2f}" for x in r[mode])} | '
                      f'{np.median(r[mode]) / base:.2f}x |', flush=True)
        if args.skip_live:
            return 0
        runs = [(v, args.rate) for v in args.cameras]
        for item in args.extra:
            cams, _, hz = item.partition('@')
            runs.append((int(cams), float(hz)))
        args.int8_calibration = ''
        if 'int8' in args.precision:       # once, before and outside the measured runs
            try:
                args.int8_calibration, note, took = prepare_int8_runs(
                    workdir, max(v for v, _ in runs), args.threads or 0, args.input_size)
            except ValueError as error:
                print(f'bench/pipeline.py: --precision int8: {error}', file=sys.stderr)
                return 2
            print(f'\n# int8 ({took:.1f} s, before the measured runs and outside them): '
                  f'{note}; every int8 run gives its detectors calibration '
                  f'{args.int8_calibration}, as `monet pipeline --precision int8` does',
                  flush=True)
        print(f'\n## End to end, {WIDTH}x{HEIGHT} rgb8, '
              + ' / '.join(f'{p} ({backend_for(p, args.backend)})' for p in args.precision)
              + ', '
              f'{args.seconds:.0f} s measured after {args.warmup:.0f} s warm-up'
              + (f', median of {args.repeat} runs'
                 + (' (off/on interleaved)' if args.viewable else '') if args.repeat > 1
                 else '')
              + (f', with a second job ({args.second_job} CPU-bound process(es) beside '
                 'every run)' if args.second_job else ''))
        print('| cameras @ Hz | layout | viewable | published frames/s | keypoints3d/s | '
              'of them with every camera /s | detector images/s'
              ' | latency median ms | latency p95 ms | heatmaps latency median / p95 ms'
              ' | node CPU ms per keypoints3d | fusion frames fused / partial / stale '
              '(whole run) | detector batches (incomplete) / frames dropped '
              '(whole run) | detector ms/batch: convert, crop, '
              'forward, publish | fusion ms: receive (per view), decode, undistort, '
              'triangulate, errors, publish | node callback errors | load |')
        print('|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|')
        costs = []
        with second_job(args.second_job):
            if args.second_job:
                time.sleep(5)   # let the load average see it
            run_cases(args, runs, workdir, costs)
        if costs:
            print('\n## What the viewable outputs cost (debug images at their default rate '
                  'with a subscriber per camera, /tf_static, camera markers; off -> on)')
            print('| cameras @ Hz | layout | keypoints3d/s off -> on | throughput change | '
                  'node CPU ms per keypoints3d off -> on | CPU change |')
            print('|---|---|---|---|---|---|')
            for views, rate, layout, off, on in costs:
                runs = (f' (runs {"/".join(f"{x:.1f}" for x in off["fused_runs"])} -> '
                        f'{"/".join(f"{x:.1f}" for x in on["fused_runs"])})'
                        if len(off['fused_runs']) > 1 else '')
                print(f'| {views} @ {rate:.0f} | {layout} | {off["fused"]:.1f} -> '
                      f'{on["fused"]:.1f}{runs} | '
                      f'{100 * (on["fused"] / off["fused"] - 1):+.1f}% | '
                      f'{off["cpu_ms"]:.1f} -> {on["cpu_ms"]:.1f} | '
                      f'{100 * (on["cpu_ms"] / off["cpu_ms"] - 1):+.1f}% |', flush=True)
    print(f'# load average {" ".join(f"{x:.1f}" for x in os.getloadavg())} at the end (a '
          'shared machine inflates every figure)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
