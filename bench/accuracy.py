"""The paper's Table 1 and Figure 6 on synthetic recordings: all six modes, same step budget.

For each synthetic rig (`monet synth`: a moving human, 14 keypoints, <1% labelled instants):
  1. the recording is rendered once (seeded) and decoded into memory;
  2. the labels of each labelled instant are kept in --label-views views only (chosen with
     the seed; the paper's spatial augmentation needs unlabelled views), the contiguous tail
     (--eval-fraction) is held out: never trained on, never tracked into;
  3. every mode (supervised, spatial, spatiotemporal, bootstrap1, bootstrap2, monet) trains
     the same network from the same initialisation (seed) for the same number of steps,
     --jobs processes in parallel (forked after decoding, one torch thread each);
  4. each model is evaluated on the held-out instants (evaluation.evaluate_detector):
     reprojection error (all-view triangulation without RANSAC, mean +- std px vs the
     detections, and vs the ground truth) and PCK at 0.01..0.2 of the heatmap window.
Prints the table (rows = modes, columns = rigs) and writes results.md/.csv/.json and
pck_<rig>.png (Figure 6) under --out, with the wall time, seeds and configuration.

Forms (small net 64 px -> 16x16 heatmaps, width 24, Adam 1e-3, 3 labelled views per
labelled instant; rigs ring8 and dome6; wall times measured 2026-11-23 on the 2-core
development machine, quiet, 2 jobs, no GPU; figures in bench/results/accuracy.md):
  reduced (default): 240 instants, 2 labelled (0.83%), 300 steps per mode, seed 0
      .venv/bin/python bench/accuracy.py --out /tmp/monet_accuracy          # 2.0 min
  medium, several seeds and a third rig with only 4 cameras:
      .venv/bin/python bench/accuracy.py --out /tmp/acc_seeds --frames 600 --steps 1500 \
          --rigs ring8 dome6 ring4 --seeds 1 2                             # 23.6 min
  full: 1500 instants, 6 labelled (0.40%), 6000 steps per mode, seed 0
      .venv/bin/python bench/accuracy.py --full --out /tmp/monet_accuracy_full   # 29.8 min
Variants side by side: --set KEY=VALUE (any TrainConfig field) with --tag NAME --merge.
"""
import argparse
from concurrent.futures import ProcessPoolExecutor
import json
import multiprocessing
import os
from pathlib import Path
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from monet_ros.cli import main as monet_main  # noqa: E402
from monet_ros.evaluation import markdown_table, write_report  # noqa: E402
from monet_ros.evaluation.report import MODE_TITLES  # noqa: E402
from monet_ros.learning.config import MODES, TrainConfig  # noqa: E402

# Two rigs: different camera count, layout, image size and field of view (intrinsics).
RIGS = {
    'ring8': ['--cameras', '8', '--layout', 'ring', '--width', '320', '--height', '240',
              '--hfov', '60'],
    'dome6': ['--cameras', '6', '--layout', 'dome', '--width', '288', '--height', '224',
              '--hfov', '75'],
    # few views: RANSAC bootstrapping needs 3 agreeing views of 4, so it labels less
    'ring4': ['--cameras', '4', '--layout', 'ring', '--width', '320', '--height', '240',
              '--hfov', '60'],
}
DEFAULT_RIGS = ['ring8', 'dome6']
REDUCED = dict(frames=240, label_fraction=0.008, steps=300, seeds=[0],
               monet_bootstrap_rounds=2)
FULL = dict(frames=1500, label_fraction=0.004, steps=6000, seeds=[0],
            monet_bootstrap_rounds=2)

_DATA = {}          # rig -> TrainingData inputs, filled before forking


def synthesise(out, name, rig, frames, label_fraction, seed):
    folder = Path(out) / 'data' / name
    if not (folder / 'ground_truth.npz').exists():
        code = monet_main(['synth', '--out', str(folder), '--frames', str(frames),
                           '--label-fraction', str(label_fraction), '--seed', str(seed),
                           '--quiet', *RIGS[rig]])
        if code:
            raise SystemExit(f'monet synth failed for {rig}')
    return folder


