"""`monet train`: semi-supervised training from a recording + labels (the paper's modes)."""
import argparse
from dataclasses import dataclass, fields
import os
from pathlib import Path
import sys

from monet_ros import json_text
from monet_ros.config import setting, validate_config
from monet_ros.learning.config import TrainConfig

HELP = ('semi-supervised training from recordings + labels (modes: reprojection, the default '
        'and the most accurate measured: L_L + L_B + L_R; supervised, spatial, spatiotemporal, '
        'bootstrap1, bootstrap2, monet, temporal_difference, reprojection_epipolar, and the '
        'ablations bootstrap2_epipolar, epipolar; --distill-rounds N adds rounds of '
        "distillation from the detector's own filtered 3D)")


@dataclass(frozen=True)
class TrainRunOptions:
    """The options of `monet train` that are not TrainConfig (validated; errors name them)."""
    max_instants: int = setting(0, 'read at most this many instants (0 = all)', minimum=0,
                                maximum=100_000_000)
    threads: int = setting(0, 'torch CPU threads (0 = torch default)', minimum=0,
                           maximum=256)
    holdout_labelled: int = setting(0, 'labelled instants left out of training and scored '
                                    '(0 = off)', minimum=0, maximum=100_000_000)

    def __post_init__(self):
        validate_config(self)


# the skeleton of `monet train` without --skeleton (`monet info --labels` names the label
# keypoints it lacks)
DEFAULT_SKELETON = 'human14'


def add_arguments(parser):
    from monet_ros.commands.common import add_rig_units_argument
    parser.add_argument('data', help='recording: `monet synth` output folder, rosbag2 folder '
                        'or .mcap file')
    parser.add_argument('--out', required=True, help='output folder (checkpoints, log)')
    parser.add_argument('--rig', help="rig file (default: the data folder's rig.yaml, else "
                        "the bag's CameraInfo + /tf_static)")
    add_rig_units_argument(parser)
    parser.add_argument('--labels', help="labels CSV, stamp_ns- or frame-keyed (default: the "
                        "data folder's labels.csv); checked against the recording, see "
                        '--camera-map / --skip-bad-labels')
    parser.add_argument('--ground-truth', help='ground_truth.npz (for ground-truth crop boxes)')
    parser.add_argument('--skeleton', default=DEFAULT_SKELETON,
                        help='skeleton preset or YAML file')
    parser.add_argument('--max-instants', type=int, default=0,
                        help='read at most this many instants (0 = all)')
    parser.add_argument('--resume', action='store_true',
                        help='continue from OUT/trainer_state.pt')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')
    parser.add_argument('--threads', type=int, default=0,
                        help='torch CPU threads (0 = torch default; 1 is fastest on a busy '
                        'machine)')
    parser.add_argument('--holdout-labelled', type=int, default=0, metavar='N',
                        help="leave N labelled instants (every subject's labels there) out "
                        "of training and report the model's error on them at the end: every "
                        "subject's, pooled and per subject, in crops around each (px, as "
                        '--validation-labels), and as `monet process` runs the model (px, '
                        'mm; with labels of several subjects as `monet process --subjects N`, '
                        'pooled and per subject) (0 = off)')
    from monet_ros.commands.labels import add_label_arguments
    add_label_arguments(parser)
    group = parser.add_argument_group('training configuration (TrainConfig)')
    for f in fields(TrainConfig):
        flag = '--' + f.name.replace('_', '-')
        kind = {'int': int, 'float': float, 'str': str, 'bool': parse_bool}[
            f.type if isinstance(f.type, str) else f.type.__name__]
        default = COMMAND_DEFAULTS.get(f.name, f.default)
        group.add_argument(flag, dest=f.name, type=kind, default=None,
                           help=f'{f.metadata["description"]} (default {default!r})')
    from monet_ros.commands.common import add_subject_settings_arguments
    teacher = parser.add_argument_group(
        'distillation teacher of several subjects (--distill-rounds N with labels of several '
        'subjects: the teacher runs `monet process --subjects S --filter optim`, S the most '
        "subjects labelled at an instant; these are that command's options, lengths in mm "
        "whatever the rig's unit)")
    add_subject_settings_arguments(teacher, help_prefix='teacher: ')


