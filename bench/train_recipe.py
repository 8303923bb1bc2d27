"""The CPU training recipe (issue 22, item 5): Trainer.step speed at 128 and 256 px, float32
against bfloat16 (TrainConfig.precision), then the accuracy of a float32- and a
bfloat16-trained model, side by side in one run. Never asserts; prints markdown tables.

    .venv/bin/python bench/train_recipe.py --out /tmp/recipe
        [--threads 1] [--sizes 128 256] [--steps 10] [--repeats 3]
        [--accuracy-steps 300] [--accuracy-size 128] [--rig ring6ho] [--skip-accuracy]

1. Speed: a `monet synth` recording (4 cameras 320x240, 90 frames: the `make demo` one), the
   small net (width 48, the default) in supervised mode with the default batch (8 labelled +
   8 pseudo-labelled + 2 unlabelled instants x 4 views = 24 crops per step, all labelled in
   supervised mode); one Trainer per (input size, precision), 2 warm-up steps, then
   --repeats timed runs of --steps Trainer.step calls each, the precisions interleaved (a
   load change hits both); steps/s is the median of the runs. The load average is printed
   before and after: on a shared machine the figures are noisy, compare the ratio.
2. Accuracy: bench/accuracy.py, unchanged, run twice on one synthetic rig (default ring6ho,
   300 instants, 2% labelled: 5 labelled instants trained, labels in 3 views each, as in
   bench/results/accuracy.md), supervised, --accuracy-steps steps at --accuracy-size px, the
   small net at its default width 48 and sigma 2 heatmap px (`monet train`'s defaults):
   float32, then `--set precision=bfloat16 --tag bf16 --merge`. Both models are scored the
   same way (float32 inference, tracked crops on the held-out tail, against the ground
   truth); its own tables go to stderr, its files to OUT/accuracy.

torch threads: --threads (1 = the fastest on a busy 2-core machine; 2 for a quiet one).
"""
import argparse
import contextlib
import os
from pathlib import Path
import sys
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / 'bench'))

import accuracy  # noqa: E402  (bench/accuracy.py: main, value, RIGS)
import numpy as np  # noqa: E402
import torch  # noqa: E402

PRECISIONS = ('float32', 'bfloat16')
# the `make demo` recording (README, bench/results/recipe.md)
DEMO = ['--cameras', '4', '--frames', '90', '--width', '320', '--height', '240',
        '--label-fraction', '0.034', '--distinct-sides', '--seed', '0', '--quiet']


def load():
    return ' '.join(f'{x:.2f}' for x in os.getloadavg())


def demo_recording(out):
    from monet_ros.cli import main as monet_main
    from monet_ros.learning.recording import load_recording

    folder = Path(out) / 'demo'
    if not (folder / 'ground_truth.npz').exists():
        with contextlib.redirect_stdout(sys.stderr):
            code = monet_main(['synth', '--out', str(folder), *DEMO])
        if code:
            raise SystemExit('train_recipe: monet synth failed')
    return load_recording(folder)


