"""Detector throughput: images per second per architecture at batch = number of cameras.

For each architecture and batch (1, 4, 8 cameras) it times, median of --repeats runs after
a warm-up:
  baseline  plain eval-mode model forward (BatchNorm not folded)
  forward   the Detector's network forward (BatchNorm folded into the convolutions)
  predict   Detector.predict end to end: crop + resize every 1280x960 frame (antialiased),
            uint8 -> float, one batched forward, heatmaps back to numpy, virtual cameras
  CPU time  predict images per CPU-second of this process x torch threads: an estimate of
            the rate on that many dedicated cores when the machine is shared
Run: .venv/bin/python bench/detector.py [--device cpu|cuda] [--archs small cpm hourglass]
Target: small net >= 30 images/s aggregate at 256x256 on 2 CPU cores.
"""
import argparse
import os
import statistics
import sys
import time

import numpy as np
import torch

from monet_ros.geometry import Camera
from monet_ros.models import build_model
from monet_ros.models.detector import Detector


def timed(fn, fn_args, repeats, device):
    """Median wall seconds and median process CPU seconds of fn(*fn_args) over `repeats` runs
    after one warm-up run."""
    fn(*fn_args)  # warm-up (allocations, kernel selection)
    times, cpu = [], []
    for _ in range(repeats):
        if device.type == 'cuda':
            torch.cuda.synchronize()
        start, start_cpu = time.perf_counter(), time.process_time()
        fn(*fn_args)
        if device.type == 'cuda':
            torch.cuda.synchronize()
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return statistics.median(times), statistics.median(cpu)


def rig(n, width=1280, height=960):
    K = np.array([[1000.0, 0, width / 2], [0, 1000.0, height / 2], [0, 0, 1]])
    return [Camera(name=f'cam{i}', K=K, dist=np.zeros(5), R=np.eye(3),
                   t=np.array([0.0, 0.0, 3.0]), width=width, height=height) for i in range(n)]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--archs', nargs='+', default=['small', 'hourglass', 'cpm'])
    parser.add_argument('--batches', nargs='+', type=int, default=[1, 4, 8])
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--keypoints', type=int, default=14)
    parser.add_argument('--device', default='cuda' if torch.cuda.is_available() else 'cpu')
    args = parser.parse_args(argv)
    device = torch.device(args.device)
    threads = torch.get_num_threads()
    name = torch.cuda.get_device_name(device) if device.type == 'cuda' else \
        f'CPU, {torch.get_num_threads()} threads, {os.cpu_count()} cores'
    load = os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan')
    print(f'device: {name}; torch {torch.__version__}; load average at start {load:.2f}; '
          f'median of {args.repeats} runs; {args.keypoints} keypoints', file=sys.stderr)
    rng = np.random.default_rng(0)
    rows = []
    for arch in args.archs:
        torch.manual_seed(0)
        model = build_model(arch, args.keypoints).eval().to(device)
        detector = Detector(model, {'keypoints': [f'k{i}' for i in range(args.keypoints)]},
                            device=device)
        h, w = model.input_size
        for batch in args.batches:
            x = torch.rand(batch, 3, h, w, device=device)
            images = rng.integers(0, 256, size=(batch, 960, 1280, 3), dtype=np.uint8)
            cameras = rig(batch)
            with torch.inference_mode():
                base, _ = timed(model, (x,), args.repeats, device)
                fused, _ = timed(detector.model, (x,), args.repeats, device)
            full, full_cpu = timed(detector.predict, (images, cameras), args.repeats, device)
            # Load-robust estimate: images per CPU-second of this process times the threads
            # (what `threads` dedicated cores would give; spin-waits make it conservative).
            rows.append((arch, f'{h}x{w}', '{}x{}'.format(*model.heatmap_size), batch,
                         batch / base, batch / fused, batch / full, 1000 * full,
                         batch * threads / full_cpu))
            print(f'  {arch} batch {batch} done', file=sys.stderr)
    header = ('arch', 'input', 'heatmap', 'batch', 'baseline img/s', 'forward img/s',
              'predict img/s', 'predict ms/batch', f'predict img/s, CPU time x {threads}')
    print(f'\nDetector throughput on {name} (load average at start {load:.2f})')
    print('| ' + ' | '.join(header) + ' |')
    print('|' + '---|' * len(header))
    for arch, size, heat, batch, base, fused, full, ms, by_cpu in rows:
        print(f'| {arch} | {size} | {heat} | {batch} | {base:.1f} | {fused:.1f} | {full:.1f} '
              f'| {ms:.0f} | {by_cpu:.1f} |')
    small = [r for r in rows if r[0] == 'small']
    if small:
        best = max(r[6] for r in small)
        best_cpu = max(r[8] for r in small)
        print(f'\nsmall net, predict end to end: best {best:.1f} images/s wall clock, '
              f'{best_cpu:.1f} images/s from CPU time x {threads} threads '
              f'(target >= 30 on 2 CPU cores)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
