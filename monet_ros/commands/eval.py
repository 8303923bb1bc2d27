"""`monet eval`: PCK and reprojection-error tables (rows = modes, columns = datasets);
with --reference, accuracy against labels or a 3D reference in px and mm, one row per
checkpoint, and with --subjects N one more per reference subject (commands/
eval_reference.py)."""
from pathlib import Path
import sys

HELP = 'PCK curves and reprojection-error tables against ground truth, PNG plots'


def add_arguments(parser):
    parser.add_argument('checkpoints', nargs='*', help='checkpoint files (model.pt) to evaluate')
    parser.add_argument('--data', action='append', default=[],
                        help='recording with ground truth (repeatable: one column each); a '
                        'checkpoint is evaluated on the data its metadata names, or on every '
                        'data given when it names none of them')
    parser.add_argument('--out', required=True, help='report folder (results.md/csv/json, PNG)')
    parser.add_argument('--skeleton', default='human14', help='skeleton preset or YAML file')
    parser.add_argument('--instants', choices=('held-out', 'all'), default='held-out',
                        help='evaluate on the held-out tail used in training, or everything')
    parser.add_argument('--from-json', help='re-render the report from a results.json')
    parser.add_argument('--device', default=None, help='torch device (default: CUDA if present)')
    parser.add_argument('--threads', type=int, default=0, help='torch CPU threads (0 = default)')
    parser.add_argument('--labels', help="labels CSV for --data (default: the data folder's); "
                        'checked against the recording like monet train')
    from monet_ros.commands.eval_reference import add_reference_arguments
    from monet_ros.commands.labels import add_label_arguments
    add_label_arguments(parser)
    add_reference_arguments(parser)


def scored_instants_text(rec, instants, start, meta, which):
    """(kind, line) saying which instants `monet eval` scores: kind 'held-out' (never
    trained on), 'training' (every one was trained on) or 'mixed' (--instants all over a
    held-out tail); the line counts them."""
    import numpy as np

    n = len(instants)
    if start is None:
        if meta.get('recording') not in (None, rec.name):      # another recording's model
            return 'held-out', (f'all {n} instants (the model was trained on '
                                f'{meta.get("recording")}, not on this recording)')
        return 'training', (f'all {n} instants, which the model was TRAINED on (it was '
                            'trained without a held-out tail, --eval-fraction 0): these '
                            'figures are not generalisation; train with --eval-fraction 0.2 '
                            'to score instants it never saw')
    held = int(np.sum(rec.stamps[instants] >= int(start)))
    if which == 'all' and held < n:
        return 'mixed', (f'all {n} instants (--instants all): {n - held} trained on, {held} '
                         'held out')
    return 'held-out', (f'{n} held-out instants (from instant {int(instants[0])}, never '
                        'trained on)')


def load_results_json(path):
    """EvalSummary list from a results.json (ValueError naming the file and what is wrong)."""
    import json

    from monet_ros.evaluation import load_summaries

    try:
        summaries = load_summaries(path)
    except json.JSONDecodeError as error:
        raise ValueError(f'{path}: not JSON (line {error.lineno}: {error.msg})') from None
    except (KeyError, TypeError, AttributeError, ValueError) as error:
        raise ValueError(f'{path}: not a monet eval results.json ({type(error).__name__}: '
                         f'{error})') from None
    if not summaries:
        raise ValueError(f'{path}: holds no results')
    return summaries


def run(args):
    from monet_ros.commands.common import check_threads, made_output_dir
    from monet_ros.models.device import check_device

    check_threads('monet eval', args.threads)
    device = check_device('monet eval', args.device)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(20, 'output is a file, not a folder', str(out))
    # made now (an unwritable place is named at once); removed again when the run fails or
    # is stopped before writing into it
    with made_output_dir(out):
        return _run(args, out, device)


def _run(args, out, device):
    import numpy as np

    from monet_ros.evaluation import markdown_table, write_report
    from monet_ros.evaluation.evaluate import evaluate_detector
    from monet_ros.learning.recording import load_recording
    from monet_ros.learning.trainer import crop_boxes
    from monet_ros.models.detector import Detector

    if args.reference:
        from monet_ros.commands.eval_reference import run_reference
        return run_reference(args)
    if args.subjects != 1 or any(getattr(args, dest) != default for dest, (default, _) in
                                 (args.subject_only_defaults or {}).items()):
        raise ValueError('--subjects and its settings apply only with --reference (a '
                         'reference of several subjects); monet eval against a synth ground '
                         'truth scores one subject')
    if args.from_json:
        summaries = load_results_json(args.from_json)
    else:
        if not args.checkpoints or not args.data:
            raise ValueError('give checkpoints and --data (or --from-json)')
        from monet_ros.commands.labels import label_options_from_args
        options = label_options_from_args(args)
        recordings = [load_recording(d, skeleton=args.skeleton, labels=args.labels,
                                     label_options=options) for d in args.data]
        for data, rec in zip(args.data, recordings):
            if rec.gt3d is None:
                raise ValueError(f'--data {data}: no ground truth (ground_truth.npz beside '
                                 'the recording); monet eval needs 3D ground truth (or give '
                                 '--reference)')
        for data, recording in zip(args.data, recordings):
            if recording.read_report.notice(data):
                print(f'monet eval: {recording.read_report.notice(data)}', file=sys.stderr)
        summaries = []
        for path in args.checkpoints:
            detector = Detector.from_checkpoint(path, device=device)
            meta = detector.metadata
            named = [r for r in recordings if r.name == meta.get('recording')]
            cfg = meta.get('train_config', {})
            for rec in named or recordings:
                if list(rec.keypoints) != list(meta['keypoints']):
                    raise ValueError(f'{path}: keypoints {meta["keypoints"]} differ from '
                                     f"{rec.name}'s skeleton {list(rec.keypoints)}")
                start = meta.get('held_out_from_stamp_ns')
                if args.instants == 'all' or start is None:
                    instants = np.arange(rec.num_instants)
                else:
                    instants = np.flatnonzero(rec.stamps >= int(start))
                if len(instants) == 0:
                    raise ValueError(f'{path}: no held-out instant of {rec.name} (held out '
                                     f'from stamp {start}); use --instants all')
                kind, line = scored_instants_text(rec, instants, start, meta, args.instants)
                print(f'monet eval: {path} on {rec.name}: {line}', file=sys.stderr)
                h, w = detector.input_size
                boxes = crop_boxes(rec, cfg.get('box_source', 'auto'), w / h,
                                   cfg.get('box_margin', 0.25))
                mode = meta.get('mode') or Path(path).stem
                summary = evaluate_detector(detector, rec, instants, boxes, mode, rec.name)
                summary.extra['checkpoint'] = str(path)
                summary.extra['instants_scored'] = kind
                failed = summary.extra['reprojection_failures']
                if failed:
                    print(f'monet eval: {path} on {rec.name}: {failed} of '
                          f'{failed + summary.extra["reprojection_count"]} view reprojection '
                          'errors beyond the image diagonal (views that do not agree at all) '
                          'counted as failures, not in the mean', file=sys.stderr)
                summary.extra['step'] = meta.get('step')
                summaries.append(summary)
    paths = write_report(out, summaries)
    print(markdown_table(summaries), end='')
    print('written: ' + ', '.join(str(p) for p in paths.values()), file=sys.stderr)
    return 0
