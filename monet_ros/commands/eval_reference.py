"""`monet eval CKPT... --data REC --reference REF`: every checkpoint run over the recording
exactly as `monet process` runs it (the same function, tracked crops), then scored against
a reference (monet_ros.evaluation.reference): ONE row per checkpoint with 2D pixel error
and PCK@px on labelled views (a 3D reference: on its projection into the cameras), 3D
error in mm (median / mean / p90), PCK@mm and coverage.

Several subjects (`--subjects N`, N >= 2; labels with a `subject` column, or an importer's
tracks / individuals): every checkpoint runs as `monet process --subjects N` runs it (the
same function, commands.model_run.run_model; the several-subject settings are that
command's options) and every reference subject is scored against the track matched to it
(evaluation.reference.score_subjects: one-to-one, least mean 3D distance over the scored
instants both have, the labels' own triangulation against the track's 3D): the
checkpoint's row is then the pooled figures (subject `all`) and one row per reference
subject follows (subject, track: the matched identity or -1, match_mm: the pair's mean 3D
distance in mm, and its own figures). A reference of several subjects without --subjects N
is refused (one line naming the file, the field subject and --subjects); a reference of
one subject is scored against its matched track.

Instants scored: those with a reference, less the instants labelled in the training
labels (--labels, or for a 3D reference the data folder's labels.csv) unless
--include-labelled: a model is not scored on what it was trained on. The command says
which (ranges of instant indices) and writes them to OUT/reference_instants.csv (frame,
stamp_ns, status: scored / labelled / no reference). Writes OUT/reference.csv and
OUT/reference.json.
"""
import csv
import math
from pathlib import Path
import sys

import numpy as np

from monet_ros import json_text


def add_reference_arguments(parser):
    parser.add_argument('--reference', help='score against this reference instead of a synth '
                        'ground truth: labels CSV, DeepLabCut/Lightning Pose/SLEAP/anipose/'
                        'DANNCE labels, TRC or anipose 3D CSV')
    parser.add_argument('--reference-format', default='auto',
                        choices=('auto', 'trc', 'anipose3d', 'labels', 'dlc', 'lightning-pose',
                                 'sleap', 'anipose', 'dannce'),
                        help='reference format (default: from the file)')
    parser.add_argument('--reference-axes', choices=('xyz', 'yzx'), default='xyz',
                        help='TRC axes: yzx for a Y-up file (Pose2Sim)')
    parser.add_argument('--reference-fps', type=float, default=None,
                        help="rate of an anipose CSV's fnum without stamp_ns (default: the "
                        "recording's)")
    parser.add_argument('--reference-rate-mismatch', choices=('resample', 'refuse'),
                        default='resample', help='a 3D reference at another rate than the '
                        'recording: interpolate it linearly in time at the instants '
                        '(default) or refuse')
    parser.add_argument('--include-labelled', action='store_true',
                        help='also score the instants labelled in the training labels '
                        "(--labels; for a 3D reference also the data folder's labels.csv), "
                        'which are left out by default')
    parser.add_argument('--rig', help="rig file (default: the recording's)")
    from monet_ros.commands.common import add_rig_units_argument
    add_rig_units_argument(parser)
    parser.add_argument('--subjects', type=int, default=1, metavar='N',
                        help='with --reference: run the checkpoints as `monet process '
                        '--subjects N` (N >= 2) and score every subject of the reference '
                        '(labels with a subject column), each against the track matched to '
                        'it (1 = one subject)')
    from monet_ros.commands.common import add_subject_settings_arguments
    add_subject_settings_arguments(parser)
    parser.add_argument('--px-thresholds', default='5,10,20', help='2D PCK thresholds (px)')
    parser.add_argument('--mm-thresholds', default='25,50,100', help='3D PCK thresholds (mm)')


def _thresholds(text, flag):
    try:
        values = tuple(float(t) for t in str(text).split(',') if t.strip())
    except ValueError:
        values = ()
    if not values or not all(np.isfinite(v) and v > 0 for v in values):
        raise ValueError(f'{flag}: expected positive numbers separated by commas, got {text!r}')
    return values