def parse_bool(text):
    """'true'/'false' (also 1/0, yes/no, on/off) for boolean TrainConfig flags."""
    value = {'true': True, '1': True, 'yes': True, 'on': True,
             'false': False, '0': False, 'no': False, 'off': False}.get(text.lower())
    if value is None:
        raise argparse.ArgumentTypeError(f'expected true or false, got {text!r}')
    return value


# TrainConfig fields whose default for `monet train` is not the Python API's
COMMAND_DEFAULTS = {'precision': 'auto'}


def config_from_args(args):
    values = dict(COMMAND_DEFAULTS)
    values.update({f.name: getattr(args, f.name) for f in fields(TrainConfig)
                   if getattr(args, f.name, None) is not None})
    return TrainConfig(**values)


RUN_FILES = ('model.pt', 'trainer_state.pt')


def check_not_a_run(out, resume):
    """Without --resume, `out` must not hold a training run already (RUN_FILES): training
    into it replaced that run's model and state and mixed its checkpoints/ with the new
    run's. ConfigError naming --out and what it holds."""
    from monet_ros.config import ConfigError

    held = [name for name in RUN_FILES if (Path(out) / name).exists()]
    if held and not resume:
        raise ConfigError('monet train', 'out', f'{out}: holds a training run '
                          f'({", ".join(held)}); not overwriting: --resume continues it, or '
                          'choose a new folder')


