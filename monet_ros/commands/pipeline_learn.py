"""`monet pipeline --learn`: the online learner beside the player, detector and fusion.

The learner node (monet_ros.nodes.learner) fine-tunes the pipeline's model on the same
recording in its default mode, reprojection (L_L on the labelled instants, lambda_p L_B on
pseudo-labels tracked from them, lambda_r L_R on the unlabeled ones; no L_E) in a background
thread and announces better checkpoints on /monet/model; the detector hot-reloads them
between frames. Every validated checkpoint prints one line with the learner's held-out
reprojection error and the live pipeline's mean reprojection error of the frames fused with
the previous weights (since the last announcement).
"""
from pathlib import Path
import time

import numpy as np


def add_learn_arguments(parser):
    group = parser.add_argument_group('online learning (--learn)')
    group.add_argument('--learn', action='store_true',
                       help='also run the learner: fine-tune the model on the recording and '
                       'hot-reload the detector with every better checkpoint (use with --loop)')
    group.add_argument('--labels', help='labels CSV for the learner (default: labels.csv of a '
                       '`monet synth` folder holding the recording)')
    group.add_argument('--learn-out', help='learner output folder (default: '
                       '~/.cache/monet_ros/learner, or learner/ in --workdir); a fresh run '
                       'each time')
    group.add_argument('--learn-every', type=int, default=50,
                       help='training steps between checkpoints (each validated, announced '
                       'when not worse)')
    group.add_argument('--learn-lr', type=float, default=1e-4, help='learning rate')
    group.add_argument('--learn-tolerance-px', type=float, default=0.0,
                       help="announce a checkpoint whose criterion is at most the last "
                       "announced one's + this (px); the criterion is the learner's "
                       'publish_metric: the held-out labelled error (mean px on the labelled '
                       'instants held out for validation) by default, the held-out '
                       'reprojection error when no labelled instant can be held out')


def learner_bags(bag):
    """A recording inside a `monet synth` folder learns from the folder (labels, rig)."""
    bag = Path(bag)
    if bag.name == 'recording' and (bag.parent / 'labels.csv').is_file():
        return bag.parent
    return bag


def _px(value, missing):
    """'1.23 px', or `missing` for a metric the validation could not give (None / NaN)."""
    if value is None or not np.isfinite(value):
        return missing
    return f'{value:.2f} px'


class AnnouncementLog:
    """Prints a line per validated checkpoint with the live reprojection error so far."""

    def __init__(self, summary):
        self.summary = summary
        self.since = time.monotonic()

    def __call__(self, result):
        now = time.monotonic()
        with self.summary.lock:
            errors = [e for t, e in self.summary.errors if t >= self.since]
        live = f'{np.mean(errors):.2f} px over {len(errors)} frames' if errors else 'no frames'
        held = _px(result.metrics.get('reprojection_px'), 'none (no held-out instant '
                   'triangulated)')
        labelled = _px(result.metrics.get('labelled_mean_px'), 'none (no labelled instant '
                       'held out)')
        verdict = 'announced' if result.published else 'kept back'
        print(f'learner: step {result.step} {verdict} (held-out reprojection {held}, held-out '
              f'labelled error {labelled}: {result.reason}); live reprojection with the '
              f'previous weights: {live}', flush=True)
        if result.published:
            self.since = now


def learner_node(args, rig, summary):
    """The LearnerNode of `monet pipeline --learn` (ValueError/OSError on bad input)."""
    from monet_ros.nodes.learner import LearnerNode

    base = Path(args.workdir) if args.workdir else Path.home() / '.cache' / 'monet_ros'
    out = Path(args.learn_out) if args.learn_out else base / 'learner'
    overrides = dict(bags=[str(learner_bags(args.bag))], out=str(out), model=str(args.model),
                     labels=str(args.labels or ''), resume=False, threads=1,
                     checkpoint_every=args.learn_every, lr=args.learn_lr,
                     publish_tolerance_px=args.learn_tolerance_px,
                     device=args.device or 'auto')
    if args.rig and not Path(args.rig).is_dir() and Path(args.rig).suffix != '.mcap':
        overrides['rig'] = str(rig)
    if args.rig_units:
        overrides['rig_units'] = args.rig_units
    node = LearnerNode(overrides=overrides)
    node.listeners.append(AnnouncementLog(summary))
    return node