def keep_label_views(recording, count, seed):
    """Keep the labels of `count` random views per labelled instant (0 = all views)."""
    if count <= 0:
        return []
    rng = np.random.default_rng(seed)
    kept = []
    for t in recording.labelled_instants:
        views = np.sort(rng.choice(recording.num_views, size=count, replace=False))
        drop = np.setdiff1d(np.arange(recording.num_views), views)
        recording.labels[t, drop] = np.nan
        kept.append([int(t), views.tolist()])
    return kept


def train_and_evaluate(job):
    """Worker: train one mode on one dataset, evaluate on the held-out tail -> summary JSON."""
    import torch

    from monet_ros.evaluation.evaluate import evaluate_detector
    from monet_ros.learning.trainer import Trainer, TrainingData
    from monet_ros.models import build_model
    from monet_ros.models.detector import Detector

    torch.set_num_threads(1)
    rig, config_dict, out, tag = job
    config = TrainConfig.from_dict(config_dict)
    recording = _DATA[rig]          # rig = the dataset name (rig, or rig-sSEED)
    probe = build_model(config.architecture, recording.num_keypoints, **config.model_options())
    data = TrainingData(recording, config, probe.input_size, probe.heatmap_size)
    start = time.monotonic()
    label = config.mode + (f'+{tag}' if tag else '')
    trainer = Trainer(config, data, Path(out) / 'runs' / rig / label)
    pseudo_initial = trainer.pseudo_label_count
    summary = trainer.run(progress=False)
    train_s = time.monotonic() - start
    detector = Detector(trainer.model, trainer.metadata(), device=trainer.device)
    result = evaluate_detector(detector, recording, data.held_out, data.boxes, label, rig)
    result.extra.update({'train_seconds': round(train_s, 1), 'steps': summary['steps'],
                         'pseudo_labels_initial': pseudo_initial,
                         'pseudo_labels_final': summary['pseudo_labels'],
                         # share of the unlabeled train views x keypoints pseudo-labelled
                         'pseudo_label_coverage': float(np.isfinite(
                             trainer.pseudo_only[data.unlabeled_instants, ..., 0]).mean()),
                         'seed': config.seed, 'eval_seconds':
                         round(time.monotonic() - start - train_s, 1),
                         'last_terms': summary['last'], 'config': config.to_dict()})
    print(f'[{rig} {label}] {summary["steps"]} steps in {train_s:.0f} s, '
          f'reproj {result.reprojection_mean:.2f} px, PCK@0.1 {result.pck.at(0.1):.3f}',
          file=sys.stderr, flush=True)
    return result.to_json()


def parse_overrides(pairs):
    """--set KEY=VALUE pairs -> dict of TrainConfig fields (values parsed as YAML scalars)."""
    import yaml

    known = set(TrainConfig.__dataclass_fields__)
    overrides = {}
    for pair in pairs:
        key, sep, value = pair.partition('=')
        if not sep or key not in known:
            raise SystemExit(f'--set {pair!r}: expected KEY=VALUE with KEY a TrainConfig field '
                             f'(one of {sorted(known)})')
        overrides[key] = yaml.safe_load(value)
    return overrides


def dataset_name(rig, seed, seeds):
    return rig if len(seeds) == 1 else f'{rig}-s{seed}'


