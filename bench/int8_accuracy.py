"""What `--precision int8` costs in accuracy on real video (issue 38 item 3): the Pose2Sim
4-camera recording (bench/real.py's data, reference and scoring), one detector trained on a
few labelled instants, then `monet process` (commands.process.process_recording, as a user
runs it) in float32, bfloat16 (where native) and int8 (ONNX Runtime static QDQ quantisation
calibrated on the recording's crops of the run's crop mode, models.quantize and
monet_ros.int8_calibration), with tracked crops (the default) and full-frame crops
(`--no-track`: float32 and int8). Reported: each run's 2D detections and 3D against
float32's with the same crops (px, mm: median / p90 / max over the keypoints both give),
and each against Pose2Sim's reference on the unlabelled instants (3D median / mean / p90
mm, PCK@10 px). The synthetic-rig check is test/commands/test_process_int8.py.

    .venv/bin/python bench/int8_accuracy.py [--labels 6] [--steps 1000] [--work DIR]
"""
import argparse
import importlib.util
import os
from pathlib import Path
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def bench_real():
    spec = importlib.util.spec_from_file_location('bench_real', REPO / 'bench' / 'real.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module




def stats(values):
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if not v.size:
        return '–'
    return f'{np.median(v):.2f} / {np.percentile(v, 90):.2f} / {v.max():.2f}'


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--labels', type=int, default=6, help='labelled instants')
    parser.add_argument('--steps', type=int, default=1000)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--work', type=Path, default=Path('/tmp/monet-int8-accuracy'))
    parser.add_argument('--out', type=Path, default=REPO / 'bench' / 'results' /
                        'int8_accuracy.md')
    args = parser.parse_args(argv)
    import torch

    from monet_ros.commands.process import ProcessConfig
    from monet_ros.cores import cpu_model
    from monet_ros.learning.config import TrainConfig
    from monet_ros.learning.recording import load_recording
    from monet_ros.learning.trainer import Trainer, TrainingData
    from monet_ros.models import build_model, save_checkpoint
    from monet_ros.models.detector import bfloat16_native

    torch.set_num_threads(1)
    real = bench_real()
    root = real.default_data_root()
    bag = root / real.BAG
    load = os.getloadavg()
    print(f'# CPU: {cpu_model()}; load average at start '
          f'{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}', file=sys.stderr)
    recording = load_recording(bag, skeleton='human14')
    reference = real.load_reference(root, recording.keypoints)
    reference2d = real.project_reference(reference, recording.cameras)
    instants = real.choose_instants(recording.num_instants, args.labels, args.seed)
    unlabelled = np.setdiff1d(np.arange(recording.num_instants), instants)
    args.work.mkdir(parents=True, exist_ok=True)
    checkpoint = args.work / f'model-l{args.labels}-s{args.seed}-{args.steps}.pt'
    if not checkpoint.exists():
        rec = real.labelled_recording(recording, reference2d, instants)
        config = TrainConfig(mode='supervised', seed=args.seed, input_size=128,
                             steps=args.steps, checkpoint_every=10 ** 6, precision='float32')
        probe = build_model(config.architecture, rec.num_keypoints, **config.model_options())
        data = TrainingData(rec, config, probe.input_size, probe.heatmap_size)
        start = time.monotonic()
        trainer = Trainer(config, data, warn=lambda m: None)
        trainer.run(progress=False)
        save_checkpoint(checkpoint, trainer.model, trainer.metadata())
        print(f'trained {args.steps} steps in {time.monotonic() - start:.0f} s', file=sys.stderr)
    # (precision, tracked crops): each compared with float32 of the same crop mode
    runs = ([('float32', True)] + ([('bfloat16', True)] if bfloat16_native('cpu') else []) +
            [('int8', True), ('float32', False), ('int8', False)])
    got = {}
    for precision, track in runs:
        start = time.monotonic()
        options = {'precision': precision, 'config': ProcessConfig(track=track)}
        if precision == 'int8':
            # calibrated on the crops of the run (models.quantize): tracked or full frame
            options.update(backend='onnxruntime', calibration=bag)
        X, points, _ = real.process_path(bag, checkpoint, args.work / f'out-{precision}-'
                                         f'{track}-{time.time_ns()}', recording.stamps,
                                         recording.cameras, **options)
        got[precision, track] = (X, points)
        print(f'{precision} (tracked {track}): monet process in '
              f'{time.monotonic() - start:.0f} s', file=sys.stderr)
    lines = [
        '# `--precision int8` accuracy on real video (Pose2Sim 4-camera recording)', '',
        f'Command: `python bench/int8_accuracy.py {" ".join(argv or sys.argv[1:])}`; '
        f'{cpu_model()}, load average at the start '
        f'{load[0]:.2f}, at the end {os.getloadavg()[0]:.2f}. Detector: small net, input 128, '
        f'{args.steps} supervised steps on {args.labels} labelled instants (seed {args.seed}: '
        f'{instants.tolist()}), float32 training; scored on the {len(unlabelled)} unlabelled '
        'instants through `monet process` (fuse_heatmaps), with tracked crops (the default) '
        'and full-frame crops (`--no-track`); int8 calibrated on the crops of the run; each '
        'run against float32 with the same crops.', '',
        '| precision | crops | 2D vs float32 (px): median / p90 / max | 3D vs float32 (mm): '
        'median / p90 / max | 3D vs reference (mm): median / mean / p90 | PCK@10 px | '
        'triangulated |',
        '|---|---|---|---|---|---|---|']
    for precision, track in runs:
        X, points = got[precision, track]
        X0, p0 = got['float32', track]
        d2 = np.linalg.norm(points - p0, axis=-1)[unlabelled]
        d3 = np.linalg.norm(X - X0, axis=-1)[unlabelled] * 1000.0
        r = real.score(X, points, reference, reference2d, unlabelled)
        lines.append(f'| {precision} | {"tracked" if track else "full frame"} | {stats(d2)} | '
                     f'{stats(d3)} | {r["median_mm"]:.1f} / {r["mean_mm"]:.1f} / '
                     f'{r["p90_mm"]:.1f} | {100 * r["pck10"]:.1f}% | '
                     f'{r["triangulated"]:.0%} |')
    text = '\n'.join(lines) + '\n'
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
