"""Where a detector batch's time goes (issue 38 item 1): one instant of V JPEG cameras split
into its stages, per image, for each precision, against the bare forward-pass rate.

Stages (median over --repeats batches after a warm-up; ms per image):
  decode full      cv2.imdecode of every 640x480 JPEG at full size (BGR)
  decode reduced   io.jpeg_scale.decode_for_crop: decoded at the crop's scale (1/s), one view
                   after the other
  decode parallel  the same decodes of the instant's views in parallel threads
                   (io.jpeg_scale.decode_views on --view-threads, as the detector node and
                   `monet process` decode)
  crop full        the Detector's crop of the full decodes (antialiased warp + BGR -> RGB,
                   models.crop_images with layouts on --view-threads, as Detector.predict)
  crop reduced     the same crop of the reduced decodes (same heatmap cameras)
  crop raw         the same crop of raw 640x480 rgb8 frames (a sensor_msgs/Image camera: no
                   decode, the message buffer cropped as it is)
  forward          Detector.forward: uint8 crops -> float input -> network -> numpy heatmaps
  bare forward     the network alone on a ready float input (torch model / ONNX session):
                   the denominator; every throughput is also given as a fraction of it
  encode           heatmaps -> sensor_msgs/Image (io.heatmaps_to_image_msg) + camera_info
  publish          rclpy publish of those messages to one subscriber in another process
  DDS delivery     publish -> callback in that subscriber (header stamp = wall clock), median
Chains (images/s): decode + crop + forward + encode + publish, with the full, reduced,
parallel reduced decode and with raw input (no decode), each also as a fraction of the bare
forward pass of the same precision (chain / bare).
Precisions: float32 (torch), bfloat16 (torch, only where native), float32 (onnxruntime) and
int8 (onnxruntime, only with VNNI / AMX-INT8; calibrated on the bench's own crops).
Threads: --threads for torch and onnxruntime alike, --view-threads for the decodes and crops
(default --threads); OpenMP waits passively, as in the detector node (OMP_WAIT_POLICY=PASSIVE
unless set). The load average and CPU model are printed: on a shared machine every figure is
inflated.
Run: .venv/bin/python bench/detector_budget.py [--cameras 8 16] [--repeats 5] [--no-dds]
     [--view-threads N] [--network small|cpm|hourglass] [--input-size PX]
"""
import argparse
import os
import statistics
import subprocess
import sys
import time

import cv2
import numpy as np

from monet_ros.cores import ViewThreads, cpu_model
from monet_ros.geometry import Camera
from monet_ros.io.images import raw_to_rgb8
from monet_ros.io.jpeg_scale import decode_for_crop, decode_views
from monet_ros.nodes import passive_openmp

WIDTH, HEIGHT = 640, 480

SUBSCRIBER = r"""
import sys, time, rclpy
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image
rclpy.init()
node = Node('budget_sink')
delays = []
def on(msg):
    sent = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
    delays.append((time.time_ns() - sent) / 1e6)
node.create_subscription(Image, '/budget/heatmaps', on, 100)
print('ready', flush=True)
end = time.monotonic() + float(sys.argv[1])
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
delays.sort()
print('delays', len(delays), delays[len(delays) // 2] if delays else float('nan'), flush=True)
"""




