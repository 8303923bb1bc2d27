"""`monet eval CKPT... --data REC --reference REF`: every checkpoint run over the recording
exactly as `monet process` runs it (the same function, tracked crops), then scored against
a reference (monet_ros.evaluation.reference): ONE row per checkpoint with 2D pixel error
and PCK@px on labelled views (a 3D reference: on its projection into the cameras), 3D
error in mm (median / mean / p90), PCK@mm and coverage.

Instants scored: those with a reference, less the instants labelled in the training
labels (--labels, or for a 3D reference the data folder's labels.csv) unless
--include-labelled: a model is not scored on what it was trained on. The command says
which (ranges of instant indices) and writes them to OUT/reference_instants.csv (frame,
stamp_ns, status: scored / labelled / no reference). Writes OUT/reference.csv and
OUT/reference.json.
"""
import csv
import json
from pathlib import Path
import sys
import tempfile

import numpy as np


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


def _has_reference(reference):
    """(T,) bool: instants where the reference has a 3D point or a 2D point."""
    has = np.isfinite(reference.X).all(-1).any(-1)
    if reference.points2d is not None:
        has |= np.isfinite(reference.points2d).all(-1).any(axis=(1, 2))
    return has


def _scored_instants(args, reference, bag_path):
    """(T,) bool scored, (T,) bool labelled (with a reference), labels path or None: the
    rule of the module docstring. ValueError when labelled instants leave none."""
    from monet_ros.evaluation.reference import labelled_instants
    from monet_ros.learning.recording import find_recording_parts

    has_ref = _has_reference(reference)
    path = args.labels or (find_recording_parts(bag_path)['labels']
                           if reference.kind == '3d' else None)
    labelled = has_ref & (labelled_instants(path, reference.stamps) if path else False)
    scored = has_ref if args.include_labelled else has_ref & ~labelled
    if has_ref.any() and not scored.any():
        raise ValueError(f'--reference {args.reference}: every instant with a reference is '
                         f'labelled in {path} (the training labels); --include-labelled '
                         'scores them')
    return scored, labelled, path


def _write_instants(path, reference, scored, labelled):
    """frame, stamp_ns, status (scored / labelled / no reference) of every instant."""
    with open(path, 'w', newline='') as f:
        w = csv.writer(f, lineterminator='\n')
        w.writerow(['frame', 'stamp_ns', 'status'])
        for t, stamp in enumerate(reference.stamps):
            status = 'scored' if scored[t] else 'labelled' if labelled[t] else 'no reference'
            w.writerow([t, int(stamp), status])


def run_reference(args):
    from monet_ros.commands.labels import label_options_from_args
    from monet_ros.commands.process import process_recording
    from monet_ros.evaluation.reference import alignment_text, load_reference, score
    from monet_ros.io.export_tables import ExportError, read_anipose_csv
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
        px = _thresholds(args.px_thresholds, '--px-thresholds')
        mm = _thresholds(args.mm_thresholds, '--mm-thresholds')
        options = label_options_from_args(args)
        index = recording_index(args.data[0], rig=args.rig, camera_map=options.camera_map,
                                rig_units=args.rig_units)
        references = {}
        with tempfile.TemporaryDirectory(prefix='monet-eval-') as tmp:
            for n, path in enumerate(args.checkpoints):
                _, meta = load_checkpoint(path)
                keypoints = tuple(meta['keypoints'])
                if keypoints not in references:
                    ref = load_reference(
                        args.reference, index, keypoints, fmt=args.reference_format,
                        options=options, axes=args.reference_axes,
                        reference_fps=args.reference_fps,
                        rate_policy=args.reference_rate_mismatch)
                    references[keypoints] = (ref, *_scored_instants(args, ref,
                                                                    args.data[0]))
                reference, scored, labelled, labels_path = references[keypoints]
                out = Path(tmp) / f'run{n}'
                process_recording(index.bag, path, out, rig=args.rig, device=args.device,
                                  progress=False, exports=('csv', 'npz'),
                                  camera_map=options.camera_map, rig_units=args.rig_units)
                table = read_anipose_csv(out / 'keypoints3d.csv')
                det = np.load(out / 'detections2d.npz')
                names = [c.name for c in index.cameras]
                order = [list(det['cameras']).index(c) if c in det['cameras'] else None
                         for c in names]
                p2 = np.full((len(table['stamps_ns']), len(names), len(keypoints), 2), np.nan)
                for v, o in enumerate(order):
                    if o is not None:
                        p2[:, v] = det['points2d'][:, o]
                figures = score(reference, table['stamps_ns'], table['X'], p2, px, mm,
                                instants=scored)
                rows.append(dict(checkpoint=str(path), mode=meta.get('mode') or Path(path).stem,
                                 step=meta.get('step'), **figures))
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
    (out_dir / 'reference.json').write_text(json.dumps(rows, indent=1))
    ref, scored, labelled, labels_path = next(iter(references.values()))
    _write_instants(out_dir / 'reference_instants.csv', ref, scored, labelled)
    cols = ['mode', 'step', 'px_median', *[f'pck2d@{t:g}px' for t in px], 'mm_median',
            'mm_mean', 'mm_p90', *[f'pck3d@{t:g}mm' for t in mm], 'coverage']
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
        cells = [r['checkpoint']] + [
            f'{r[c]:.3g}' if isinstance(r[c], float) else str(r[c]) for c in cols]
        print('| ' + ' | '.join(cells) + ' |')
    print('written: ' + str(out_dir / 'reference.csv'), file=sys.stderr)
    return 0
