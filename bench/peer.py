"""A peer on the same labels: sleap-nn against our detector, side by side in one run.

Issue 36 item 4. The data, labels and scoring are bench/real.py's, by import: the 4-camera
Pose2Sim recording (../shared/data/derived_pose2sim_4cam_mcap, 100 instants, 540 x 960 JPEG
at half resolution), one label set of --labels instants chosen by --seed (one per stratum,
real.choose_instants), labels = Pose2Sim's reference projected into the 4 views (none outside
an image), the 14 human14 joints, and the scores on the unlabelled instants against that
reference (real.score: 3D median / mean / p90 mm, share triangulated, PCK@5/10/20 px).

Rows of one run, each with the same labelled images (labels x 4 views) and, for the trained
ones, the same training wall-time budget (--budget-s, one torch thread each, run one after
the other):

- peer sleap-nn: SLEAP's PyTorch backend (sleap-nn 0.3.5) trained from scratch on the
  labelled images, exported to a SLEAP labels file (.slp, written by sleap-io). Settings a
  SLEAP user would choose for few labels on a CPU (PEER below): single-instance model, UNet
  (16 filters, x2 per level, max stride 16, output stride 2), input scaling 0.25 (a 540 x 960
  view -> 135 x 240; the person ~55 x 90 px), confidence maps sigma 2.5, augmentation
  rotation +-15 deg, scale 0.9-1.1, brightness and contrast 0.9-1.1, Adam lr 1e-3 (sleap-nn's
  default), batch 4, epochs of 50 steps, validation = the training images (with so few labels
  none is held out, as our runs hold none out), the best checkpoint by validation loss. The
  training stops at the end of the epoch after which another epoch would exceed --budget-s
  (a Lightning callback; sleap-nn has no wall-time limit of its own). It then predicts every
  frame of every camera (its default peak threshold), the 2D is written as a points table
  (frame,camera,keypoint,u,v,score: docs/triangulate.md) and triangulated by the real
  `monet triangulate` command (a subprocess, its defaults: --threshold-px 15,
  --confidence-threshold 0.1, --min-views 2, exclusion) on a rig YAML of the recording's own
  cameras.
- ours default / ours supervised: bench/real.py's run_job (train within --budget-s, then
  `monet process`'s core), default mode `reprojection` and its `supervised` control
  (--no-supervised drops it), TrainConfig overrides --set (default input_size=128
  precision=auto: the README's CPU recipe, bfloat16 where the CPU runs it natively).
- nearest labelled pose: real.baselines' image-blind row.

sleap-nn is a bench-only dependency, never a product one: the first run creates its own
virtual environment at --peer-venv (default ~/.cache/monet_ros/peer-venv, about 7 GB) from
bench/peer_requirements.txt. Pins that import on this x86_64 machine (Python 3.11): sleap-nn
0.3.5, sleap-io 0.9.5, torch 2.14.1 + torchvision 0.29.1 (PyPI's CUDA build, run on the CPU;
pip takes both from the machine's disk). torch 2.13.0+cpu (the wheel on disk) beside PyPI's
torchvision fails to import (operator torchvision::nms does not exist) and the CPU index is
not reachable from here.

Writes OUT.md (table, command, CPU model, load averages, settings) and OUT.json.
    python bench/peer.py --budget-s 240     # one label set, 3 instants, seed 0: ~13 min
    python bench/peer.py --seed 1 --peer-steps 1250 --steps 4316 --no-supervised
        # fixed step counts (what 600 s of one core gave each side on seed 0): a budget
        # that does not move with the machine's load
    python bench/real.py ... --peer bench/results/peer.json   # the peer's row in real.py
"""
import argparse
import json
import os
from pathlib import Path
import resource
import shutil
import subprocess
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parents[1]
REQUIREMENTS = REPO / 'bench' / 'peer_requirements.txt'
DEFAULT_VENV = Path('~/.cache/monet_ros/peer-venv')
# sleap-nn settings (a SLEAP user's choices for few labels on a CPU); the docstring says why
PEER = {'scale': 0.25, 'filters': 16, 'filters_rate': 2.0, 'max_stride': 16,
        'output_stride': 2, 'sigma': 2.5, 'batch_size': 4, 'learning_rate': 1e-3,
        'steps_per_epoch': 50, 'geometry_aug': ['rotation', 'scale'],
        'intensity_aug': ['brightness', 'contrast']}
OURS = {'reprojection': 'ours default (reprojection)', 'supervised': 'ours supervised'}


