"""Online learner: training steps/s, and accuracy over time of online learning.

1. Steps/s of OnlineLearner.step (small net, all 8 views of an instant in L_E, CPU; CUDA
   too when present), --mode (default: the learner's default, reprojection; the figures
   below are of mode monet, L_L + lambda_e L_E + lambda_p L_B) side by side with supervised
   (L_L only, the baseline), median of --repeats runs of --steps steps.
2. Over time: a starting model trained with labels only (mode supervised, Trainer,
   --start-steps, with the learner's validation split: it never sees the held-out labels)
   on a synthetic 8-camera rig; then --minutes of online learning (OnlineLearner, --mode,
   a checkpoint every --every steps, announced by the learner's own criterion:
   publish_metric auto = the mean error on the held-out validation labels,
   --validation-labels of the labelled instants) and, beside it, the same minutes of
   supervised training continued from the same start (the baseline, checkpoints every
   --every x --supervised-every-factor steps). Every checkpoint (kept, announced or not)
   is then evaluated on the held-out tail on the path the live pipeline runs
   (models.Detector -> fusion.fuse_heatmaps, robust triangulation): the 3D error of the
   fused keypoints against the ground truth (mm) and their reprojection error (px); plus
   evaluation.evaluate_detector (2D error of the detections against the projected ground
   truth, px; PCK@0.1). The table (timeline.md), a PNG (timeline.png: 3D, 2D, held-out
   labelled, reprojection error over time; filled = announced) and results.json go to
   --out; the rank correlation of each criterion with the 3D error over the checkpoints
   is printed. Without ground truth (--data of a real recording) the ground-truth columns
   are empty and the held-out labelled error is the accuracy figure.

    .venv/bin/python bench/learner.py --out /tmp/monet_learner_bench [--minutes 2]

Data: --data DIR (a `monet synth` folder), else `monet synth` (ring, 8 cameras, 14
keypoints, --label-fraction 0.04 = 6 labelled instants, 2 of them held out) when the
command exists, else the test suite's 8-camera blob scene.

Measured 2026-12-02 (bench/results/learner.md, --minutes 2 --every 40 --eval-stride 1, load
0.9-2.5), --mode reprojection (the learner's default): start 236 mm; the last announced model
173 mm (-27%), 2D 9.48 px; supervised continued from the same start 215 mm, 10.82 px; rank
correlation of the held-out labelled error with the 3D error +0.82 (reprojection error +0.47).
Steps/s (8 views, 1 thread): supervised 23.4, reprojection 22.4.

Measured 2026-12-01 on the shared 2-core CPU machine (the lead's and other helpers' jobs
running: load average 5.1 at the start, 8.0 at the end; no GPU used), `monet synth --frames
150 --cameras 8 --layout ring --width 320 --height 240 --label-fraction 0.04 --seed 0` (6
labelled instants: 4 trained on, 2 held out = instants 65 and 140), --start-steps 400
--minutes 2 --every 40 --eval-stride 1, wall 310 s (a short run: one seed, one start; the
3D error moves by +-25 mm between neighbouring checkpoints):
    steps/s (8 views, 1 torch thread): supervised 14.9, monet 14.3
    start (labels only): 3D 244 mm, 2D vs ground truth 12.1 px, held-out labelled 11.5 px,
      reprojection 8.8 px
    2 min monet, last announced (labelled criterion, step 920 of 1120): 3D 205 mm, 2D 10.8
      px, held-out labelled 9.0 px, reprojection 5.7 px
      - the reprojection criterion replayed on the same checkpoints would have stopped at
        step 160: 3D 262 mm (worse than the start), 2D 12.1 px, reprojection 5.5 px
    2 min supervised, last announced (step 600 of 1080): 3D 213 mm, 2D 10.9 px, held-out
      labelled 9.9 px, reprojection 7.4 px (reprojection criterion: step 1080, 214 mm)
    rank correlation with the 3D error over the checkpoints: held-out labelled +0.83
      (monet, 29), +0.93 (supervised, 10); reprojection +0.04 (monet), +0.56 (supervised)
  The views agree better under monet from the first checkpoints (8.8 -> 5.5 px) while the
  3D error first rises; the held-out labelled error follows the 3D error, the reprojection
  error does not.
"""
import argparse
from dataclasses import fields
import json
import os
from pathlib import Path
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / 'test'))

import torch  # noqa: E402