def run(args):
    from monet_ros.commands.common import check_threads
    from monet_ros.commands.labels import label_options_from_args
    from monet_ros.commands.train_holdout import hold_out, score_holdout
    from monet_ros.labels import LabelError
    from monet_ros.learning import distributed
    from monet_ros.learning.distributed import DistributedTrainer as Trainer
    from monet_ros.learning.recording import load_recording
    from monet_ros.learning.trainer import (
        check_resume_keypoints,
        check_training_precision,
        pick_device,
    )
    from monet_ros.models import build_model
    from monet_ros.models.detector import resolve_precision
    from monet_ros.models.device import check_device
    from monet_ros.skeleton import load_skeleton

    options = TrainRunOptions(max_instants=args.max_instants, threads=args.threads,
                               holdout_labelled=args.holdout_labelled)
    config = config_from_args(args)
    check_distill_options(args, config)                          # before any file is read
    check_teacher_options(args, config.distill_rounds > 0)
    check_device('monet train', None if config.device == 'auto' else config.device)
    check_threads('monet train', options.threads)
    world, device = distributed.init_from_env(config.device)     # a torchrun job, if any
    # bfloat16 only where native: refused before the recording is read
    train_device = device or pick_device(config.device)
    check_training_precision(config.precision, train_device)
    # which arithmetic runs, and why (auto: the CPU feature found); said with the notes
    precision_note = resolve_precision(config.precision, 'torch', train_device)[1]
    if world.distributed and config.distill_rounds:
        raise ValueError('--distill-rounds is not supported under torchrun (its teacher runs '
                         'monet process in one process): train with --distill-rounds 0 there')
    if world.distributed and args.holdout_labelled:
        raise ValueError('--holdout-labelled is not supported under torchrun (train, then '
                         'score the held-out labels with `monet eval`)')
    if not world.writer:             # rank 0 reports and writes; the other ranks train
        args.no_progress = True
        sys.stdout = open(os.devnull, 'w')
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(20, 'output is a file, not a folder', str(out))
    check_not_a_run(out, args.resume)
    skeleton = load_skeleton(args.skeleton)
    said = skeleton_line(skeleton, args.skeleton)
    if args.resume and (out / 'trainer_state.pt').exists():    # before any network is built
        check_resume_keypoints(out, skeleton.keypoints, skeleton.name)
    out.mkdir(parents=True, exist_ok=True)        # an unwritable place is named at once
    try:
        recording = load_recording(args.data, rig=args.rig, labels=args.labels,
                                   ground_truth=args.ground_truth, skeleton=skeleton.keypoints,
                                   max_instants=options.max_instants or None,
                                   label_options=label_options_from_args(args),
                                   rig_units=args.rig_units)
    except LabelError as error:      # labels of another animal: say which skeleton it was
        if 'is not a keypoint of the skeleton' not in str(error):
            raise
        raise LabelError(f'{error} [{said}]') from None
    # the teacher's options once the labels say how many subjects (one line, before notes)
    teacher = check_teacher_options(args, config.distill_rounds > 0, recording.num_subjects)
    # the skeleton and the arithmetic first (once the inputs are read: a bad input stays one
    # line), then what reading found
    notes = [f'monet train: {said}', f'monet train: {precision_note}']
    notes += ([f'monet train: {recording.read_report.notice(args.data)}']
              if recording.read_report.notice(args.data) else [])
    notes += [f'monet train: note: {note}' for note in recording.rig_notes]
    if recording.label_report is not None:
        notes.append(f'monet train: labels: {recording.label_report.summary()}')
    for line in notes if world.writer else ():
        print(line, file=sys.stderr)
    held, held_path = hold_out(recording, args.holdout_labelled, args.out)
    probe = build_model(config.architecture, recording.num_keypoints, **config.model_options())
    try:
        data = distributed.shared_training_data(recording, config, probe.input_size,
                                                probe.heatmap_size, holdout=held)
    except ValueError as error:
        raise ValueError(f'{error}; {_labels_text(recording, config)}') from None
    if config.distill_rounds:
        check_something_to_distil(data, config)
    if args.resume and (out / 'trainer_state.pt').exists():
        trainer = Trainer.resume(out, data, config=config, device=device)
        if world.writer:
            print(f'resumed at step {trainer.step_count}', file=sys.stderr)
    else:
        if args.resume and world.writer:
            print(f'nothing to resume: no {out / "trainer_state.pt"} (a checkpoint is written '
                  f'every {config.checkpoint_every} steps); starting at step 0', file=sys.stderr)
        trainer = Trainer(config, data, out, device=device)
    trainer.skeleton_name = skeleton.name
    if config.validation_labels > 0 and not len(data.validation_instants):
        from monet_ros.learning.trainer import no_validation_text
        trainer.warn(no_validation_text(config.validation_labels, '--validation-labels',
                                        f'after --holdout-labelled {len(held)}' if len(held)
                                        else '') + "; the summary's validation is null")
    if world.writer:
        print(f'{recording.name}: {recording.num_instants} instants x {recording.num_views} '
              f'views, {len(data.labelled_instants)} labelled'
              + (f' ({data.num_other_labelled} more labelled subject-instants: crops '
                 f'around subjects other than 0, up to {recording.num_subjects} per '
                 'instant)' if data.num_other_labelled else '')
              + f', {len(data.unlabeled_instants)} '
              f'unlabeled{_rows_text(data)}, {len(data.held_out)} held out; mode {config.mode} '
              f'({trainer.objective_text()}{_unused_terms_text(args, config)}), '
              f'{trainer.pseudo_label_count} pseudo-labels{_gate_text(data.pseudo_gate)}, '
              f'device {trainer.device}'
              + (f', {world.world_size} ranks ({world.backend}), {trainer.per_rank_batch} '
                 'crops per rank per step' if world.distributed else ''), file=sys.stderr)
    # where the run ends: its steps and the distillation rounds it has reached
    end = config.steps + trainer.distill_round * config.distill_round_steps
    if trainer.step_count >= end and trainer.distill_round >= config.distill_rounds and \
            world.writer:
        print(f'monet train: already at step {trainer.step_count} >= --steps {config.steps}'
              + (f' + {trainer.distill_round} distillation rounds x '
                 f'{config.distill_round_steps} steps' if trainer.distill_round else '')
              + ': nothing to train', file=sys.stderr)
    try:
        if config.distill_rounds:
            from monet_ros.commands.train_distill import train_with_distillation
            from monet_ros.learning.recording import find_recording_parts
            parts = find_recording_parts(args.data)
            summary = train_with_distillation(
                trainer, parts['bag'], rig=args.rig or parts['rig'],
                camera_map=label_options_from_args(args).camera_map,
                rig_units=args.rig_units, skeleton=args.skeleton,
                progress=not args.no_progress, **teacher)
        else:
            summary = trainer.run(progress=not args.no_progress)
    except RuntimeError as error:
        # torch.save on a full disk: "enforce fail at inline_container.cc ... file write
        # failed" names neither the folder nor the disk.
        if 'inline_container' in str(error) or 'write failed' in str(error):
            raise OSError(28, 'No space left on device', str(out)) from None
        raise
    if not world.writer:
        distributed.shutdown()
        return 0
    summary['checkpoint'] = str(out / 'model.pt')
    fit = summary['fit']
    print(f'fit to the labelled views: median {fit["median_px"]:.2f} px '
          f'({fit["median_heat"]:.2f} heatmap px), mean {fit["mean_px"]:.2f} px, p90 '
          f'{fit["p90_px"]:.2f} px ({fit["count"]} keypoints)', file=sys.stderr)
    if summary.get('validation'):
        for line in scored_lines('error on the held-out validation labels '
                                 '(--validation-labels)', summary['validation'],
                                 len(data.validation_instants)):
            print(line, file=sys.stderr)
    for stats in summary['bootstrap']:
        print(f'bootstrapping round {stats["round"]} at step {stats["step"]}: '
              f'{stats["pseudo_labels"]} pseudo-labels (peak cut-off {stats["cutoff"]:.3g})',
              file=sys.stderr)
    if summary['warnings']:
        print(f'monet train: {len(summary["warnings"])} WARNING(S), this model may be '
              'unusable:', file=sys.stderr)
        for message in summary['warnings']:
            print(f'  WARNING: {message}', file=sys.stderr)
    if held_path is not None:
        # every subject's, in crops around each (as --validation-labels scores)
        crops = trainer.holdout_error()
        summary['holdout'] = {'instants': held.tolist(), 'crops': crops}
        for line in scored_lines(f'monet train: held-out labelled instants {held.tolist()} '
                                 '(--holdout-labelled), in crops around each subject',
                                 crops, len(held)):
            print(line, file=sys.stderr)
        # as `monet process` runs the model (--subjects N with labels of several subjects)
        from monet_ros.learning.recording import find_recording_parts
        parts = find_recording_parts(args.data)
        configs = {}
        if recording.num_subjects > 1:
            from monet_ros.commands.train_distill import teacher_subject_configs
            configs = teacher or dict(zip(('subjects', 'association', 'tracker'),
                                          teacher_subject_configs(args,
                                                                  recording.num_subjects)))
        figures = score_holdout(parts['bag'], args.rig or parts['rig'], out / 'model.pt',
                                held_path, recording,
                                label_options_from_args(args).camera_map, args.rig_units,
                                **configs)
        per = figures.pop('subjects', None)
        summary['holdout'].update(figures)
        how = (f'as monet process --subjects {configs["subjects"].subjects} runs the model'
               if configs else 'as monet process runs the model')
        print(f'monet train: held-out labelled instants {held.tolist()}: '
              + holdout_text(figures, recording.cameras[0].units)
              + (f' ({how}; every subject pooled)' if per else f' ({how})'), file=sys.stderr)
        if per:
            summary['holdout']['subjects'] = {str(p['subject']): p for p in per}
            for p in per:
                track = f'track {p["track"]}' if p['track'] >= 0 else 'no track matched'
                print(f'  subject {p["subject"]} ({track}): '
                      + holdout_text(p, recording.cameras[0].units), file=sys.stderr)
    print(json_text.dumps(summary, indent=1))
    distributed.shutdown()
    return 0


