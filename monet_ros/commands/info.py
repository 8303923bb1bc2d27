"""`monet info REC [--labels L]`: what a recording holds - topics, cameras, instants
(frame indices), stamps (first / last / rate) and which instants are labelled.

Frame indices are those that frame-indexed labels (frame,camera,keypoint,u,v) and the
importers use: the 0-based index of each multiview instant (views grouped by header
stamp), incomplete instants included.
"""
import sys

import numpy as np

HELP = 'list topics, cameras, instants, stamps and labelled instants of a recording'


def _ranges(indices):
    """[1, 2, 3, 7] -> '1-3, 7'."""
    out, run = [], []
    for i in indices:
        if run and i == run[-1] + 1:
            run.append(i)
            continue
        if run:
            out.append(f'{run[0]}-{run[-1]}' if len(run) > 1 else str(run[0]))
        run = [i]
    if run:
        out.append(f'{run[0]}-{run[-1]}' if len(run) > 1 else str(run[0]))
    return ', '.join(out)


def _training_note(keypoints, skeleton):
    """Without --skeleton (the labels' keypoints are the file's): which of them `monet
    train`'s default skeleton lacks, whose rows it refuses (a line for the report), or ''
    when it has them all. With --skeleton the labels were checked against it already."""
    if skeleton:
        return ''
    from monet_ros.commands.train import DEFAULT_SKELETON
    from monet_ros.skeleton import load_skeleton
    known = set(load_skeleton(DEFAULT_SKELETON).keypoints)
    outside = [k for k in keypoints if k not in known]
    if not outside:
        return f"every keypoint of the file is in {DEFAULT_SKELETON}, monet train's default"
    return (f"{len(outside)} of the file's {len(keypoints)} keypoints are not in "
            f"{DEFAULT_SKELETON}, monet train's default skeleton, which refuses their rows: "
            f'{", ".join(outside)} (give monet train --skeleton with them, or --keypoint-map '
            'SRC=DST)')


def add_arguments(parser):
    from monet_ros.commands.labels import add_label_arguments
    parser.add_argument('rec', help='recording: rosbag2 folder, .mcap or `monet synth` folder')
    parser.add_argument('--rig', help="rig file (default: the recording's)")
    from monet_ros.commands.common import add_rig_units_argument
    add_rig_units_argument(parser)
    parser.add_argument('--labels', help='labels CSV (stamp- or frame-keyed) to check against '
                        'the recording and list')
    parser.add_argument('--skeleton', default=None, help='skeleton preset or YAML for '
                        '--labels (default: the keypoints named in the file)')
    parser.add_argument('--stamps', action='store_true', help='print every instant: frame '
                        'index, stamp_ns, complete')
    add_label_arguments(parser)


def run(args):
    from monet_ros.commands.labels import label_options_from_args
    from monet_ros.labels import LabelError, read_label_rows, resolve_labels
    from monet_ros.learning.recording import RecordingError
    from monet_ros.learning.recording_index import recording_index
    from monet_ros.skeleton import SkeletonError, load_skeleton

    try:
        options = label_options_from_args(args)
        index = recording_index(args.rec, rig=args.rig, camera_map=options.camera_map,
                                rig_units=args.rig_units)
        labels = report = None
        if args.labels:
            rows = read_label_rows(args.labels)
            mapped = dict(options.keypoint_map)
            keypoints = (tuple(load_skeleton(args.skeleton).keypoints) if args.skeleton
                         else tuple(dict.fromkeys(mapped.get(r.keypoint, r.keypoint)
                                                  for r in rows)))
            labels, report = resolve_labels(rows, index.stamps, index.cameras, keypoints,
                                            options, valid=index.complete)
            training = _training_note(keypoints, args.skeleton)
    except (LabelError, RecordingError, SkeletonError, ValueError, OSError) as error:
        print(f'monet info: {error}', file=sys.stderr)
        return 2
    out = sys.stdout
    print(f'recording: {index.bag}', file=out)
    for note in index.notes or ():
        print(f'note: {note}', file=out)
    print('topics:', file=out)
    for info in sorted(index.reader.topics.values(), key=lambda t: t.name):
        count = '?' if info.count is None else info.count
        print(f'  {info.name}  {info.msgtype}  {count} messages', file=out)
    print(f'cameras (rig length unit {index.cameras[0].units}):', file=out)
    for cam in index.cameras:
        print(f'  {cam.name}  {cam.width}x{cam.height}  fx {cam.K[0, 0]:.1f} fy '
              f'{cam.K[1, 1]:.1f}  image topic {index.topics[cam.name]}', file=out)
    stamps = index.stamps
    T = len(stamps)
    period = float(np.median(np.diff(stamps))) if T > 1 else 0.0
    rate = f'{1e9 / period:.3f} Hz' if period > 0 else 'n/a'
    print(f'instants: {T} (frames 0-{T - 1}), {int(index.complete.sum())} complete, '
          f'{T - int(index.complete.sum())} missing a view', file=out)
    print(f'stamps: first {stamps[0]} ns, last {stamps[-1]} ns, rate {rate} '
          f'(median period {period:.0f} ns)', file=out)
    if args.stamps:
        for i, (s, c) in enumerate(zip(stamps, index.complete)):
            print(f'  {i} {s} {"complete" if c else "incomplete"}', file=out)
    if labels is not None:
        where = {int(s): i for i, s in enumerate(stamps)}
        frames = sorted(where[s] for s in labels.stamps)
        print(f'labels: {args.labels}: {report.summary()}', file=out)
        print(f'labelled instants ({len(frames)}): {_ranges(frames) or "none"}', file=out)
        if training:
            print(f'skeleton: {training}', file=out)
        if labels.subjects not in ([], [0]):
            print(f'subjects: {", ".join(map(str, labels.subjects))} (the labels\' subject '
                  'column; ids within an instant)', file=out)
        counts = {}
        for _, cam, *_ in labels.subject_rows():
            counts[cam] = counts.get(cam, 0) + 1
        for cam in index.cameras:
            print(f'  {cam.name}: {counts.get(cam.name, 0)} labelled keypoints', file=out)
    report = index.reader.report
    if report is not None and not report.ok:
        print(f'monet info: reading {args.rec}: {report.summary()}', file=sys.stderr)
    return 0
