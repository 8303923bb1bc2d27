"""GPU figures: detector images/s (small / CPM / hourglass at batch 1/8/32), the detector
path of the live node (Detector.predict of 8 camera images in one batch, torch and ONNX
Runtime) and training steps/s. Run through bench/gpu.sh on a machine with CUDA; falls
back to the CPU (and says so) where there is none. Prints tables; never asserts.

    python bench/gpu.py [--device cuda] [--seconds 2] [--tiny]
"""
import argparse
import os
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import torch  # noqa: E402

from monet_ros.learning.losses import masked_heatmap_mse  # noqa: E402
from monet_ros.models import Detector, build_model, save_checkpoint  # noqa: E402
from monet_ros.synth.rig import RigConfig, make_rig  # noqa: E402


def sync(device):
    if device.type == 'cuda':
        torch.cuda.synchronize(device)


def rate(fn, device, seconds, min_calls=3):
    """Calls per second of fn over about `seconds` (after 2 warm-up calls)."""
    for _ in range(2):
        fn()
    sync(device)
    calls, start = 0, time.perf_counter()
    while calls < min_calls or time.perf_counter() - start < seconds:
        fn()
        calls += 1
    sync(device)
    return calls / (time.perf_counter() - start)


def inference(model, batch, device, seconds, amp):
    images = torch.rand(batch, 3, *model.input_size, device=device)

    def step():
        with torch.inference_mode(), torch.autocast(device.type, torch.bfloat16,
                                                    enabled=amp):
            model(images)
    return batch * rate(step, device, seconds)


def training(model, batch, device, seconds, amp):
    model.train()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-4)
    images = torch.rand(batch, 3, *model.input_size, device=device)
    h, w = model.heatmap_size
    points = torch.rand(batch, model.num_keypoints, 2, device=device) * torch.tensor(
        [w - 1.0, h - 1.0], device=device)

    def step():
        optimizer.zero_grad(set_to_none=True)
        with torch.autocast(device.type, torch.bfloat16, enabled=amp):
            stages = model(images)
        loss = masked_heatmap_mse([s.float() for s in stages], points, sigma=1.5)
        loss.backward()
        optimizer.step()
    steps = rate(step, device, seconds)
    model.eval()
    return steps


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--device', default='cuda' if torch.cuda.is_available() else 'cpu')
    parser.add_argument('--seconds', type=float, default=2.0, help='timed seconds per figure')
    parser.add_argument('--batches', type=int, nargs='+', default=[1, 8, 32])
    parser.add_argument('--train-batch', type=int, default=16)
    parser.add_argument('--architectures', nargs='+', default=['small', 'cpm', 'hourglass'])
    parser.add_argument('--tiny', action='store_true',
                        help='a check of the script: small inputs, batches 1 and 2, 0.2 s')
    args = parser.parse_args()
    device = torch.device(args.device)
    options = {}
    if args.tiny:
        args.seconds, args.batches, args.train_batch = 0.2, [1, 2], 2
        options = {'small': {'width': 16, 'input_size': (64, 64)},
                   'cpm': {'num_stages': 2, 'width': 16, 'input_size': (64, 64)},
                   'hourglass': {'features': 32, 'depth': 2, 'input_size': (64, 64)}}
    if device.type == 'cuda':
        torch.backends.cudnn.benchmark = True
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True
        name = torch.cuda.get_device_name(device)
    else:
        name = f'CPU ({os.cpu_count()} cores, {torch.get_num_threads()} torch threads)'
    print(f'# device: {name}; torch {torch.__version__}; {args.seconds:g} s per figure'
          f'{"; --tiny (not real figures)" if args.tiny else ""}')
    amp_modes = [False, True] if device.type == 'cuda' else [False]
    print('\n## Detector networks (forward only; float32, TF32 on; bf16 = autocast)')
    header = ' | '.join(f'batch {b} images/s' for b in args.batches)
    print(f'| network | input | precision | {header} | training steps/s (batch '
          f'{args.train_batch}, Adam) |')
    print('|---|---|---|' + '---|' * len(args.batches) + '---|')
    for arch in args.architectures:
        torch.manual_seed(0)
        model = build_model(arch, 14, **options.get(arch, {})).to(device).eval()
        for amp in amp_modes:
            cells = [f'{inference(model, b, device, args.seconds, amp):.0f}'
                     for b in args.batches]
            steps = training(model, args.train_batch, device, args.seconds, amp)
            print(f'| {arch} | {model.input_size[0]}x{model.input_size[1]} | '
                  f'{"bf16" if amp else "fp32"} | {" | ".join(cells)} | {steps:.1f} |',
                  flush=True)
        del model
        if device.type == 'cuda':
            torch.cuda.empty_cache()

    views = 2 if args.tiny else 8
    print(f'\n## The live detector path: Detector.predict of {views} 640x480 camera images '
          '(crop + one batched forward + heatmaps back to the host)')
    print('| network | backend, precision | images/s |')
    print('|---|---|---|')
    rig = make_rig(RigConfig(num_cameras=views))
    images = np.random.default_rng(0).integers(0, 255, (views, 480, 640, 3), np.uint8)
    with tempfile.TemporaryDirectory() as tmp:
        for arch in args.architectures:
            torch.manual_seed(0)
            path = Path(tmp) / f'{arch}.pt'
            save_checkpoint(path, build_model(arch, 14, **options.get(arch, {})),
                            {'keypoints': [f'k{i}' for i in range(14)]})
            for backend, precision in (('torch', 'float32'), ('torch', 'bfloat16'),
                                       ('onnxruntime', 'float32')):
                name = f'{backend} {precision}'
                try:
                    detector = Detector.from_checkpoint(path, device=device, backend=backend,
                                                        precision=precision)
                except ValueError as error:  # no onnxruntime / CUDA provider / bfloat16
                    print(f'| {arch} | {name} | n/a: {error} |', flush=True)
                    continue
                fps = views * rate(lambda d=detector: d.predict(images, rig), device,
                                   args.seconds)
                print(f'| {arch} | {name} | {fps:.0f} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