def holdout_text(figures, units):
    """'2D median 3.1 px, PCK@10px 90% (12 views); 3D median 4.2 mm, mean 5.0 mm (rig in m),
    coverage 100%' of evaluation.reference.score figures. A median that is not a number
    says why: a miss counts as infinitely far (more than half of the labelled views missed:
    an infinite median), no view or point scored (NaN)."""
    import math
    px, mm = figures['px_median'], figures['mm_median']
    two_d = (f'2D median {px:.1f} px' if math.isfinite(px) else
             '2D median: more than half of the labelled views missed' if px == math.inf else
             '2D: no labelled view scored')
    three_d = (f'3D median {mm:.1f} mm, mean {figures["mm_mean"]:.1f} mm' if math.isfinite(mm)
               else '3D: no point scored')
    return (f'{two_d}, PCK@10px {100 * figures["pck2d@10px"]:.0f}% ({figures["views_2d"]} '
            f'views); {three_d} (rig in {units}), coverage {100 * figures["coverage"]:.0f}%')


def scored_lines(what, figures, instants):
    """The lines of held-out labels scored in crops (Trainer.validation_error /
    holdout_error figures of `instants` instants): `what`: pooled median / mean, then one
    line per subject when several were labelled there."""
    lines = [f'{what}: median {figures["median_px"]:.2f} px, mean {figures["mean_px"]:.2f} px '
             f'({figures["count"]} keypoints of {instants} instants, never trained on'
             + (', every subject labelled there' if figures.get('subjects') else '') + ')']
    for subject, e in figures.get('subjects', {}).items():
        lines.append(f'  subject {subject}: median {e["median_px"]:.2f} px, mean '
                     f'{e["mean_px"]:.2f} px ({e["count"]} keypoints, in crops around it)')
    return lines


