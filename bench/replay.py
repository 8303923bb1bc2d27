"""Decode throughput of a recording: our reader vs rosbags AnyReader vs mcap + mcap_ros2.

Writes (once, cached) an 8-camera 640x480 rgb8 synthetic bag with BagWriter (smooth random
images, 30 fps), then times, for each reader, decoding every image message of the 8 image
topics into (H, W, 3) numpy arrays; ours also groups them into multiview frames
(iter_multiview_frames). Prints multiview frames/s, images/s and MB/s of message data:
the median of --runs runs per reader. Target: >= 150 multiview frames/s (5x real time
at 30 fps for 8 cameras).

    .venv/bin/python bench/replay.py [--frames 90] [--runs 5] [--bag /tmp/monet_replay_bench]
"""
import argparse
import os
from pathlib import Path
import statistics
import sys
import time

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from monet_ros.io import (  # noqa: E402
    BagWriter,
    any_image_to_numpy,
    iter_multiview_frames,
    open_bag,
)

CAMERAS = 8
W, H = 640, 480
FPS = 30


def make_bag(path, frames, compression):
    """8 cameras x frames rgb8 images (smooth noise, shifted per frame) + CameraInfo-free."""
    rng = np.random.default_rng(0)
    base = []
    for _ in range(CAMERAS):
        small = rng.integers(0, 256, (H // 16, W // 16, 3)).astype(np.uint8)
        base.append(cv2.resize(small, (W, H), interpolation=cv2.INTER_CUBIC))
    t0 = 1_700_000_000_000_000_000
    with BagWriter(path, compression=compression) as bag:
        for k in range(frames):
            stamp = t0 + k * (1_000_000_000 // FPS)
            for c in range(CAMERAS):
                img = np.roll(base[c], (k * 3, k * 5), axis=(0, 1))
                bag.write_image(f'/cam{c}/image_raw', stamp, img, f'cam{c}_optical')


def topics():
    return [f'/cam{c}/image_raw' for c in range(CAMERAS)]


def run_ours(bag):
    reader = open_bag(bag)
    frames = images = nbytes = 0
    for f in iter_multiview_frames(reader, topics()):
        frames += 1
        for img in f.images.values():
            images += 1
            nbytes += img.nbytes
        assert not f.missing
    return frames, images, nbytes


def run_ours_raw(bag):
    reader = open_bag(bag)
    images = nbytes = 0
    for m in reader.messages(topics=topics(), decode=False):
        images += 1
        nbytes += len(m.data)
    return images // CAMERAS, images, nbytes


def run_rosbags(bag):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    images = nbytes = 0
    with AnyReader([Path(bag)], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        conns = [c for c in reader.connections if c.topic in topics()]
        for conn, _, raw in reader.messages(connections=conns):
            img = any_image_to_numpy(reader.deserialize(raw, conn.msgtype))
            images += 1
            nbytes += img.nbytes
    return images // CAMERAS, images, nbytes


def run_mcap_ros2(bag):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    images = nbytes = 0
    for path in sorted(Path(bag).glob('*.mcap')):
        with open(path, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for item in reader.iter_decoded_messages(topics=topics()):
                img = any_image_to_numpy(item.decoded_message)
                images += 1
                nbytes += img.nbytes
    return images // CAMERAS, images, nbytes


READERS = [
    ('monet_ros open_bag + iter_multiview_frames', run_ours),
    ('monet_ros open_bag raw (no decode)', run_ours_raw),
    ('rosbags AnyReader + deserialize', run_rosbags),
    ('mcap make_reader + mcap_ros2 decode', run_mcap_ros2),
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--frames', type=int, default=90)
    ap.add_argument('--runs', type=int, default=5)
    ap.add_argument('--compression', default='none', choices=['none', 'zstd', 'lz4'])
    ap.add_argument('--bag', default=None, help='bag folder (created when absent)')
    args = ap.parse_args(argv)
    bag = Path(args.bag or f'/tmp/monet_replay_bench_{args.frames}_{args.compression}')
    if not (bag / 'metadata.yaml').is_file():
        t = time.perf_counter()
        make_bag(bag, args.frames, args.compression)
        print(f'wrote {bag} ({args.frames} frames x {CAMERAS} cameras {W}x{H} rgb8, '
              f'{sum(p.stat().st_size for p in bag.iterdir()) / 1e6:.0f} MB) in '
              f'{time.perf_counter() - t:.1f} s', file=sys.stderr)
    print(f'bag: {bag}  ({args.frames} multiview frames, {CAMERAS} x {W}x{H} rgb8, chunk '
          f'compression {args.compression}); {os.cpu_count()} CPU cores (machine shared '
          f'with other jobs: load {os.getloadavg()[0]:.1f}); median of {args.runs} runs')
    rows = []
    for name, fn in READERS:
        fn(bag)                                   # warm the page cache and imports
        times = []
        for _ in range(args.runs):
            t = time.perf_counter()
            frames, images, nbytes = fn(bag)
            times.append(time.perf_counter() - t)
        med = statistics.median(times)
        assert images == args.frames * CAMERAS, (name, images)
        rows.append((name, med, frames / med, images / med, nbytes / med / 1e6))
    print(f'{"reader":<44} {"time s":>8} {"mv frames/s":>12} {"images/s":>9} {"MB/s":>8} '
          f'{"x realtime":>10}')
    for name, med, fps, ips, mbps in rows:
        print(f'{name:<44} {med:8.3f} {fps:12.1f} {ips:9.0f} {mbps:8.0f} {fps / FPS:10.1f}')
    ours = rows[0][2]
    print(f'target >= {5 * FPS} multiview frames/s (5x real time at {FPS} fps, {CAMERAS} '
          f'cameras): {"met" if ours >= 5 * FPS else "NOT met"} ({ours:.0f})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
