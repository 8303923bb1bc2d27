"""`monet eval`: PCK and reprojection-error tables (rows = modes, columns = datasets)."""
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


def run(args):
    import numpy as np

    from monet_ros.evaluation import load_summaries, markdown_table, write_report
    from monet_ros.evaluation.evaluate import evaluate_detector
    from monet_ros.learning.recording import RecordingError, load_recording
    from monet_ros.learning.trainer import crop_boxes
    from monet_ros.models import CheckpointError
    from monet_ros.models.detector import Detector

    if args.threads:
        import torch
        torch.set_num_threads(args.threads)
    if args.from_json:
        summaries = load_summaries(args.from_json)
    else:
        if not args.checkpoints or not args.data:
            print('monet eval: give checkpoints and --data (or --from-json)', file=sys.stderr)
            return 2
        try:
            recordings = [load_recording(d, skeleton=args.skeleton) for d in args.data]
        except (RecordingError, ValueError, OSError) as error:
            print(f'monet eval: {error}', file=sys.stderr)
            return 1
        for data, recording in zip(args.data, recordings):
            if recording.read_report.notice(data):
                print(f'monet eval: {recording.read_report.notice(data)}', file=sys.stderr)
        summaries = []
        for path in args.checkpoints:
            try:
                detector = Detector.from_checkpoint(path, device=args.device)
            except CheckpointError as error:
                print(f'monet eval: {error}', file=sys.stderr)
                return 1
            meta = detector.metadata
            named = [r for r in recordings if r.name == meta.get('recording')]
            cfg = meta.get('train_config', {})
            for rec in named or recordings:
                if list(rec.keypoints) != list(meta['keypoints']):
                    print(f'monet eval: {path}: keypoints {meta["keypoints"]} differ from '
                          f"{rec.name}'s skeleton", file=sys.stderr)
                    return 1
                start = meta.get('held_out_from_stamp_ns')
                if args.instants == 'all' or start is None:
                    instants = np.arange(rec.num_instants)
                else:
                    instants = np.flatnonzero(rec.stamps >= int(start))
                h, w = detector.input_size
                boxes = crop_boxes(rec, cfg.get('box_source', 'auto'), w / h,
                                   cfg.get('box_margin', 0.25))
                mode = meta.get('mode') or Path(path).stem
                summary = evaluate_detector(detector, rec, instants, boxes, mode, rec.name)
                summary.extra['checkpoint'] = str(path)
                summary.extra['step'] = meta.get('step')
                summaries.append(summary)
    paths = write_report(args.out, summaries)
    print(markdown_table(summaries), end='')
    print('written: ' + ', '.join(str(p) for p in paths.values()), file=sys.stderr)
    return 0