from monet_ros.cli import SUBCOMMANDS  # noqa: E402
from monet_ros.cli import main as monet_main  # noqa: E402
from monet_ros.evaluation.evaluate import evaluate_detector  # noqa: E402
from monet_ros.fusion import FusionConfig, fuse_heatmaps  # noqa: E402
from monet_ros.learning.config import MODES, TrainConfig  # noqa: E402
from monet_ros.learning.online import LearnerConfig, OnlineLearner, should_publish  # noqa: E402
from monet_ros.learning.trainer import Trainer, TrainingData  # noqa: E402
from monet_ros.models import Detector, build_model, load_checkpoint  # noqa: E402

LEARNER_MODE = next(f.default for f in fields(LearnerConfig) if f.name == 'mode')
SMALL = dict(architecture='small', input_size=96, width=24)
BATCH = dict(batch_labelled=8, batch_pseudo=8, batch_unlabeled=1, lr=1e-3, eval_fraction=0.2,
             sigma=1.5)


def make_data(args):
    """A `monet synth` folder (8 cameras) or the blob scene written as one."""
    if args.data:
        return Path(args.data), 'human14'
    folder = Path(args.out) / 'data'
    if 'synth' in SUBCOMMANDS:
        if not (folder / 'ground_truth.npz').exists():
            code = monet_main(['synth', '--out', str(folder), '--frames', str(args.frames),
                               '--cameras', '8', '--layout', 'ring', '--width', '320',
                               '--height', '240', '--label-fraction',
                               str(args.label_fraction), '--seed', '0',
                               '--quiet'])
            if code:
                raise SystemExit('monet synth failed')
        return folder, 'human14'
    from helpers.blob_bag import write_blob_folder
    from helpers.blobs import blob_recording
    if not (folder / 'ground_truth.npz').exists():
        T = args.frames
        rec = blob_recording(num_views=8, T=T, C=6, labelled=(T // 10, T // 2), seed=0,
                             label_views=(0, 1, 2), width=160, height=120, focal=180.0)
        write_blob_folder(rec, folder)
    skeleton = Path(args.out) / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2, k3, k4, k5]\n')
    return folder, str(skeleton)


def steps_per_s(folder, skeleton, mode, device, steps, repeats, out):
    """Median steps/s of OnlineLearner.step over `repeats` runs (after 3 warm-up steps)."""
    config = LearnerConfig(bags=(str(folder),), out=str(out), skeleton=skeleton, mode=mode,
                           views_per_instant=8, device=device, resume=False,
                           checkpoint_every=10 ** 6, **SMALL, **BATCH)
    learner = OnlineLearner(config, log=lambda *a: None)
    for _ in range(3):
        learner.step()
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            learner.step()
        if device.startswith('cuda'):
            torch.cuda.synchronize()
        rates.append(steps / (time.perf_counter() - start))
    return float(np.median(rates)), learner.recording


def fused_errors(checkpoint, data, instants, fusion=None):
    """The live core over held-out instants: Detector -> fuse_heatmaps.

    Returns (mean reprojection error of the fused keypoints px, mean 3D error mm vs ground
    truth, fraction of keypoints triangulated)."""
    fusion = fusion or FusionConfig()
    detector = Detector(*load_checkpoint(checkpoint), device='cpu')
    rec, cams = data.recording, data.recording.cameras
    reproj, err3d, ok = [], [], []
    for t in instants:
        boxes = detector.boxes_for(cams, data.boxes[t])
        heat, heat_cams = detector.predict(rec.images(int(t)), cams, boxes,
                                           keep_aspect=False)
        result = fuse_heatmaps(heat, np.stack([c.K for c in heat_cams]), cams, fusion)
        reproj.append(result.reprojection_error)
        ok.append(np.isfinite(result.X[:, 0]))
        if rec.gt3d is not None:
            err3d.append(np.linalg.norm(result.X - rec.gt3d[t], axis=1) * 1e3)
    reproj, ok = np.concatenate(reproj), np.concatenate(ok)
    e3 = np.concatenate(err3d) if err3d else np.array([np.nan])
    return float(np.nanmean(reproj)), float(np.nanmean(e3)), float(ok.mean())