def _has_reference(references):
    """(T,) bool: instants where a reference (of any subject) has a 3D or a 2D point."""
    has = np.zeros(len(references[0].stamps), bool)
    for reference in references:
        has |= np.isfinite(reference.X).all(-1).any(-1)
        if reference.points2d is not None:
            has |= np.isfinite(reference.points2d).all(-1).any(axis=(1, 2))
    return has


def _scored_instants(args, references, bag_path):
    """(T,) bool scored, (T,) bool labelled (with a reference), labels path or None: the
    rule of the module docstring (references: every subject's, on the same instants).
    ValueError when labelled instants leave none."""
    from monet_ros.evaluation.reference import labelled_instants
    from monet_ros.learning.recording import find_recording_parts

    reference = references[0]
    has_ref = _has_reference(references)
    path = args.labels or (find_recording_parts(bag_path)['labels']
                           if reference.kind == '3d' else None)
    labelled = has_ref & (labelled_instants(path, reference.stamps) if path else False)
    scored = has_ref if args.include_labelled else has_ref & ~labelled
    if has_ref.any() and not scored.any():
        raise ValueError(f'--reference {args.reference}: every instant with a reference is '
                         f'labelled in {path} (the training labels); --include-labelled '
                         'scores them')
    return scored, labelled, path


MISSED = 'missed'   # the table's word for an infinite median: more misses than detections


def table_cell(value):
    """The printed table's text of a reference.csv value: floats to 3 significant digits, an
    infinite median of misses as MISSED (the csv keeps inf, reference.json null)."""
    if isinstance(value, float):
        return MISSED if value == math.inf else f'{value:.3g}'
    return str(value)


def _write_instants(path, reference, scored, labelled):
    """frame, stamp_ns, status (scored / labelled / no reference) of every instant."""
    with open(path, 'w', newline='') as f:
        w = csv.writer(f, lineterminator='\n')
        w.writerow(['frame', 'stamp_ns', 'status'])
        for t, stamp in enumerate(reference.stamps):
            status = 'scored' if scored[t] else 'labelled' if labelled[t] else 'no reference'
            w.writerow([t, int(stamp), status])


def subject_configs_of(args, owner):
    """(subjects, association, tracker) of `monet eval --subjects N` (N >= 2: process.
    subject_configs on `monet process`' default ProcessConfig, the run's) or (None, None,
    None) for one subject (a several-subject option then refused: ValueError naming it)."""
    from monet_ros.commands.common import check_subject_only_options
    from monet_ros.commands.process import ProcessConfig, subject_configs
    several = args.subjects != 1
    check_subject_only_options(args, several, owner, without='scores one subject without it')
    if not several:
        return None, None, None
    return subject_configs(args, config=ProcessConfig())


