"""`monet train`: semi-supervised training from a recording + labels (the paper's modes)."""
import argparse
from dataclasses import fields
import json
from pathlib import Path
import sys

from monet_ros.config import ConfigError
from monet_ros.learning.config import TrainConfig

HELP = ('semi-supervised training from recordings + labels '
        '(modes: supervised, spatial, spatiotemporal, bootstrap1, bootstrap2, monet)')


def add_arguments(parser):
    parser.add_argument('data', help='recording: `monet synth` output folder, rosbag2 folder '
                        'or .mcap file')
    parser.add_argument('--out', required=True, help='output folder (checkpoints, log)')
    parser.add_argument('--rig', help="rig file (default: the data folder's rig.yaml, else "
                        "the bag's CameraInfo + /tf_static)")
    parser.add_argument('--labels', help="labels CSV (default: the data folder's labels.csv)")
    parser.add_argument('--ground-truth', help='ground_truth.npz (for ground-truth crop boxes)')
    parser.add_argument('--skeleton', default='human14', help='skeleton preset or YAML file')
    parser.add_argument('--max-instants', type=int, default=0,
                        help='read at most this many instants (0 = all)')
    parser.add_argument('--resume', action='store_true',
                        help='continue from OUT/trainer_state.pt')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')
    parser.add_argument('--threads', type=int, default=0,
                        help='torch CPU threads (0 = torch default; 1 is fastest on a busy '
                        'machine)')
    group = parser.add_argument_group('training configuration (TrainConfig)')
    for f in fields(TrainConfig):
        flag = '--' + f.name.replace('_', '-')
        kind = {'int': int, 'float': float, 'str': str, 'bool': parse_bool}[
            f.type if isinstance(f.type, str) else f.type.__name__]
        group.add_argument(flag, dest=f.name, type=kind, default=None,
                           help=f'{f.metadata["description"]} (default {f.default!r})')


def parse_bool(text):
    """'true'/'false' (also 1/0, yes/no, on/off) for boolean TrainConfig flags."""
    value = {'true': True, '1': True, 'yes': True, 'on': True,
             'false': False, '0': False, 'no': False, 'off': False}.get(text.lower())
    if value is None:
        raise argparse.ArgumentTypeError(f'expected true or false, got {text!r}')
    return value


def config_from_args(args):
    values = {f.name: getattr(args, f.name) for f in fields(TrainConfig)
              if getattr(args, f.name, None) is not None}
    return TrainConfig(**values)


def run(args):
    from monet_ros.learning.recording import RecordingError, load_recording
    from monet_ros.learning.trainer import Trainer, TrainingData
    from monet_ros.models import build_model

    if args.threads:
        import torch
        torch.set_num_threads(args.threads)
    try:
        config = config_from_args(args)
    except ConfigError as error:
        print(f'monet train: {error}', file=sys.stderr)
        return 2
    try:
        recording = load_recording(args.data, rig=args.rig, labels=args.labels,
                                   ground_truth=args.ground_truth, skeleton=args.skeleton,
                                   max_instants=args.max_instants or None)
    except (RecordingError, ValueError, OSError) as error:
        print(f'monet train: {error}', file=sys.stderr)
        return 1
    if recording.read_report.notice(args.data):
        print(f'monet train: {recording.read_report.notice(args.data)}', file=sys.stderr)
    probe = build_model(config.architecture, recording.num_keypoints, **config.model_options())
    data = TrainingData(recording, config, probe.input_size, probe.heatmap_size)
    out = Path(args.out)
    if args.resume and (out / 'trainer_state.pt').exists():
        trainer = Trainer.resume(out, data, config=config)
        print(f'resumed at step {trainer.step_count}', file=sys.stderr)
    else:
        trainer = Trainer(config, data, out)
    print(f'{recording.name}: {recording.num_instants} instants x {recording.num_views} views, '
          f'{len(data.labelled_instants)} labelled, {len(data.unlabeled_instants)} unlabeled, '
          f'{len(data.held_out)} held out; mode {config.mode}, {trainer.pseudo_label_count} '
          f'pseudo-labels, device {trainer.device}', file=sys.stderr)
    summary = trainer.run(progress=not args.no_progress)
    summary['checkpoint'] = str(out / 'model.pt')
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == '__main__':
    p = argparse.ArgumentParser()
    add_arguments(p)
    sys.exit(run(p.parse_args()))