def frames(n, seed=0):
    """n JPEG bytes of 640x480 smooth textured frames with a few blobs (q 90)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        small = rng.integers(0, 255, (HEIGHT // 16, WIDTH // 16, 3), np.uint8)
        image = cv2.resize(small, (WIDTH, HEIGHT), interpolation=cv2.INTER_CUBIC)
        for _ in range(6):
            centre = (int(rng.integers(40, WIDTH - 40)), int(rng.integers(40, HEIGHT - 40)))
            cv2.circle(image, centre, 12, tuple(int(c) for c in rng.integers(0, 255, 3)), -1)
        out.append(cv2.imencode('.jpg', image, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes())
    return out


def median_ms(fn, repeats):
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cameras', nargs='+', type=int, default=[8, 16])
    parser.add_argument('--network', choices=('small', 'cpm', 'hourglass'), default='small',
                        help="the detector architecture (models.build_model; random weights; "
                        "int8's speed depends on it)")
    parser.add_argument('--input-size', type=int, default=128)
    parser.add_argument('--keypoints', type=int, default=14)
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--view-threads', type=int, default=None,
                        help='threads decoding and cropping the views in parallel (default '
                        '--threads, as the detector node: cores.view_threads)')
    parser.add_argument('--no-dds', action='store_true', help='skip publish / DDS delivery')
    args = parser.parse_args(argv)
    # OpenMP threads wait passively, as in the detector node (monet_ros.nodes): before torch
    # loads. Spinning ones (OpenMP's default) took the cores from ONNX Runtime's and the
    # decode threads, and from the whole chain on a shared machine.
    passive_openmp()
    import torch

    from monet_ros.models import build_model
    from monet_ros.models.crop import crop_images
    from monet_ros.models.detector import Detector, bfloat16_native
    from monet_ros.models.quantize import cpu_int8_feature
    torch.set_num_threads(args.threads)
    views_on = ViewThreads(args.threads if args.view_threads is None else args.view_threads)
    print(f'# {cpu_model()}; {os.cpu_count()} CPUs; load average at start '
          f'{" ".join(f"{x:.2f}" for x in os.getloadavg())}; threads {args.threads}, view '
          f'threads {views_on.threads}, OMP_WAIT_POLICY {os.environ["OMP_WAIT_POLICY"]}; '
          f'{args.network} net {args.input_size}x{args.input_size}, {args.keypoints} keypoints; '
          f'{WIDTH}x{HEIGHT} JPEG q90, full-frame crops; median of {args.repeats}')
    size = args.input_size
    model = build_model(args.network, args.keypoints, input_size=(size, size)).eval()
    meta = {'keypoints': [f'k{i}' for i in range(args.keypoints)]}
    K = np.array([[500.0, 0, WIDTH / 2 - 0.5], [0, 500.0, HEIGHT / 2 - 0.5], [0, 0, 1]])
    publisher = sink = None
    if not args.no_dds:
        import rclpy
        from rclpy.node import Node
        from sensor_msgs.msg import CameraInfo, Image
        rclpy.init()
        node = Node('budget_source')
        publisher = node.create_publisher(Image, '/budget/heatmaps', 100)
        info_publisher = node.create_publisher(CameraInfo, '/budget/camera_info', 100)
    from monet_ros.io import camera_info_from_camera, heatmaps_to_image_msg
    rows = []
    for V in args.cameras:
        cameras = [Camera(name=f'cam{i}', K=K, dist=np.zeros(5), R=np.eye(3),
                          t=np.array([0.0, 0.0, 3.0]), width=WIDTH, height=HEIGHT)
                   for i in range(V)]
        data = frames(V, seed=V)
        setups = [('float32', 'torch', 'float32')]
        if bfloat16_native('cpu'):
            setups.append(('bfloat16', 'torch', 'bfloat16'))
        setups.append(('float32 ort', 'onnxruntime', 'float32'))
        probe = Detector(model, meta, device='cpu')
        boxes = probe.boxes_for(cameras)
        full = [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_COLOR) for d in data]
        calibration = np.stack([raw_to_rgb8(c, 'bgr8') for c in
                                crop_images(full, boxes, (size, size))])
        if cpu_int8_feature() is not None:
            setups.append(('int8 ort', 'onnxruntime', 'int8'))
        common = {}
        common['decode full'] = median_ms(
            lambda data=data: [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_COLOR)
                               for d in data],
            args.repeats) / V
        reduced = [decode_for_crop(d, c, b, (size, size)) for d, c, b in zip(data, cameras, boxes)]
        views = list(zip(data, cameras, boxes))
        common['decode reduced'] = median_ms(
            lambda views=views: [
                decode_for_crop(d, c, b, (size, size)) for d, c, b in views], args.repeats) / V
        common['decode parallel'] = median_ms(
            lambda views=views: decode_views(views, (size, size), views_on), args.repeats) / V
        parallel = decode_views(views, (size, size), views_on)
        assert all(np.array_equal(p[0], r[0]) for p, r in zip(parallel, reduced))
        bgr, rgb = ['bgr8'] * V, ['rgb8'] * V
        common['crop full'] = median_ms(
            lambda full=full, boxes=boxes, bgr=bgr: crop_images(
                full, boxes, (size, size), layouts=bgr, threads=views_on),
            args.repeats) / V
        small_boxes = np.stack([r[3] for r in reduced])
        common['crop reduced'] = median_ms(
            lambda images=[r[0] for r in reduced], boxes=small_boxes, bgr=bgr: crop_images(
                images, boxes, (size, size), layouts=bgr, threads=views_on), args.repeats) / V
        # raw rgb8 frames as an Image message's buffer (io.images.view_for_crop: no copy)
        raw = [raw_to_rgb8(f, 'bgr8').copy() for f in full]
        common['crop raw'] = median_ms(
            lambda raw=raw, boxes=boxes, rgb=rgb: crop_images(
                raw, boxes, (size, size), layouts=rgb, threads=views_on),
            args.repeats) / V
        heat, heat_cams = probe.predict([r[0] for r in reduced], [r[2] for r in reduced],
                                        small_boxes, keep_aspect=False,
                                        encodings=['bgr8'] * V)
        def encode(heat=heat, heat_cams=heat_cams):
            return [(heatmaps_to_image_msg(h, 0, 'cam'),
                     camera_info_from_camera(c, 0, 'cam')) for h, c in zip(heat, heat_cams)]
        common['encode'] = median_ms(encode, args.repeats) / V
        if publisher is not None:
            messages = encode()
            sink = subprocess.Popen([sys.executable, '-c', SUBSCRIBER,
                                     str(3 + args.repeats * 0.5)], stdout=subprocess.PIPE,
                                    text=True)
            sink.stdout.readline()
            deadline = time.monotonic() + 10
            while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
                time.sleep(0.05)

            def publish(messages=messages):
                now = time.time_ns()
                for image, info in messages:
                    image.header.stamp.sec, image.header.stamp.nanosec = divmod(now, 10**9)
                    publisher.publish(image)
                    info_publisher.publish(info)
            times = []
            for _ in range(args.repeats + 1):
                start = time.perf_counter()
                publish()
                times.append(time.perf_counter() - start)
                time.sleep(0.3)
            common['publish'] = 1e3 * statistics.median(times[1:]) / V
            line = sink.communicate(timeout=60)[0].strip().splitlines()[-1].split()
            common['DDS delivery (latency)'] = float(line[2])
        crops = np.stack([raw_to_rgb8(c, 'bgr8') for c in
                          crop_images([r[0] for r in reduced], small_boxes, (size, size))])
        for name, backend, precision in setups:
            detector = Detector(model, meta, device='cpu', backend=backend, threads=args.threads,
                                precision=precision, calibration=calibration)
            forward = median_ms(lambda d=detector, c=crops: d.forward(c), args.repeats) / V
            ready = detector.input_buffer(V)
            ready.copy_(torch.from_numpy(crops).permute(0, 3, 1, 2)).div_(255.0)
            if detector.runner is not None:
                array = ready.numpy().copy()
                bare = median_ms(lambda d=detector, a=array: d.runner(a), args.repeats) / V
            else:
                def bare_torch(net=detector.model, ready=ready, bf16=precision == 'bfloat16'):
                    with torch.inference_mode(), torch.autocast('cpu', dtype=torch.bfloat16,
                                                                enabled=bf16):
                        net(ready)
                bare = median_ms(bare_torch, args.repeats) / V
            rows.append((V, name, common, forward, bare))
    print()
    print('| cameras | precision | decode full | decode reduced | decode parallel | crop full | '
          'crop reduced | crop raw | forward | bare forward | encode | publish | DDS latency | '
          'images/s full decode | images/s reduced | images/s parallel decode | images/s raw | '
          'bare forward images/s | reduced / bare | parallel decode / bare | raw / bare |')
    print('|' + '---|' * 21)
    for V, name, c, forward, bare in rows:
        tail = forward + c['encode'] + c.get('publish', 0.0)
        total_full = c['decode full'] + c['crop full'] + tail
        total_reduced = c['decode reduced'] + c['crop reduced'] + tail
        total_parallel = c['decode parallel'] + c['crop reduced'] + tail
        total_raw = c['crop raw'] + tail
        dds = c.get('DDS delivery (latency)', float('nan'))
        print(f'| {V} | {name} | {c["decode full"]:.3f} | {c["decode reduced"]:.3f} | '
              f'{c["decode parallel"]:.3f} | {c["crop full"]:.3f} | {c["crop reduced"]:.3f} | '
              f'{c["crop raw"]:.3f} | {forward:.3f} | {bare:.3f} | '
              f'{c["encode"]:.3f} | {c.get("publish", float("nan")):.3f} | {dds:.2f} ms | '
              f'{1e3 / total_full:.0f} | {1e3 / total_reduced:.0f} | '
              f'{1e3 / total_parallel:.0f} | {1e3 / total_raw:.0f} | {1e3 / bare:.0f} | '
              f'{bare / total_reduced:.2f} | {bare / total_parallel:.2f} | '
              f'{bare / total_raw:.2f} |')
    print(f'\n# ms per image (DDS latency: per message, publish -> subscriber callback); '
          f'load average at the end {" ".join(f"{x:.2f}" for x in os.getloadavg())}')
    views_on.close()
    if publisher is not None:
        import rclpy
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