def check_teacher_options(args, distill, subjects=None):
    """The distillation teacher's several-subject options (add_subject_settings_arguments:
    `monet process --subjects`' own, validated by process.subject_configs): ValueError
    naming the first one given without --distill-rounds, or (subjects: the most labelled
    at an instant, once the labels are read) with labels of one subject, or with a bad
    value. Returns train_with_distillation's {subjects, association, tracker} ({} with one
    subject or before the labels are read)."""
    from monet_ros.commands.common import check_subject_only_options
    from monet_ros.commands.train_distill import teacher_subject_configs
    check_subject_only_options(
        args, distill, 'monet train', needs='--distill-rounds N (the teacher of labels of '
        'several subjects)', without='has no distillation teacher without it')
    if subjects is None:
        if distill:                    # the values, before the recording is read
            teacher_subject_configs(args, 2)
        return {}
    check_subject_only_options(
        args, not distill or subjects > 1, 'monet train',
        needs='labels of several subjects (a subject column; the teacher then runs `monet '
        'process --subjects N`)', without='has labels of one subject: its teacher runs `monet '
        'process` on one')
    if not distill or subjects < 2:
        return {}
    return dict(zip(('subjects', 'association', 'tracker'),
                    teacher_subject_configs(args, subjects)))


def check_distill_options(args, config):
    """ValueError naming the first distillation setting (DISTILL_SETTINGS) given on the
    command line without --distill-rounds N >= 1: the run has no round to use it."""
    from monet_ros.commands.common import check_applies
    from monet_ros.learning.config import DISTILL_SETTINGS
    check_applies([_option(name) for name in DISTILL_SETTINGS
                   if getattr(args, name, None) is not None], config.distill_rounds > 0,
                  'monet train', needs='--distill-rounds N (N >= 1)',
                  without='has no distillation round without it')


