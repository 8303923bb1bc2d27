"""Live pipeline figures: end-to-end latency and throughput, detector images/s, fusion time.

    .venv/bin/python bench/pipeline.py [--cameras 4 8] [--seconds 10] [--rate 30] [--viewable]

End to end: this script publishes V camera streams (640x480 rgb8 + camera_info, stamped
with the wall clock) at `--rate` Hz to a real detector process (one node, all cameras
batched, small net, CPU) and a real fusion process, and times each /monet/keypoints3d
from its image stamp to its arrival here. Micro-benchmarks (in this process, median of
--runs): Detector.predict of V images in one batch against V single-image calls (the
baseline: one camera per forward), and fuse_heatmaps per frame against plain DLT without
outlier rejection (geometry.triangulate). --viewable adds a second end-to-end run per
camera count with the viewable outputs on (detector debug_image at its default rate with a
subscriber to every camera's, fusion /tf_static, skeleton and camera markers) to show what
they cost. Prints tables; never asserts.
"""
import argparse
import os
from pathlib import Path
import random
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from monet_ros.fusion import FusionConfig, fuse_heatmaps  # noqa: E402
from monet_ros.geometry import save_rig, triangulate  # noqa: E402
from monet_ros.models import Detector, build_model, decode_heatmaps, save_checkpoint  # noqa: E402
from monet_ros.skeleton import load_skeleton  # noqa: E402
from monet_ros.synth.rig import RigConfig, make_rig  # noqa: E402

WIDTH, HEIGHT = 640, 480


def median_time(fn, runs):
    fn()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def frames_for(rig, rng, count=8):
    """A few noise frames per camera (content does not change the cost of a forward)."""
    return [rng.integers(0, 255, (len(rig), HEIGHT, WIDTH, 3), dtype=np.uint8)
            for _ in range(count)]


def micro(views, runs, threads):
    import torch
    torch.set_num_threads(threads)
    rig = make_rig(RigConfig(num_cameras=views))
    model = build_model('small', 14)
    detector = Detector(model, {'keypoints': list(load_skeleton('human14').keypoints)},
                        device='cpu')
    images = frames_for(rig, np.random.default_rng(0), 1)[0]
    boxes = np.array([[160, 60, 480, 420]] * views, float)
    batched = median_time(lambda: detector.predict(list(images), rig, boxes), runs)
    single = median_time(lambda: [detector.predict([images[v]], [rig[v]], boxes[v:v + 1])
                                  for v in range(views)], runs)
    heat, heat_cams = detector.predict(list(images), rig, boxes)
    # Heatmaps with one clear peak per keypoint (a trained net's output shape).
    X = np.random.default_rng(1).uniform([-0.3, -0.3, 0.5], [0.3, 0.3, 1.6], (14, 3))
    h, w = heat.shape[2:]
    vv, uu = np.mgrid[0:h, 0:w]
    maps = []
    for cam in heat_cams:
        uv = cam.project(X)
        d2 = (uu[None] - uv[:, 0, None, None]) ** 2 + (vv[None] - uv[:, 1, None, None]) ** 2
        maps.append(np.exp(-d2 / 8.0).astype(np.float32))
    maps = np.stack(maps)
    K_heat = np.stack([c.K for c in heat_cams])
    config = FusionConfig()
    fusion = median_time(lambda: fuse_heatmaps(maps, K_heat, rig, config), runs * 5)
    decode = median_time(lambda: decode_heatmaps(maps), runs * 5)
    peaks = np.stack([cam.project(X) for cam in rig])
    plain = median_time(lambda: triangulate(peaks, rig), runs * 5)
    return dict(views=views, batched=batched, single=single, fusion=fusion, decode=decode,
                plain=plain, heat=heat.shape)


