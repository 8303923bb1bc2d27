"""`monet labels import FORMAT PATH --rec REC --out labels.csv`: labels of other tools ->
the canonical stamp-keyed labels CSV of a recording (monet_ros.labels), checked by the one
label validator. Also the label options shared by train, eval and info.

Formats (monet_ros.labels_import): dlc (DeepLabCut / Lightning Pose CollectedData CSV or
H5), sleap (SLEAP analysis HDF5 or .slp), anipose (pose-2d H5 per camera), dannce (Label3D .mat),
frames (frame-indexed CSV frame,camera,keypoint,u,v), stamps (stamp-keyed CSV).
"""
import sys

HELP = 'import labels (DeepLabCut, Lightning Pose, SLEAP, anipose, DANNCE, CSV) for a recording'


def add_label_arguments(parser):
    """--camera-map, --keypoint-map, --skip-bad-labels (one spelling for every command)."""
    parser.add_argument('--camera-map', action='append', default=[], metavar='SRC=DST',
                        help="rename label cameras to the recording's (e.g. cam_01=cam01; "
                        'repeatable or comma separated)')
    parser.add_argument('--keypoint-map', action='append', default=[], metavar='SRC=DST',
                        help="rename label / reference keypoints to the skeleton's, or a "
                        'shipped map: body25, body25b (Pose2Sim .trc), coco17, halpe26 -> '
                        'human14 (repeatable)')
    parser.add_argument('--skip-bad-labels', action='store_true',
                        help='drop and count label rows that match no camera, keypoint or '
                        'instant or lie outside the image (default: such a row is an error)')


def label_options_from_args(args):
    """LabelOptions of the arguments above (LabelError on a bad map entry)."""
    from monet_ros.labels import LabelOptions
    return LabelOptions(camera_map=tuple(args.camera_map), keypoint_map=tuple(args.keypoint_map),
                        skip_bad=bool(args.skip_bad_labels))


def resize_hint(bag, label_scale):
    """'; this recording ... --label-scale S' when its import record says how it was resized
    (and --label-scale asked for something else), else ''."""
    from monet_ros.io.source_sizes import SourceSizeError, read_source_sizes
    try:
        record = read_source_sizes(bag)
    except SourceSizeError:
        return ''
    if record is None or record[0] == 1.0 or str(label_scale) == f'{record[0]:g}':
        return ''
    return (f'; this recording was imported with --resize {record[0]:g}: --label-scale '
            f'{record[0]:g} for labels of its videos')


def add_arguments(parser):
    from monet_ros.geometry.pose2sim import POSE_MODELS
    from monet_ros.labels_import import FORMATS
    sub = parser.add_subparsers(dest='labels_command', metavar='ACTION')
    sub.required = True
    imp = sub.add_parser('import', help='convert labels to the labels CSV of a recording',
                         description=__doc__.split('\n\n')[0])
    imp.add_argument('format', choices=sorted(FORMATS), help='source format')
    imp.add_argument('path', nargs='+', help='labels file(s) or project folder')
    imp.add_argument('--rec', required=True, help='recording (rosbag2 folder, .mcap or '
                     '`monet synth` folder) whose instants and cameras the labels refer to')
    imp.add_argument('--rig', help="rig file (default: the recording's)")
    from monet_ros.commands.common import add_rig_units_argument
    add_rig_units_argument(imp)
    imp.add_argument('--out', required=True, help='output labels CSV (stamp_ns,camera,...)')
    imp.add_argument('--skeleton', default=None, help='skeleton preset or YAML (default: the '
                     'keypoints found in the labels, in their order)')
    imp.add_argument('--camera', help='camera of every row (single-camera files whose name '
                     'does not contain the camera name)')
    imp.add_argument('--min-score', type=float, default=0.0,
                     help='drop points whose likelihood/score is below this (anipose, SLEAP '
                     'predictions; counted)')
    imp.add_argument('--pose-model', choices=tuple(POSE_MODELS), default=None,
                     help="openpose: the keypoint names (default: the --skeleton's when it "
                     'has as many, else the one model with that many)')
    imp.add_argument('--label-scale', default='auto', metavar='auto|S',
                     help="labels made on the videos of a recording imported with --resize: "
                     "auto (default) scales other tools' labels (not frames / stamps) from "
                     'the videos to the recording as monet import videos recorded it; S: '
                     "scale every label by S (the recording's size / the labels' images' "
                     "size; 1 = already in the recording's pixels)")
    add_label_arguments(imp)


def run(args):
    from monet_ros.labels import LabelError, LabelResolutionError, resolve_labels, write_labels
    from monet_ros.labels_import import import_labels, to_recording_pixels
    from monet_ros.learning.recording import RecordingError
    from monet_ros.learning.recording_index import recording_index
    from monet_ros.skeleton import SkeletonError, load_skeleton

    try:
        options = label_options_from_args(args)
        index = recording_index(args.rec, rig=args.rig, camera_map=options.camera_map,
                                rig_units=args.rig_units)
        cameras = [c.name for c in index.cameras]
        skeleton = tuple(load_skeleton(args.skeleton).keypoints) if args.skeleton else None
        reader_options = (dict(pose_model=args.pose_model, keypoints=skeleton,
                               keypoint_map=dict(options.keypoint_map))
                          if args.format == 'openpose' else None)
        result = import_labels(args.format, args.path, cameras=cameras, camera=args.camera,
                               min_score=args.min_score, camera_map=dict(options.camera_map),
                               options=reader_options)
        rows, scaled = to_recording_pixels(result.rows, args.format, index.bag,
                                           args.label_scale, dict(options.camera_map))
        if skeleton:
            keypoints = skeleton
        else:
            mapped = dict(options.keypoint_map)
            keypoints = tuple(dict.fromkeys(mapped.get(k, k) for k in result.keypoints))
        try:
            labels, report = resolve_labels(rows, index.stamps, index.cameras, keypoints,
                                            options, valid=index.complete)
        except LabelResolutionError as error:
            raise LabelError(f'{error}{resize_hint(index.bag, args.label_scale)}') from None
        if not len(labels):
            raise LabelError(f'{args.path}: no label left to write ({report.summary()}'
                             f'{"; " + result.note if result.note else ""}); nothing written '
                             f'to {args.out}')
        count = write_labels(args.out, labels)
    except (LabelError, RecordingError, SkeletonError, ValueError,
            OSError) as error:
        print(f'monet labels import: {error}', file=sys.stderr)
        return 2
    missing = (f'{result.missing} point{"" if result.missing == 1 else "s"} without a '
               'position in the source (NaN / inf, not detected or not placed) left out'
               if result.missing else '')
    extra = ''.join(f'; {note}' for note in (result.note, missing, scaled) if note)
    print(f'monet labels import: {count} labels at {len(labels)} instants x '
          f'{len(labels.cameras)} cameras -> {args.out} ({report.summary()}{extra})')
    return 0