# ---------------------------------------------------------------------------------------
# The peer's side: runs in the peer venv (numpy, sleap-io, sleap-nn; no monet_ros)
# ---------------------------------------------------------------------------------------

def peer_train(work, budget_s, seed, steps=0):
    """Build labels.slp from work/labels.json, train sleap-nn within budget_s (or exactly
    `steps` steps, rounded up to whole epochs, when steps > 0), write work/train.json."""
    import numpy as np
    import sleap_io as sio
    import torch

    torch.set_num_threads(1)
    spec = json.loads((work / 'labels.json').read_text())
    skeleton = sio.Skeleton(nodes=list(spec['keypoints']), edges=[list(b) for b in spec['bones']],
                           name='human14')     # (sleap-io turns the lists' names into Nodes)
    videos = {cam: sio.Video.from_filename(files) for cam, files in spec['videos'].items()}
    frames = []
    for item in spec['labelled']:
        points = np.array(item['points'], dtype=float)
        instance = sio.Instance.from_numpy(points, skeleton=skeleton)
        frames.append(sio.LabeledFrame(video=videos[item['camera']], frame_idx=item['frame'],
                                       instances=[instance]))
    labels = sio.Labels(labeled_frames=frames, videos=list(videos.values()),
                        skeletons=[skeleton])
    labels.save(str(work / 'labels.slp'))

    import lightning as L
    from sleap_nn.train import train
    from sleap_nn.training import model_trainer

    class Budget(L.Callback):
        """Stop at the end of an epoch when one more would pass the budget."""

        def __init__(self):
            self.start = self.last = self.end = None
            self.epochs = 0

        def on_train_start(self, trainer, module):
            self.start = self.last = time.monotonic()

        def on_train_end(self, trainer, module):
            self.end = time.monotonic()

        def on_train_epoch_end(self, trainer, module):
            now = time.monotonic()
            epoch_s, self.last = now - self.last, now
            self.epochs += 1
            if not steps and now - self.start + epoch_s > budget_s:
                trainer.should_stop = True

    budget = Budget()
    setup = model_trainer.ModelTrainer._setup_loggers_callbacks

    def with_budget(self, *args, **kwargs):
        loggers, callbacks = setup(self, *args, **kwargs)
        return loggers, [*callbacks, budget]

    model_trainer.ModelTrainer._setup_loggers_callbacks = with_budget
    start, cpu = time.monotonic(), time.process_time()
    train(train_labels_path=[str(work / 'labels.slp')], use_same_data_for_val=True,
          scale=PEER['scale'], geometry_aug=PEER['geometry_aug'],
          intensity_aug=PEER['intensity_aug'],
          backbone_config={'unet': {'in_channels': 3, 'filters': PEER['filters'],
                                    'filters_rate': PEER['filters_rate'],
                                    'max_stride': PEER['max_stride'],
                                    'output_stride': PEER['output_stride']}},
          head_configs={'single_instance': {'confmaps': {
              'part_names': spec['keypoints'], 'sigma': PEER['sigma'],
              'output_stride': PEER['output_stride']}}},
          batch_size=PEER['batch_size'], learning_rate=PEER['learning_rate'],
          train_steps_per_epoch=PEER['steps_per_epoch'],
          min_train_steps_per_epoch=PEER['steps_per_epoch'],
          max_epochs=-(-steps // PEER['steps_per_epoch']) if steps else 10 ** 6,
          data_pipeline_fw='torch_dataset_cache_img_memory',
          trainer_accelerator='cpu', trainer_num_devices=1, enable_progress_bar=False,
          save_ckpt=True, ckpt_dir=str(work), run_name='model', seed=seed, num_workers=0)
    out = {'train_s': round(time.monotonic() - start, 1),
           'fit_s': round(budget.end - budget.start, 1),
           'train_cpu_s': round(time.process_time() - cpu, 1), 'epochs': budget.epochs,
           'steps': budget.epochs * PEER['steps_per_epoch'], 'settings': PEER,
           'labelled_images': len(frames)}
    (work / 'train.json').write_text(json.dumps(out, indent=1))


def peer_predict(work):
    """Predict every frame of every camera with work/model; write work/points.csv."""
    import numpy as np
    import sleap_io as sio
    import sleap_nn
    import torch

    torch.set_num_threads(1)
    spec = json.loads((work / 'labels.json').read_text())
    start = time.monotonic()
    rows = ['frame,camera,keypoint,u,v,score']
    for cam, files in spec['videos'].items():
        predicted = sleap_nn.predict(sio.Video.from_filename(files),
                                     model_paths=[str(work / 'model')], device='cpu')
        for lf in predicted.labeled_frames:
            if not lf.instances:
                continue
            points = lf.instances[0].numpy(scores=True)       # (C, 3): u, v, score
            for name, (u, v, s) in zip(spec['keypoints'], points):
                if np.isfinite(u) and np.isfinite(v):
                    rows.append(f'{lf.frame_idx},{cam},{name},{u:.3f},{v:.3f},{s:.4f}')
    (work / 'points.csv').write_text('\n'.join(rows) + '\n')
    (work / 'predict.json').write_text(json.dumps(
        {'predict_s': round(time.monotonic() - start, 1)}))


# ---------------------------------------------------------------------------------------
# Our side: the project's venv (monet_ros, bench/real.py)
# ---------------------------------------------------------------------------------------

def ensure_venv(venv, say):
    """The peer venv's python; created with pip from peer_requirements.txt when missing or
    when the list changed since (a marker file keeps the list it was made from)."""
    python = venv / 'bin' / 'python'
    marker = venv / 'monet_peer_requirements.txt'
    wanted = REQUIREMENTS.read_text()
    if python.exists() and marker.exists() and marker.read_text() == wanted:
        return python
    say(f'creating the peer venv {venv} from {REQUIREMENTS.name} (several GB, minutes)')
    base = getattr(sys, '_base_executable', sys.executable)
    subprocess.run([base, '-m', 'venv', str(venv)], check=True)
    subprocess.run([str(python), '-m', 'pip', 'install', '-r', str(REQUIREMENTS)], check=True)
    subprocess.run([str(python), '-c', 'import sleap_nn, sleap_io, torchvision.ops'],
                   check=True)
    marker.write_text(wanted)
    return python


def run_peer_stage(python, stage, work, *extra):
    """Run a stage of this file in the peer venv; returns its (wall s, child CPU s)."""
    env = dict(os.environ, OMP_NUM_THREADS='1', MKL_NUM_THREADS='1', WANDB_MODE='disabled',
               PYTHONPATH='')
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.monotonic()
    log = work / f'{stage}.log'
    with open(log, 'w') as f:
        done = subprocess.run([str(python), str(Path(__file__).resolve()), '--stage', stage,
                               '--work', str(work), *extra], stdout=f, stderr=subprocess.STDOUT,
                              env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        tail = log.read_text().splitlines()[-30:]
        raise SystemExit(f'peer stage {stage} failed (exit {done.returncode}); the end of '
                         f'{log}:\n' + '\n'.join(line[:300] for line in tail))
    return (time.monotonic() - start,
            after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)


def export_labels(work, recording, labels2d, instants):
    """Every frame as a PNG per camera + work/labels.json (the labelled points, NaN = none)."""
    import cv2

    from monet_ros.skeleton import load_skeleton

    skeleton = load_skeleton('human14')
    names = list(recording.keypoints)
    bones = [[b if isinstance(b, str) else names[b] for b in bone] for bone in skeleton.bones]
    videos = {}
    for cam, frames in zip(recording.cameras, recording.frames):
        folder = work / 'frames' / cam.name
        folder.mkdir(parents=True)
        files = []
        for t, image in enumerate(frames):
            path = folder / f'{t:06d}.png'
            cv2.imwrite(str(path), image[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 1])
            files.append(str(path))
        videos[cam.name] = files
    labelled = []
    for t in instants:
        for v, cam in enumerate(recording.cameras):
            pts = labels2d[t, v]
            if (~(pts[:, 0] == pts[:, 0])).all():
                continue                           # no joint of the reference in this view
            labelled.append({'camera': cam.name, 'frame': int(t),
                             'points': [[None if p != p else float(p) for p in q]
                                        for q in pts]})
    (work / 'labels.json').write_text(json.dumps(
        {'keypoints': names, 'bones': bones, 'videos': videos, 'labelled': labelled}))
    return len(labelled)


def triangulate_peer(work, recording):
    """`monet triangulate` on the peer's points table (a subprocess, as a user runs it);
    returns X (T, C, 3) and points (T, V, C, 2) read back, NaN = nothing."""
    import numpy as np

    from monet_ros.geometry.rig import save_rig
    from monet_ros.io.export_tables import read_anipose_csv

    T, C = recording.num_instants, recording.num_keypoints
    X = np.full((T, C, 3), np.nan)
    points = np.full((T, recording.num_views, C, 2), np.nan)
    lines = (work / 'points.csv').read_text().splitlines()[1:]
    save_rig(work / 'rig.yaml', recording.cameras)
    command = [sys.executable, '-m', 'monet_ros.cli', 'triangulate', str(work / 'points.csv'),
               '--rig', str(work / 'rig.yaml'), '--out', str(work / 'tri'),
               '--skeleton', 'human14', '--export', 'csv', '--quiet']
    env = dict(os.environ, PYTHONPATH=str(REPO))
    shown = ' '.join(['monet', *command[3:]]).replace(str(work), 'WORK')
    if not lines:                                 # the peer detected nothing: no 3D
        return X, points, shown + ' (not run: no 2D)'
    subprocess.run(command, check=True, env=env)
    table = read_anipose_csv(work / 'tri' / 'keypoints3d.csv')
    order = [table['keypoints'].index(k) for k in recording.keypoints]
    for row, fnum in enumerate(table['fnum']):
        if 0 <= int(fnum) < T:
            X[int(fnum)] = table['X'][row][order]
    cams = {c.name: v for v, c in enumerate(recording.cameras)}
    keys = {k: c for c, k in enumerate(recording.keypoints)}
    for line in lines:
        frame, cam, key, u, v, _ = line.split(',')
        points[int(frame), cams[cam], keys[key]] = float(u), float(v)
    return X, points, shown


def peer_row(args, real, recording, instants, say):
    python = ensure_venv(args.peer_venv.expanduser(), say)
    work = Path(tempfile.mkdtemp(prefix='monet-peer-', dir=args.work))
    try:
        n = export_labels(work, recording, real._STATE['reference2d'], instants)
        say(f'peer: {n} labelled images exported; training sleap-nn ('
            + (f'{args.peer_steps} steps)' if args.peer_steps else f'{args.budget_s:.0f} s)'))
        train_wall, train_cpu = run_peer_stage(python, 'train', work, '--budget-s',
                                               str(args.budget_s), '--seed', str(args.seed),
                                               '--peer-steps', str(args.peer_steps))
        trained = json.loads((work / 'train.json').read_text())
        predict_wall, _ = run_peer_stage(python, 'predict', work)
        X, points, command = triangulate_peer(work, recording)
    finally:
        if args.keep:
            say(f'peer work folder kept: {work}')
        else:
            shutil.rmtree(work, ignore_errors=True)
    unlabelled = sorted(set(range(recording.num_instants)) - set(instants.tolist()))
    row = real.score(X, points, real._STATE['reference'], real._STATE['reference2d'],
                     unlabelled)
    row.update({'labels': len(instants), 'seed': args.seed, 'mode': 'peer sleap-nn',
                'steps': trained['steps'], 'train_s': trained['fit_s'],
                'train_process_wall_s': round(train_wall, 1),
                'train_cpu_s': round(train_cpu, 1), 'epochs': trained['epochs'],
                'predict_wall_s': round(predict_wall, 1), 'labelled_images': n,
                'settings': trained['settings'], 'triangulate': command,
                'instants': instants.tolist(), 'warnings': []})
    say(f'peer sleap-nn: {row["steps"]} steps, 3D median {real.fmt(row["median_mm"], ".0f")}'
        f' mm, PCK@10 {row["pck10"]:.3f}')
    return row


def parse_overrides(parser, pairs, TrainConfig):
    import yaml

    overrides = {}
    for pair in pairs:
        key, sep, value = pair.partition('=')
        if not sep or key not in TrainConfig.__dataclass_fields__:
            parser.error(f'--set {pair!r}: expected KEY=VALUE with KEY a TrainConfig field')
        value = yaml.safe_load(value)
        if isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                pass
        overrides[key] = value
    return overrides




def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--data', type=Path, default=None,
                        help='shared data folder (default: ../shared/data)')
    parser.add_argument('--out', default=None, help='output path stem (default '
                        'bench/results/peer): OUT.md and OUT.json')
    parser.add_argument('--labels', type=int, default=3, help='labelled instants (one set)')
    parser.add_argument('--seed', type=int, default=0,
                        help='label set (real.choose_instants) and training seed')
    parser.add_argument('--budget-s', type=float, default=300.0,
                        help='training wall time of every trained row (s), one thread each')
    parser.add_argument('--peer-steps', type=int, default=0,
                        help="the peer's training steps (whole epochs of 50) instead of "
                             '--budget-s: a budget that does not depend on the load')
    parser.add_argument('--steps', type=int, default=0,
                        help="our rows' training steps instead of --budget-s")
    parser.add_argument('--peer-venv', type=Path, default=DEFAULT_VENV,
                        help="the peer's virtual environment, created on first use")
    parser.add_argument('--set', nargs='*', default=['input_size=128', 'precision=auto'],
                        metavar='KEY=VALUE', help='TrainConfig overrides of our rows')
    parser.add_argument('--no-supervised', action='store_true',
                        help='leave out our supervised row (saves one budget)')
    parser.add_argument('--peer-only', action='store_true', help='only the peer row')
    parser.add_argument('--work', default=None, help='folder for the temporary files')
    parser.add_argument('--keep', action='store_true', help="keep the peer's work folder")
    parser.add_argument('--stage', choices=('train', 'predict'), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.stage:                                # inside the peer venv
        work = Path(args.work)
        if args.stage == 'train':
            peer_train(work, args.budget_s, args.seed, args.peer_steps)
        else:
            peer_predict(work)
        return 0

    sys.path.insert(0, str(REPO))
    sys.path.insert(0, str(REPO / 'bench'))
    import real

    from monet_ros.commands.demo import default_data_root
    from monet_ros.cores import cpu_model
    from monet_ros.learning.config import TrainConfig
    from monet_ros.learning.recording import load_recording

    def say(line):
        print(line, file=sys.stderr, flush=True)

    overrides = parse_overrides(parser, args.set, TrainConfig)
    stem = Path(args.out or REPO / 'bench' / 'results' / 'peer')
    root = args.data or default_data_root()
    if not (root / real.BAG).exists():
        say(f'peer.py: {root / real.BAG} not found (use --data)')
        return 2 if args.data else 0
    start = time.monotonic()
    loads = [os.getloadavg()]
    recording = load_recording(root / real.BAG, skeleton='human14')
    reference = real.load_reference(root, recording.keypoints)
    real._STATE.update(recording=recording, reference=reference, bag=root / real.BAG,
                       reference2d=real.project_reference(reference, recording.cameras))
    instants = real.choose_instants(recording.num_instants, args.labels, args.seed)
    say(f'{recording.num_instants} instants x {recording.num_views} views; labelled '
        f'instants {instants.tolist()}')
    rows = [peer_row(args, real, recording, instants, say)]
    loads.append(os.getloadavg())
    if not args.peer_only:
        modes = ['reprojection'] + ([] if args.no_supervised else ['supervised'])
        for mode in modes:
            row = real.run_job((args.labels, mode, args.budget_s, args.steps, overrides,
                                args.seed))
            row['mode'] = OURS[mode]
            rows.append(row)
            loads.append(os.getloadavg())
    rows += [dict(r, seed=args.seed) for r in real.baselines(args.labels, args.seed)
             if r['mode'] == 'nearest labelled pose']
    command = 'python bench/peer.py ' + ' '.join(argv if argv is not None else sys.argv[1:])
    peer = rows[0]
    text = '\n'.join([
        f'# A peer on the same labels: sleap-nn vs ours ({args.labels} labelled instants, '
        f'seed {args.seed})', '',
        f'Command: `{command.strip()}` (wall {time.monotonic() - start:.0f} s).',
        f'Machine: {cpu_model()}, {os.cpu_count()} cores; load averages (1 / 5 / 15 min) at '
        'the start and after each trained row: ' + '; '.join(
            ' / '.join(f'{x:.1f}' for x in load) for load in loads) + '.',
        (f'Budget: {args.budget_s:.0f} s of training wall time per trained row'
         if not (args.peer_steps or args.steps) else
         f'Budget: fixed step counts (peer {args.peer_steps or "by time"}, ours '
         f'{args.steps or "by time"} steps)') + ', one torch '
        f'thread each, one after the other (peer: {peer["epochs"]} epochs of '
        f'{PEER["steps_per_epoch"]} steps in {peer["train_s"]:.0f} s, {peer["train_cpu_s"]:.0f}'
        f' s CPU for its whole training process; prediction of all frames '
        f'{peer["predict_wall_s"]:.0f} s). Our rows: TrainConfig overrides '
        f'{overrides or "none"}.',
        f'Labelled instants {instants.tolist()} ({peer["labelled_images"]} labelled images); '
        'scores on the other instants against the Pose2Sim reference (bench/real.py score).',
        f'Peer settings (sleap-nn 0.3.5, single-instance UNet from scratch): {PEER}; its 2D '
        f'triangulated by `{peer["triangulate"]}`.', '',
        real.table(rows), ''])
    stem.parent.mkdir(parents=True, exist_ok=True)
    stem.with_suffix('.md').write_text(text)
    stem.with_suffix('.json').write_text(json.dumps(rows, indent=1))
    print(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