def evaluate(checkpoint, data, label, instants):
    """Ground-truth figures of a checkpoint on `instants`: the live core's fused keypoints
    (fused_reproj_px, fused_3d_mm, triangulated) and evaluation.evaluate_detector (gt_2d_px:
    detections vs projected ground truth; pck@0.1; gt_reproj_px). n/a without ground truth
    (real data: the held-out labelled error is then the accuracy figure)."""
    model, meta = load_checkpoint(checkpoint)
    fused_px, fused_mm, fraction = fused_errors(checkpoint, data, instants)
    row = {'fused_reproj_px': fused_px, 'triangulated': fraction,
           'fused_3d_mm': fused_mm if data.recording.gt3d is not None else None}
    if data.recording.gt3d is not None:
        summary = evaluate_detector(Detector(model, meta, device='cpu'), data.recording,
                                    instants, data.boxes, mode=label)
        row.update({'gt_2d_px': summary.extra['error2d_mean'],
                    'gt_reproj_px': summary.gt_reprojection_mean,
                    'pck@0.1': summary.pck.at(0.1)})
    return row


def online(folder, skeleton, start, out, mode, minutes, every, device, validation):
    """Run OnlineLearner for `minutes` from `start`, keeping every checkpoint; print each
    one live. Returns (learner, timeline rows: t_s, step, checkpoint path, the learner's own
    metrics and verdict)."""
    config = LearnerConfig(bags=(str(folder),), out=str(out), skeleton=skeleton, model=str(start),
                           mode=mode, views_per_instant=8, checkpoint_every=every,
                           device=device, resume=False, validate_instants=16,
                           keep_checkpoints=0, validation_labels=validation, **SMALL, **BATCH)
    learner = OnlineLearner(config, log=lambda *a: None)
    s = learner.start_metrics
    timeline = [{'mode': mode, 't_s': 0.0, 'step': 0, 'path': str(start), 'announced': 'start',
                 'labelled_px': s.get('labelled_mean_px'),
                 'labelled_median_px': s.get('labelled_median_px'),
                 'reproj_px': s.get('reprojection_px')}]
    print(f'  [{mode}] start: held-out labelled {_px(s.get("labelled_mean_px"))} px, held-out '
          f'reprojection {_px(s.get("reprojection_px"))} px; announcing on {learner.metric}',
          flush=True)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 60 * minutes:
        learner.step()
        result = learner.checkpoint_due()
        if result is None:
            continue
        m = result.metrics
        timeline.append({'mode': mode, 't_s': time.monotonic() - t0, 'step': result.step,
                         'path': result.path, 'announced': 'yes' if result.published else 'no',
                         'labelled_px': m.get('labelled_mean_px'),
                         'labelled_median_px': m.get('labelled_median_px'),
                         'reproj_px': m.get('reprojection_px')})
        print(f'  [{mode}] {timeline[-1]["t_s"]:6.0f} s  step {result.step:5d}  '
              f'{"announced" if result.published else "kept back"}: {result.reason}',
              flush=True)
    return learner, timeline


def replay_criteria(timeline, tolerance_px=0.0):
    """{(mode, criterion): the timeline row of the model each criterion would have announced
    last}: online.should_publish replayed over every checkpoint of each mode, with
    the labelled (labelled_px) and the reprojection (reproj_px) criterion."""
    out = {}
    for mode in dict.fromkeys(r['mode'] for r in timeline):
        rows = [r for r in timeline if r['mode'] == mode]
        for name, key, metric in (('labelled', 'labelled_px', 'labelled_mean_px'),
                                  ('reprojection', 'reproj_px', 'reprojection_px')):
            last = rows[0]
            for row in rows[1:]:
                if should_publish({metric: row[key]}, last[key], tolerance_px, metric)[0]:
                    last = row
            out[mode, name] = last
    return out


def _px(value):
    return 'n/a' if value is None else f'{value:.2f}'