def check_something_to_distil(data, config):
    """ValueError naming --distill-rounds when every view x keypoint of the training
    instants is labelled (train_distill.distill_cells: none left): the teacher would run
    over the recording for nothing."""
    import numpy as np

    from monet_ros.commands.train_distill import distill_cells
    if not distill_cells(data).any():
        training = len(np.setdiff1d(data.train, data.validation_instants))
        raise ValueError(f'--distill-rounds {config.distill_rounds}: every view x keypoint of '
                         f'the {training} training '
                         'instants is labelled: nothing unlabelled to distil (the teacher '
                         'would run for nothing); train with --distill-rounds 0')


def _option(name):
    """The option of TrainConfig field `name` (--its-name)."""
    return '--' + name.replace('_', '-')


def _unused_terms_text(args, config):
    """'; mode reprojection has no L_E (--lambda-e 3 not used), no L_T (...)' for the weights
    of loss terms given on the command line that the mode does not train (TrainConfig is
    shared by every mode: such a weight is legal, and unused: said, not refused), '' when
    none."""
    from monet_ros.learning.config import TERM_WEIGHTS
    terms = config.spec.terms
    unused = [(term, name) for term, name in TERM_WEIGHTS.items()
              if term != 'D' and term not in terms and getattr(args, name, None) is not None]
    if not unused:
        return ''
    return f'; mode {config.mode} has ' + ', '.join(
        f'no L_{term} ({_option(name)} {getattr(config, name):g} not used)'
        for term, name in unused)


def skeleton_line(skeleton, given):
    """'skeleton NAME (FILE), C keypoints: a, b, ...' (the start-up line of `monet train`):
    which skeleton the heatmap channels are, a preset's file or the YAML given."""
    from monet_ros.skeleton import skeleton_path
    path, preset = skeleton_path(given)
    source = f'preset {path}' if preset else str(given)
    names = list(skeleton.keypoints)
    shown = ', '.join(names[:8]) + (', ...' if len(names) > 8 else '')
    return (f'skeleton {skeleton.name} ({source}), {len(names)} keypoints: {shown} '
            '(--skeleton to choose another)')


def _labels_text(recording, config):
    """Where the labelled instants went, for the error of a run left with none to train on:
    none in the labels, or all held out by --eval-fraction / --validation-labels."""
    import numpy as np

    from monet_ros.learning.trainer import split_instants
    labelled = recording.labelled_instants
    if not len(labelled):
        return ('the labels have no instant of this recording: give --labels (or a labels.csv '
                'beside the recording)')
    text = (f'{len(labelled)} labelled instants (indices {labelled.tolist()[:8]}) of '
            f'{recording.num_instants}')
    if config.eval_fraction > 0:
        held = np.intersect1d(labelled, split_instants(recording.num_instants,
                                                       config.eval_fraction)[1])
        text += (f', {len(held)} of them in the last {config.eval_fraction:.0%} of the '
                 f'instants, held out by --eval-fraction {config.eval_fraction:g} (the '
                 'default 0 trains on every instant)')
    if config.validation_labels > 0:
        text += (f'; --validation-labels {config.validation_labels:g} holds out a share of '
                 'the labelled instants')
    return text


def _gate_text(gate):
    """' (of N tracked: D beyond --pseudo-max-frames dropped, K of those kept as confirmed)'
    for the start-up line, '' without the gate."""
    if not gate:
        return ''
    return (f' (of {gate["tracked"]} tracked view labels: {gate["dropped"]} beyond '
            f'--pseudo-max-frames dropped, {gate["confirmed"]} beyond it kept as confirmed by '
            'a second track)')


def _rows_text(data):
    """' (unlabelled (instant, subject) rows: subject 0 N, subject 1 M)' for the start-up
    line when subjects other than 0 have their own unlabelled rows, '' otherwise."""
    rows = data.unlabeled_rows_per_subject()
    if len(rows) < 2:
        return ''
    return (' (unlabelled (instant, subject) rows: '
            + ', '.join(f'subject {s} {n}' for s, n in rows.items()) + ')')


if __name__ == '__main__':
    p = argparse.ArgumentParser()
    add_arguments(p)
    sys.exit(run(p.parse_args()))