def speed(recording, sizes, precisions, steps, repeats):
    """{(size, precision): [steps/s of each timed run]} and the crops per step."""
    from monet_ros.learning.config import TrainConfig
    from monet_ros.learning.trainer import Trainer, TrainingData

    rates, crops = {}, None
    for size in sizes:
        trainers = {}
        data = None
        for precision in precisions:
            config = TrainConfig(mode='supervised', architecture='small', input_size=size,
                                 precision=precision, device='cpu', steps=10 ** 6,
                                 checkpoint_every=10 ** 6)
            if data is None:       # crops and tracks do not depend on the precision
                data = TrainingData(recording, config, (size, size), (size // 4, size // 4))
            trainers[precision] = Trainer(config, data, warn=lambda message: None)
            for _ in range(2):                                            # warm-up
                trainers[precision].step()
            crops = sum(len(p[1]) for p in trainers[precision].last_plan)
        for _ in range(repeats):
            for precision, trainer in trainers.items():
                start = time.perf_counter()
                for _ in range(steps):
                    trainer.step()
                rates.setdefault((size, precision), []).append(
                    steps / (time.perf_counter() - start))
        print(f'# {size} px done, load {load()}', file=sys.stderr, flush=True)
    return rates, crops


def speed_table(rates, crops, steps, repeats):
    lines = [f'| input | precision | steps/s (median of {repeats} x {steps}) | runs | '
             'images/s | vs float32 |', '|---|---|---|---|---|---|']
    for (size, precision), runs in rates.items():
        median = float(np.median(runs))
        base = float(np.median(rates.get((size, 'float32'), runs)))
        lines.append(f'| {size} px | {precision} | {median:.2f} | '
                     f'{" ".join(f"{r:.2f}" for r in runs)} | {median * crops:.0f} | '
                     f'{median / base:.2f}x |')
    return '\n'.join(lines)


def accuracy_runs(out, rig, steps, size):
    """bench/accuracy.py twice (float32; bfloat16 merged beside it) -> EvalSummary list."""
    from monet_ros.evaluation import load_summaries

    common = ['--out', str(out), '--rigs', rig, '--frames', '300', '--label-fraction', '0.02',
              '--modes', 'supervised', '--steps', str(steps), '--input-size', str(size),
              '--sigma', '2', '--width', '48', '--jobs', '1', '--device', 'cpu']
    for extra in ([], ['--set', 'precision=bfloat16', '--tag', 'bf16', '--merge']):
        print(f'# bench/accuracy.py {" ".join(common + extra)}', file=sys.stderr, flush=True)
        with contextlib.redirect_stdout(sys.stderr):
            code = accuracy.main(common + extra)
        if code:
            raise SystemExit('train_recipe: bench/accuracy.py failed')
    return load_summaries(Path(out) / 'results.json')


def accuracy_table(summaries):
    lines = ['| precision | train s | steps/s in training | fit on labels (heat px) | '
             '2D err. (px) | 2D med. (px) | PCK@0.1 | 3D err. (mm) | 3D med. (mm) |',
             '|---|---|---|---|---|---|---|---|---|']
    for s in summaries:
        e = s.extra
        precision = e['config']['precision']
        fit = (e.get('fit') or {}).get('median_heat', float('nan'))
        lines.append(f'| {precision} | {e["train_seconds"]:.0f} | '
                     f'{e["steps"] / max(e["train_seconds"], 1e-9):.2f} | {fit:.2f} | '
                     f'{accuracy.value(s, "error2d_mean"):.2f} | '
                     f'{accuracy.value(s, "error2d_median"):.2f} | '
                     f'{accuracy.value(s, "pck@0.1"):.3f} | '
                     f'{accuracy.value(s, "error3d_mm"):.0f} | '
                     f'{accuracy.value(s, "error3d_median_mm"):.0f} |')
    return '\n'.join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', default='/tmp/monet_train_recipe')
    parser.add_argument('--threads', type=int, default=1, help='torch CPU threads')
    parser.add_argument('--sizes', type=int, nargs='+', default=[128, 256],
                        help='network input sides (px) of the speed table')
    parser.add_argument('--steps', type=int, default=10, help='timed steps per run')
    parser.add_argument('--repeats', type=int, default=3, help='timed runs (median)')
    parser.add_argument('--accuracy-steps', type=int, default=300,
                        help='training steps of each accuracy run')
    parser.add_argument('--accuracy-size', type=int, default=128,
                        help='network input side (px) of the accuracy runs')
    parser.add_argument('--rig', default='ring6ho', choices=list(accuracy.RIGS),
                        help="bench/accuracy.py's rig for the accuracy runs")
    parser.add_argument('--skip-accuracy', action='store_true', help='the speed table only')
    args = parser.parse_args(argv)
    from monet_ros.models.detector import bfloat16_native

    torch.set_num_threads(args.threads)
    precisions = PRECISIONS if bfloat16_native('cpu') else PRECISIONS[:1]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = 'bench/train_recipe.py ' + ' '.join(sys.argv[1:] if argv is None else argv)
    print(f'# `{command}`: torch {torch.__version__}, {args.threads} thread(s), '
          f'{os.cpu_count()} cores, bfloat16 native on this CPU: {bfloat16_native("cpu")}; '
          f'load average {load()}\n')
    rates, crops = speed(demo_recording(out), args.sizes, precisions, args.steps,
                         args.repeats)
    print(f'## Trainer.step on CPU: small net, supervised, {crops} crops per step\n')
    print(speed_table(rates, crops, args.steps, args.repeats))
    print(f'\nload average after the speed runs: {load()}\n')
    if args.skip_accuracy or len(precisions) == 1:
        return 0
    start = time.monotonic()
    summaries = accuracy_runs(out / 'accuracy', args.rig, args.accuracy_steps,
                              args.accuracy_size)
    print(f'\n## Accuracy: {args.rig}, supervised, {args.accuracy_steps} steps at '
          f'{args.accuracy_size} px (bench/accuracy.py; held-out tail, tracked crops, float32 '
          'inference for both)\n')
    print(accuracy_table(summaries))
    print(f'\naccuracy runs: {time.monotonic() - start:.0f} s wall; load average after: '
          f'{load()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