def run_reference(args):
    from monet_ros.commands.common import print_precision
    from monet_ros.commands.labels import label_options_from_args
    from monet_ros.evaluation.reference import alignment_text, load_reference, load_references
    from monet_ros.io.export_tables import ExportError
    from monet_ros.labels import LabelError
    from monet_ros.learning.recording import RecordingError
    from monet_ros.learning.recording_index import recording_index
    from monet_ros.models import CheckpointError, load_checkpoint

    prog = 'monet eval'
    if len(args.data) != 1 or not args.checkpoints:
        print(f'{prog}: --reference needs checkpoints and exactly one --data recording',
              file=sys.stderr)
        return 2
    rows = []
    try:
        subjects, association, tracker = subject_configs_of(args, prog)
        px = _thresholds(args.px_thresholds, '--px-thresholds')
        mm = _thresholds(args.mm_thresholds, '--mm-thresholds')
        options = label_options_from_args(args)
        index = recording_index(args.data[0], rig=args.rig, camera_map=options.camera_map,
                                rig_units=args.rig_units)
        references = {}
        # the models run as `monet process` runs them: its default precision, said once
        print_precision(prog, 'auto', 'auto', args.device or None)
        from monet_ros.commands.model_run import run_model, score_run
        for path in args.checkpoints:
            _, meta = load_checkpoint(path)
            keypoints = tuple(meta['keypoints'])
            if keypoints not in references:
                load = load_references if subjects is not None else load_reference
                refs = load(args.reference, index, keypoints, fmt=args.reference_format,
                            options=options, axes=args.reference_axes,
                            reference_fps=args.reference_fps,
                            rate_policy=args.reference_rate_mismatch)
                refs = refs if subjects is not None else [refs]
                references[keypoints] = (refs, *_scored_instants(args, refs, args.data[0]))
            refs, scored, labelled, labels_path = references[keypoints]
            run = run_model(index.bag, path, index.cameras, rig=args.rig, device=args.device,
                            camera_map=options.camera_map, rig_units=args.rig_units,
                            subjects=subjects, association=association, tracker=tracker)
            figures = score_run(refs, run, px, mm, instants=scored)
            row = dict(checkpoint=str(path), mode=meta.get('mode') or Path(path).stem,
                       step=meta.get('step'))
            per = figures.pop('subjects', None)
            if per is None:
                rows.append(dict(row, **figures))
            else:          # the pooled row, then one row per reference subject
                rows.append(dict(row, subject='all', track='', match_mm='', **figures))
                rows += [dict(row, **p) for p in per]
    except (LabelError, ExportError, RecordingError, CheckpointError, ValueError,
            OSError) as error:
        print(f'{prog}: {error}', file=sys.stderr)
        return 2
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(out_dir / 'reference.csv', 'w', newline='') as f:
        w = csv.DictWriter(f, fieldnames=keys, lineterminator='\n')
        w.writeheader()
        w.writerows(rows)
    (out_dir / 'reference.json').write_text(json_text.dumps(rows, indent=1))
    refs, scored, labelled, labels_path = next(iter(references.values()))
    ref = refs[0]
    _write_instants(out_dir / 'reference_instants.csv', ref, scored, labelled)
    cols = ['mode', 'step', 'subject', 'track', 'px_median',
            *[f'pck2d@{t:g}px' for t in px], 'mm_median', 'mm_mean', 'mm_p90',
            *[f'pck3d@{t:g}mm' for t in mm], 'coverage']
    cols = [c for c in cols if c in keys]
    two_d = (f', {rows[0].get("views_2d")} labelled views' if ref.kind == '2d' else
             f'; 2D: its projection into the {len(index.cameras)} cameras '
             f'({rows[0].get("views_2d")} points inside the images, occlusion unknown)')
    print(f'reference: {args.reference} ({ref.kind}, {rows[0]["joints_3d"]} joints in 3D'
          + two_d + (f'; not in the model: {", ".join(ref.unused)}' if ref.unused else '')
          + ')')
    print(f'3D errors in mm (the rig and the 3D in {ref.units}, converted)')
    if ref.alignment:
        print(f'reference time: {alignment_text(ref.alignment)}')
    if 'subject' in keys:
        print(f'subjects: {len(refs)} in the reference ({", ".join(str(r.subject) for r in refs)}'
              f'), the model run with --subjects {args.subjects}; each reference subject '
              'scored against the track matched to it (one-to-one, least mean 3D distance '
              'over the scored instants both have; track -1: none); rows subject all: '
              'every subject pooled')
    from monet_ros.commands.info import _ranges
    print(f'scored instants: {int(scored.sum())} of {len(scored)} '
          f'({_ranges(np.flatnonzero(scored).tolist())})'
          + (f'; not scored: {int(labelled.sum())} labelled in {labels_path} '
             '(--include-labelled scores them)' if labelled.any() and not
             args.include_labelled else '')
          + f'; listed in {out_dir / "reference_instants.csv"}')
    print('| ' + ' | '.join(['checkpoint', *cols]) + ' |')
    print('|' + '---|' * (len(cols) + 1))
    for r in rows:
        print('| ' + ' | '.join([r['checkpoint']] + [table_cell(r.get(c, '')) for c in cols])
              + ' |')
    if any(r.get('px_median') == math.inf for r in rows):
        print(f'{MISSED}: more than half of the labelled views have no detection (a miss '
              'counts as infinitely far)')
    print('written: ' + str(out_dir / 'reference.csv'), file=sys.stderr)
    return 0