def end_to_end(views, seconds, rate, workdir, threads, viewable=False):
    """Real detector + fusion processes fed by this process; returns figures."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2
    import yaml

    from monet_ros.io import camera_info_from_camera, header_stamp_ns, numpy_to_image_msg
    from monet_ros.nodes.qos import IMAGE_OUT, STREAM_IN

    rig = make_rig(RigConfig(num_cameras=views))
    rig_path = workdir / f'rig{views}.yaml'
    save_rig(rig_path, rig)
    model_path = workdir / 'small.pt'
    if not model_path.exists():
        save_checkpoint(model_path, build_model('small', 14),
                        {'keypoints': list(load_skeleton('human14').keypoints)})
    env = dict(os.environ)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    env.update(ROS_DOMAIN_ID=str(random.randint(1, 101)), ROS_LOG_DIR=str(workdir / 'log'),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONPATH=str(REPO),
               FASTRTPS_DEFAULT_PROFILES_FILE=str(REPO / 'config' / 'fastdds_profile.xml'))
    params = workdir / f'params{views}_{int(viewable)}.yaml'
    params.write_text(yaml.safe_dump({
        '/**/detector': {'ros__parameters': {'rig': str(rig_path), 'model': str(model_path),
                                             'device': 'cpu', 'threads': threads,
                                             'debug_image': viewable}},
        '/**/fusion': {'ros__parameters': {'rig': str(rig_path), 'publish_tf': viewable,
                                           'camera_markers': viewable}}}))
    procs = [subprocess.Popen([sys.executable, '-m', f'monet_ros.nodes.{name}', '--ros-args',
                               '--params-file', str(params)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for name in ('fusion', 'detector')]
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    context = Context()
    rclpy.init(context=context, domain_id=int(env['ROS_DOMAIN_ID']))
    node = Node('bench', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    latencies, arrivals = [], []
    node.create_subscription(
        PointCloud2, '/monet/keypoints3d',
        lambda m: (latencies.append(time.time_ns() - header_stamp_ns(m)),
                   arrivals.append(time.monotonic())), STREAM_IN)
    heat_count = [0]
    debug_count = [0]
    for cam in rig:
        if viewable:
            node.create_subscription(Image, f'/monet/{cam.name}/debug_image',
                                     lambda m: debug_count.__setitem__(0, debug_count[0] + 1),
                                     STREAM_IN)
        node.create_subscription(Image, f'/monet/{cam.name}/heatmaps',
                                 lambda m: heat_count.__setitem__(0, heat_count[0] + 1),
                                 STREAM_IN)
    pubs = [(node.create_publisher(Image, cam.topic, IMAGE_OUT),
             node.create_publisher(CameraInfo, f'/{cam.name}/camera_info', IMAGE_OUT))
            for cam in rig]
    frames = frames_for(rig, np.random.default_rng(2))
    messages = [[numpy_to_image_msg(f[v], 0, cam.name) for v, cam in enumerate(rig)]
                for f in frames]
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not all(
                p[0].get_subscription_count() for p in pubs):
            executor.spin_once(timeout_sec=0.1)
        published = 0
        start = time.monotonic()
        warmup = 3.0
        next_tick = start
        measured_from = None
        while time.monotonic() - start < warmup + seconds:
            now = time.monotonic()
            if now >= next_tick:
                next_tick += 1.0 / rate
                stamp = time.time_ns()
                for v, cam in enumerate(rig):
                    image = messages[published % len(messages)][v]
                    image.header.stamp.sec, image.header.stamp.nanosec = divmod(stamp, 10**9)
                    pubs[v][1].publish(camera_info_from_camera(cam, stamp, cam.name))
                    pubs[v][0].publish(image)
                published += 1
                if measured_from is None and now - start >= warmup:
                    measured_from = (now, len(latencies), heat_count[0], published)
            executor.spin_once(timeout_sec=max(0.0, min(0.005, next_tick - time.monotonic())))
        end = time.monotonic()
        for _ in range(40):
            executor.spin_once(timeout_sec=0.05)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.wait(timeout=30)
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    t0, n0, h0, p0 = measured_from
    window = end - t0
    lat = np.array(latencies[n0:], float) / 1e6
    return dict(views=views, published=(published - p0) / window,
                fused=(len(latencies) - n0) / window, heat=(heat_count[0] - h0) / window,
                debug=debug_count[0] / (end - start),
                median=float(np.median(lat)) if lat.size else float('nan'),
                p95=float(np.percentile(lat, 95)) if lat.size else float('nan'))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--cameras', type=int, nargs='+', default=[4, 8])
    parser.add_argument('--seconds', type=float, default=10.0, help='measured seconds per run')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate (Hz)')
    parser.add_argument('--runs', type=int, default=5, help='micro-benchmark repetitions')
    parser.add_argument('--threads', type=int, default=2, help='torch threads')
    parser.add_argument('--skip-live', action='store_true', help='micro-benchmarks only')
    parser.add_argument('--viewable', action='store_true', help='also run each camera count '
                        'with debug images (subscribed), TF and markers on')
    args = parser.parse_args()
    print(f'# machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; '
          f'small net, CPU, torch threads {args.threads}')
    rows = [micro(v, args.runs, args.threads) for v in args.cameras]
    print('\n## Detector (one forward of V views, crop -> small net) and fusion, per frame')
    print('| views | batched forward ms | baseline: V single forwards ms | images/s batched |'
          ' images/s single | fuse_heatmaps ms | (decode ms) | baseline: plain DLT ms |')
    print('|---|---|---|---|---|---|---|---|')
    for r in rows:
        print(f'| {r["views"]} | {1e3 * r["batched"]:.1f} | {1e3 * r["single"]:.1f} | '
              f'{r["views"] / r["batched"]:.1f} | {r["views"] / r["single"]:.1f} | '
              f'{1e3 * r["fusion"]:.2f} | {1e3 * r["decode"]:.2f} | {1e3 * r["plain"]:.2f} |')
    if args.skip_live:
        return 0
    print(f'\n## End to end at {args.rate:.0f} Hz, {WIDTH}x{HEIGHT} rgb8 (detector and fusion '
          f'processes, {args.seconds:.0f} s measured after 3 s warm-up)')
    print('| cameras | viewable outputs | published frames/s | keypoints3d/s | heatmaps/s '
          '(detector images/s) | debug images/s | latency median ms | latency p95 ms |')
    print('|---|---|---|---|---|---|---|---|')
    with tempfile.TemporaryDirectory() as tmp:
        for v in args.cameras:
            for viewable in ((False, True) if args.viewable else (False,)):
                r = end_to_end(v, args.seconds, args.rate, Path(tmp), args.threads, viewable)
                print(f'| {v} | {"on" if viewable else "off"} | {r["published"]:.1f} | '
                      f'{r["fused"]:.1f} | {r["heat"]:.1f} | {r["debug"]:.1f} | '
                      f'{r["median"]:.0f} | {r["p95"]:.0f} |', flush=True)
    print(f'# load average {os.getloadavg()[0]:.1f} at the end (a shared machine inflates '
          'every figure)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
