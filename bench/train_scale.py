"""Data-parallel training scale: steps/s and images/s of the trainer at 1 and N processes
(monet_ros.learning.distributed, ranks started on localhost by torch.multiprocessing: gloo
on CPU, nccl with one GPU per rank on CUDA), median of --repeats timed runs each, with the
machine's load average. A 2-core machine shows no gain (the point is the overhead per
step: the all-gather of the outputs and DDP's gradient all-reduce); a multi-GPU machine
shows the scaling. Never asserts.

    python bench/train_scale.py [--procs 1 2] [--steps 20] [--device auto|cpu|cuda]
"""
import argparse
import json
import os
from pathlib import Path
import socket
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / 'test'))

import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.multiprocessing as mp  # noqa: E402


def free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def rank_main(rank, world_size, port, options, result):
    from helpers.blobs import blob_recording

    from monet_ros.learning import distributed
    from monet_ros.learning.config import TrainConfig
    from monet_ros.models import build_model

    if world_size > 1:
        os.environ.update(RANK=str(rank), WORLD_SIZE=str(world_size), LOCAL_RANK=str(rank),
                          MASTER_ADDR='127.0.0.1', MASTER_PORT=str(port))
    torch.set_num_threads(options['threads'])
    world, device = distributed.init_from_env(options['device'])
    device = device or torch.device('cuda' if options['device'] != 'cpu' and
                                    torch.cuda.is_available() else 'cpu')
    rec = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    config = TrainConfig(mode='monet', steps=10_000, epipolar_warmup=0.0,
                         architecture='small', input_size=options['input_size'],
                         batch_labelled=options['batch'], batch_pseudo=options['batch'],
                         batch_unlabeled=2, views_per_instant=4, eval_fraction=0.25,
                         device=str(device))
    probe = build_model('small', 3, **config.model_options())
    data = distributed.shared_training_data(rec, config, probe.input_size, probe.heatmap_size)
    trainer = distributed.DistributedTrainer(config, data, None, device=device)
    for _ in range(3):                                                  # warm-up
        trainer.step()
    rates = []
    for _ in range(options['repeats']):
        if device.type == 'cuda':
            torch.cuda.synchronize(device)
        start = time.perf_counter()
        for _ in range(options['steps']):
            trainer.step()
        if device.type == 'cuda':
            torch.cuda.synchronize(device)
        rates.append(options['steps'] / (time.perf_counter() - start))
    if world.writer:
        images = options['batch'] * 2 + 2 * 4
        Path(result).write_text(json.dumps({'steps_per_s': float(np.median(rates)),
                                            'images_per_s': float(np.median(rates)) * images,
                                            'per_rank_batch': trainer.per_rank_batch,
                                            'backend': world.backend or 'none',
                                            'device': str(device)}))
    distributed.shutdown()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--procs', type=int, nargs='+', default=None,
                        help='world sizes (default: 1 and all GPUs, or 1 and 2 on CPU)')
    parser.add_argument('--steps', type=int, default=20, help='timed steps per repeat')
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--batch', type=int, default=8, help='labelled (and pseudo) crops')
    parser.add_argument('--input-size', type=int, default=64)
    parser.add_argument('--threads', type=int, default=1, help='torch threads per rank')
    parser.add_argument('--device', default='auto', choices=('auto', 'cpu', 'cuda'))
    args = parser.parse_args()
    cuda = args.device != 'cpu' and torch.cuda.is_available()
    gpus = torch.cuda.device_count() if cuda else 0
    procs = args.procs or ([1] + ([gpus] if gpus > 1 else []) if cuda else [1, 2])
    if cuda and max(procs) > gpus:
        print(f'# skipping world sizes above the {gpus} GPU(s): nccl needs one per rank')
        procs = [p for p in procs if p <= gpus]
    options = dict(steps=args.steps, repeats=args.repeats, batch=args.batch,
                   input_size=args.input_size, threads=args.threads,
                   device='cuda' if cuda else 'cpu')
    print(f'# loadavg {os.getloadavg()}, torch {torch.__version__}, '
          f'{"%d CUDA device(s)" % gpus if cuda else "CPU"}, {os.cpu_count()} cores; '
          f'global batch {args.batch * 2 + 8} crops of {args.input_size} px, small net, '
          f'median of {args.repeats} x {args.steps} steps')
    print('| processes | backend | crops / rank | steps/s | images/s | vs 1 process |')
    print('|---|---|---|---|---|---|')
    base = None
    with tempfile.TemporaryDirectory() as tmp:
        for n in procs:
            result = Path(tmp) / f'{n}.json'
            if n == 1:
                rank_main(0, 1, 0, options, result)
            else:
                mp.spawn(rank_main, args=(n, free_port(), options, result), nprocs=n,
                         join=True)
            r = json.loads(result.read_text())
            base = base or r['steps_per_s']
            print(f'| {n} | {r["backend"]} | {r["per_rank_batch"]} | {r["steps_per_s"]:.2f} | '
                  f'{r["images_per_s"]:.0f} | {r["steps_per_s"] / base:.2f}x |', flush=True)
    print(f'# loadavg after {os.getloadavg()}')


if __name__ == '__main__':
    main()