def across_seeds(summaries, rigs, seeds):
    """Markdown: per rig and mode, mean ± std over seeds of the held-out figures, and how
    often each mode has the lowest reprojection error / highest PCK@0.1 of its seed."""
    cell = {(s.mode, s.dataset): s for s in summaries}
    present = {s.mode for s in summaries}
    modes = [m for m in MODES if m in present] + sorted(present - set(MODES))
    lines = []
    for rig in rigs:
        names = [dataset_name(rig, seed, seeds) for seed in seeds]
        complete = [n for n in names if all((m, n) in cell for m in modes)]
        if not complete:
            continue
        best_reproj = {n: min(modes, key=lambda m: cell[(m, n)].reprojection_mean)
                       for n in complete}
        best_pck = {n: max(modes, key=lambda m: cell[(m, n)].pck.at(0.1)) for n in complete}
        lines += [f'### {rig}: {len(complete)} seeds (mean ± std over seeds)', '',
                  '| Mode | reproj. (px) | vs GT (px) | 3D error (mm) | PCK@0.05 | PCK@0.1 '
                  '| PCK@0.2 | lowest reproj. | best PCK@0.1 | reproj. / MONET |',
                  '|---|---|---|---|---|---|---|---|---|---|']
        for m in modes:
            rows = [cell[(m, n)] for n in complete]

            def stat(values, fmt='.2f'):
                v = np.asarray(values, dtype=np.float64)
                return f'{v.mean():{fmt}} ± {v.std():{fmt}}'
            ratio = [cell[(m, n)].reprojection_mean / cell[('monet', n)].reprojection_mean
                     for n in complete] if 'monet' in modes else [np.nan]
            lines.append(
                f'| {MODE_TITLES.get(m, m)} | {stat([r.reprojection_mean for r in rows])} '
                f'| {stat([r.gt_reprojection_mean for r in rows])} '
                f'| {stat([1000 * r.extra["error3d_mean"] for r in rows], ".0f")} | '
                + ' | '.join(stat([r.pck.at(a) for r in rows], '.3f') for a in (0.05, 0.1, 0.2))
                + f' | {sum(best_reproj[n] == m for n in complete)}/{len(complete)} '
                f'| {sum(best_pck[n] == m for n in complete)}/{len(complete)} '
                f'| {stat(ratio)} |')
        lines.append('')
    return '\n'.join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', default='/tmp/monet_accuracy')
    parser.add_argument('--full', action='store_true', help='the full benchmark (long)')
    parser.add_argument('--rigs', nargs='+', default=DEFAULT_RIGS, choices=list(RIGS))
    parser.add_argument('--modes', nargs='+', default=list(MODES), choices=list(MODES))
    parser.add_argument('--steps', type=int, default=0, help='override the step budget')
    parser.add_argument('--frames', type=int, default=0, help='override the frame count')
    parser.add_argument('--label-fraction', type=float, default=0.0,
                        help='override the labelled share of the instants')
    parser.add_argument('--label-views', type=int, default=3,
                        help='labelled views per labelled instant (0 = all)')
    parser.add_argument('--seeds', nargs='+', type=int, default=None,
                        help="seeds (scene, labels, initialisation); default: the preset's")
    parser.add_argument('--jobs', type=int, default=2, help='parallel training processes')
    parser.add_argument('--input-size', type=int, default=64)
    parser.add_argument('--width', type=int, default=24)
    parser.add_argument('--lr', type=float, default=1e-3)
    parser.add_argument('--device', default='auto')
    parser.add_argument('--monet-bootstrap-rounds', type=int, default=None,
                        help='monet: bootstrapping rounds feeding L_B (0 = spatial only); '
                        "default: the preset's")
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE', help='any TrainConfig field, for every mode')
    parser.add_argument('--tag', default='',
                        help='suffix of the mode names (rows "MODE+TAG"): variants side by side '
                        'with --merge')
    parser.add_argument('--merge', action='store_true',
                        help='keep the (mode, dataset) results of OUT/results.json not rerun now')
    args = parser.parse_args(argv)
    preset = dict(FULL if args.full else REDUCED)
    for key in ('steps', 'frames', 'label_fraction'):
        if getattr(args, key):
            preset[key] = getattr(args, key)
    seeds = args.seeds if args.seeds is not None else preset['seeds']
    rounds = args.monet_bootstrap_rounds
    rounds = preset['monet_bootstrap_rounds'] if rounds is None else rounds
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    wall = time.monotonic()

    from monet_ros.learning.recording import load_recording

    setup = {}
    for seed in seeds:
        for rig in args.rigs:
            name = dataset_name(rig, seed, seeds)
            folder = synthesise(out, name, rig, preset['frames'], preset['label_fraction'],
                                seed)
            recording = load_recording(folder, name=name)
            labelled_all = recording.labelled_instants.tolist()
            kept = keep_label_views(recording, args.label_views, seed)
            _DATA[name] = recording
            setup[name] = {'folder': str(folder), 'seed': seed,
                           'instants': recording.num_instants, 'views': recording.num_views,
                           'labelled_instants': labelled_all,
                           'labelled_fraction': len(labelled_all) / recording.num_instants,
                           'label_views_kept': kept}
            share = 100 * len(labelled_all) / recording.num_instants
            print(f'{name}: {recording.num_instants} instants x {recording.num_views} views, '
                  f'labelled instants {labelled_all} ({share:.2f}%)', file=sys.stderr)
    base = dict(architecture='small', input_size=args.input_size, width=args.width,
                steps=preset['steps'], checkpoint_every=preset['steps'], lr=args.lr,
                device=args.device, monet_bootstrap_rounds=rounds, eval_fraction=0.2)
    base.update(parse_overrides(args.overrides))
    jobs = [(name, TrainConfig(mode=mode, **dict(base, seed=setup[name]['seed'])).to_dict(),
             str(out), args.tag) for name in setup for mode in args.modes]
    context = multiprocessing.get_context('fork')
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=context) as pool:
        results = list(pool.map(train_and_evaluate, jobs))
    from monet_ros.evaluation import EvalSummary
    summaries = [EvalSummary.from_json(r) for r in results]
    previous = out / 'results.json'
    if args.merge and previous.exists():
        from monet_ros.evaluation import load_summaries
        rerun = {(s.mode, s.dataset) for s in summaries}
        summaries = [s for s in load_summaries(previous)
                     if (s.mode, s.dataset) not in rerun] + summaries
    wall = time.monotonic() - wall
    paths = write_report(out, summaries, name='results')
    print(markdown_table(summaries))
    print('| dataset | mode | reproj. vs detections (px) | reproj. vs GT (px) | 3D error (m) '
          '| PCK@0.05 | PCK@0.1 | PCK@0.2 | pseudo-labelled | train s |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for s in summaries:
        e = s.extra
        print(f'| {s.dataset} | {s.mode} | {s.reprojection_mean:.2f} ± {s.reprojection_std:.2f} '
              f'| {s.gt_reprojection_mean:.2f} ± {s.gt_reprojection_std:.2f} '
              f'| {e["error3d_mean"]:.3f} | {s.pck.at(0.05):.3f} | {s.pck.at(0.1):.3f} '
              f'| {s.pck.at(0.2):.3f} | {100 * e.get("pseudo_label_coverage", 0):.0f}% '
              f'| {e["train_seconds"]:.0f} |')
    if len(seeds) > 1:
        aggregate = across_seeds(summaries, args.rigs, seeds)
        (out / 'across_seeds.md').write_text(aggregate)
        print('\n' + aggregate)
    command = 'bench/accuracy.py ' + ' '.join(sys.argv[1:] if argv is None else argv)
    meta = {'command': command, 'wall_seconds': round(wall, 1), 'preset': preset,
            'label_views': args.label_views, 'seeds': seeds, 'jobs': args.jobs,
            'config': base, 'datasets': setup, 'cpu_count': os.cpu_count(),
            'load_average': os.getloadavg()}
    (out / 'bench_meta.json').write_text(json.dumps(meta, indent=1))
    print(f'\nwall time {wall:.0f} s ({args.jobs} jobs, load average '
          f'{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores); seeds {seeds}; '
          f'written {", ".join(str(p) for p in paths.values())}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