def plot_timeline(rows, path):
    """4 panels over time of online learning (s): 3D error vs ground truth (mm), 2D error vs
    ground truth (px), held-out labelled error (px), held-out reprojection error (px); one
    line per mode, filled markers = announced (or the start), hollow = kept back."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    panels = [('fused_3d_mm', '3D error vs ground truth (mm, live core)'),
              ('gt_2d_px', '2D error vs ground truth (px)'),
              ('labelled_px', 'held-out labelled error (px, mean)'),
              ('reproj_px', 'held-out reprojection error (px)')]
    fig, axes = plt.subplots(1, 4, figsize=(18, 4))
    for ax, (key, title) in zip(axes, panels):
        for mode, colour in zip(dict.fromkeys(r['mode'] for r in rows), ('C0', 'C1')):
            pts = [(r['t_s'], r[key], r['announced']) for r in rows
                   if r['mode'] == mode and r.get(key) is not None]
            if not pts:
                continue
            ax.plot([p[0] for p in pts], [p[1] for p in pts], '-', color=colour, label=mode)
            for t, v, a in pts:
                ax.plot(t, v, 'o', color=colour, mfc=colour if a != 'no' else 'white')
        ax.set(xlabel='online learning time (s)', title=title)
    axes[0].legend()
    fig.suptitle('online learning from one start; filled = announced, hollow = kept back')
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def table(rows, columns):
    widths = {c: max(len(c), *(len(fmt(r.get(c))) for r in rows)) for c in columns}
    lines = ['  '.join(c.ljust(widths[c]) for c in columns)]
    for r in rows:
        lines.append('  '.join(fmt(r.get(c)).ljust(widths[c]) for c in columns))
    return '\n'.join(lines)


def fmt(value):
    if isinstance(value, float):
        return f'{value:.3f}'
    return '' if value is None else str(value)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', default='/tmp/monet_learner_bench')
    parser.add_argument('--data', help='a `monet synth` folder with 8 cameras')
    parser.add_argument('--frames', type=int, default=150)
    parser.add_argument('--steps', type=int, default=10, help='steps per speed run')
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--start-steps', type=int, default=400,
                        help='supervised steps of the starting model')
    parser.add_argument('--minutes', type=float, default=3.0, help='online learning time')
    parser.add_argument('--every', type=int, default=25, help='steps between checkpoints')
    parser.add_argument('--threads', type=int, default=1)
    parser.add_argument('--label-fraction', type=float, default=0.04,
                        help='monet synth: fraction of labelled instants (some are held out)')
    parser.add_argument('--validation-labels', type=float, default=0.34,
                        help="LearnerConfig.validation_labels (and the start model's)")
    parser.add_argument('--supervised-every-factor', type=int, default=3,
                        help='the supervised run checkpoints every --every x this steps '
                        '(it steps about 3x faster)')
    parser.add_argument('--mode', default=LEARNER_MODE, choices=MODES,
                        help="the online learner's mode (default: the learner's default, "
                        'LearnerConfig.mode)')
    parser.add_argument('--eval-stride', type=int, default=2,
                        help='evaluate every checkpoint on every n-th held-out instant')
    args = parser.parse_args()
    args.load_at_start = [round(x, 2) for x in os.getloadavg()]
    torch.set_num_threads(args.threads)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    wall = time.monotonic()
    folder, skeleton = make_data(args)
    print(f'data: {folder} (skeleton {skeleton}); torch threads {args.threads}; machine shared '
          f'with other jobs (2 cores): figures are indicative; load average '
          f'{args.load_at_start}', flush=True)

    devices = ['cpu'] + (['cuda'] if torch.cuda.is_available() else [])
    speed = []
    for device in devices:
        for mode in ('supervised', args.mode):
            rate, rec = steps_per_s(folder, skeleton, mode, device, args.steps, args.repeats,
                                    out / f'speed_{mode}_{device}')
            speed.append({'device': device, 'mode': mode, 'views': rec.num_views,
                          'image': f'{rec.cameras[0].width}x{rec.cameras[0].height}',
                          'steps_per_s': rate})
    print('\n1. training steps/s (median of %d x %d steps; small net %dpx, batch 8 '
          'labelled + 8 pseudo + 1 instant x 8 views)' % (args.repeats, args.steps,
                                                           SMALL['input_size']))
    print(table(speed, ['device', 'mode', 'views', 'image', 'steps_per_s']), flush=True)

    # 2. labels-only start, then online learning vs continued supervised training; the
    # start is trained with the learner's validation split (it never sees those labels)
    from monet_ros.learning.recording import load_recording
    from monet_ros.skeleton import load_skeleton
    keypoints = load_skeleton(skeleton).keypoints
    recording = load_recording(folder, skeleton=list(keypoints))
    cfg = TrainConfig(mode='supervised', steps=args.start_steps, checkpoint_every=10 ** 6,
                      device='cpu', validation_labels=args.validation_labels,
                      **{**SMALL, **BATCH})
    start_dir = out / 'start'
    start = start_dir / 'model.pt'
    probe = build_model('small', len(keypoints), **cfg.model_options())
    data = TrainingData(recording, cfg, probe.input_size, probe.heatmap_size)
    if not start.exists():
        t = time.monotonic()
        Trainer(cfg, data, start_dir).run(progress=False)
        print(f'\nstarting model: {args.start_steps} supervised steps (labels only) in '
              f'{time.monotonic() - t:.0f} s', flush=True)
    print(f'labelled instants: {len(data.labelled_instants)} trained on, '
          f'{len(data.validation_instants)} held out for validation '
          f'({list(map(int, data.validation_instants))}); held-out tail '
          f'{len(data.held_out)} instants', flush=True)
    timeline = []
    for mode in (args.mode, 'supervised'):
        every = args.every if mode == args.mode else args.every * args.supervised_every_factor
        print(f'\n{args.minutes:g} min of online learning, mode {mode} (checkpoint every '
              f'{every} steps):', flush=True)
        learner, rows = online(folder, skeleton, start, out / f'online_{mode}', mode,
                               args.minutes, every, 'cpu', args.validation_labels)
        np.testing.assert_array_equal(learner.data.validation_instants,
                                      data.validation_instants)
        timeline += rows
    # every checkpoint on the live path (models.Detector -> fusion) against the ground truth
    t = time.monotonic()
    sample = data.held_out[::args.eval_stride]
    for row in timeline:
        row.update(evaluate(row['path'], data, row['mode'], sample))
    print(f'\nevaluated {len(timeline)} checkpoints on {len(sample)} held-out instants in '
          f'{time.monotonic() - t:.0f} s', flush=True)
    columns = ['mode', 't_s', 'step', 'announced', 'fused_3d_mm', 'gt_2d_px', 'labelled_px',
               'reproj_px', 'fused_reproj_px', 'pck@0.1']
    print(f'\n2. over time of online learning (held-out tail: {len(sample)} instants x '
          f'{recording.num_views} views vs ground truth; held-out labelled: '
          f'{len(data.validation_instants)} instants; reproj: Trainer.validate)')
    text = table(timeline, columns)
    print(text)
    for mode in (args.mode, 'supervised'):
        rows = [r for r in timeline if r['mode'] == mode]
        last = [r for r in rows if r['announced'] in ('yes', 'start')][-1]
        print(f'  {mode}: announced by the learner at the end: step {last["step"]}, 3D '
              f'{_px(last.get("fused_3d_mm"))} mm (start {_px(rows[0].get("fused_3d_mm"))}), '
              f'held-out labelled {_px(last["labelled_px"])} px, reprojection '
              f'{_px(last["reproj_px"])} px')
        assert replay_criteria(rows)[mode, 'labelled'] is last       # the same criterion
    for (mode, name), row in replay_criteria(timeline).items():
        print(f'  {mode}, announcing on {name}: last announced step {row["step"]}, 3D '
              f'{_px(row.get("fused_3d_mm"))} mm, 2D vs ground truth {_px(row.get("gt_2d_px"))} '
              f'px, held-out labelled {_px(row["labelled_px"])} px, reprojection '
              f'{_px(row["reproj_px"])} px')
    if all(r.get('fused_3d_mm') is not None for r in timeline):
        from scipy.stats import spearmanr
        for mode in (args.mode, 'supervised', 'both'):
            rows = [r for r in timeline if mode in ('both', r['mode'])
                    and not (mode == 'both' and r['mode'] == 'supervised' and r['step'] == 0)]
            y = [r['fused_3d_mm'] for r in rows]
            rho = {k: spearmanr([r[k] for r in rows], y)[0] for k in ('labelled_px', 'reproj_px')}
            print(f'  rank correlation with the 3D error over the {len(rows)} checkpoints of '
                  f'{mode}: held-out labelled {rho["labelled_px"]:+.2f}, reprojection '
                  f'{rho["reproj_px"]:+.2f}')
    load = os.getloadavg()
    print(f'\nload average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (at start '
          f'{args.load_at_start})')
    (out / 'timeline.md').write_text(text + '\n')
    plot_timeline(timeline, out / 'timeline.png')
    (out / 'results.json').write_text(json.dumps(
        {'speed': speed, 'timeline': timeline, 'load_start': args.load_at_start,
         'load_end': load, 'args': vars(args) | {'out': str(args.out)}}, indent=1,
        default=str))
    print(f'wall time {time.monotonic() - wall:.0f} s; {out / "timeline.md"}, '
          f'{out / "timeline.png"}, {out / "results.json"}')

if __name__ == '__main__':
    main()
