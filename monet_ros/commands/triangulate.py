"""`monet triangulate`: 3D keypoints from another tool's 2D detections and a calibration.

    monet triangulate POINTS2D... --rig CAL [--rig-units m|cm|mm] --out OUT
        [--format auto|dlc|sleap|anipose|openpose|frames] [--pose-model BODY_25B]
        [--filter none|kalman|optim] [--fps F]
        [--skeleton human14]
        [--camera-map SRC=DST] [--threshold-px 15] [--confidence-threshold 0.1]
        [--min-views 2] [--method exclusion|ransac] [--export csv,trc,nwb,npz]
        [--subjects N [--association-px 15] [--gate-mm 400] [--max-speed-m-s 2]
         [--max-missed-s 0.5] [--min-keypoints 3] [--body-noise-mm 50]
         [--body-acceleration-m-s2 5] [--track-measurement-noise-mm 15]
         [--track-acceleration-m-s2 20]]

POINTS2D: what `monet labels import` reads (DeepLabCut / Lightning Pose prediction CSV or
H5 per camera, SLEAP analysis H5 per camera, an anipose pose-2d folder, OpenPose /
Pose2Sim JSON folders: monet_ros.labels_import.openpose) or a frame-indexed
table frame,camera,keypoint,u,v[,score] (monet_ros.labels_import.points2d); the score /
likelihood is the detection confidence. Triangulation is the fusion's (fusion.fuse_points:
views below --confidence-threshold, NaN and missing views left out, confidence-weighted
robust DLT with worst-view exclusion or RANSAC, cheirality-checked), batched over all
frames at once. Writes into OUT (atomically) the files of `monet process`:
keypoints3d.csv (anipose's layout), keypoints3d.trc, keypoints.nwb (monet_ros.io.
export_results), and with --filter the filtered points (monet_ros.temporal). The 3D
points are in the rig's length unit (--rig-units, the file's, or the rule of
monet_ros.geometry.units), stated in every output. The rows are
the source's frames from the first to the last one seen, numbered as the source numbers
them: CSV fnum = source frame (anipose's meaning), TRC Frame# = frame + 1, TRC Time and
NWB timestamps = frame / --fps (a table that starts at frame 10 starts at 10 / fps s).

--subjects N: several subjects (monet_ros.subjects). The tables hold per-camera instances:
SLEAP tracks, DeepLabCut individuals, the points table's `subject` column (a label within
one camera and frame only, never taken to mean the same subject elsewhere). Each frame's
instances are associated across cameras by epipolar geometry and triangulated
(subjects.association), then given identities over time (subjects.tracking); at most N
subjects per frame are kept (those seen by the most cameras; the others are counted).
keypoints3d.csv gains a `subject` column (one row per frame and subject), TRC is one file
per subject (keypoints3d_subject<id>.trc), NWB one 3D series per subject. --filter
kalman|optim filters each identity on its own (subjects.offline.smooth_subjects: over the
frames from its first to its last, with its own 2D detections); the files then hold the
filtered rows, with the subject column. Not with --export npz. The tracker's options are
every field of subjects.tracking.TrackerConfig (commands.common.tracker_options: defaults
and help from the config, as the fusion node's parameters), only with --subjects.
"""
from pathlib import Path
import sys

import numpy as np

HELP = '3D keypoints from 2D detections of other tools (DeepLabCut, SLEAP, anipose, CSV)'


def add_arguments(parser):
    from monet_ros.commands.common import add_rig_units_argument, add_subject_tracking_arguments
    from monet_ros.commands.filter_options import add_filter_arguments
    from monet_ros.geometry.pose2sim import POSE_MODELS
    from monet_ros.labels_import.points2d import FORMATS
    parser.add_argument('points2d', nargs='+', help='2D tables: per-camera DeepLabCut / '
                        'SLEAP files, an anipose pose-2d folder, OpenPose / Pose2Sim JSON '
                        'folders (one per camera), or a frame,camera,keypoint,u,v[,score] CSV')
    parser.add_argument('--rig', required=True, help='calibration (rig YAML, Pose2Sim / '
                        'anipose TOML, ...)')
    add_rig_units_argument(parser)
    parser.add_argument('--out', required=True, help='output folder (new, or an empty folder)')
    parser.add_argument('--format', choices=FORMATS, default='auto',
                        help='2D table format (default: detected from the files)')
    parser.add_argument('--pose-model', choices=tuple(POSE_MODELS), default=None,
                        help="keypoint names of OpenPose JSON (default: the --skeleton's "
                        'names when it has as many, else the one model with that many)')
    parser.add_argument('--fps', type=float, default=None,
                        help='frame rate (Hz) of the 2D frames: their times (needed by '
                        '--filter; default 30 without a filter)')
    parser.add_argument('--skeleton', default=None, help='skeleton preset or YAML: output '
                        "keypoints and order, and the bones (optim's bone-length term, NWB)")
    parser.add_argument('--camera-map', action='append', default=[], metavar='SRC=DST',
                        help="rename the 2D tables' cameras to the rig's (repeatable)")
    parser.add_argument('--threshold-px', type=float, default=15.0,
                        help='inlier threshold (image pixels)')
    parser.add_argument('--confidence-threshold', type=float, default=0.1,
                        help='detection score below which a view is left out')
    parser.add_argument('--min-views', type=int, default=2, help='fewest inlier views')
    parser.add_argument('--method', choices=('exclusion', 'ransac'), default='exclusion')
    parser.add_argument('--export', default='csv,trc,nwb',
                        help='files written into OUT: any of csv, trc, nwb, npz')
    parser.add_argument('--trc-axes', choices=('xyz', 'yzx'), default='xyz',
                        help='TRC axes: world as is, or yzx = Y-up as Pose2Sim/OpenSim')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    add_filter_arguments(parser)
    parser.add_argument('--subjects', type=int, default=None, metavar='N',
                        help='several subjects: per-camera instances associated across '
                        'cameras and tracked over time; at most N per frame')
    add_subject_tracking_arguments(parser)


def triangulate_points(paths, rig, out, fmt='auto', fps=None, skeleton=None, camera_map=None,
                       fusion_config=None, filter_config=None, exports=('csv', 'trc', 'nwb'),
                       trc_axes='xyz', progress=False, rig_units=None, pose_model=None,
                       subjects=None, tracker_config=None, association_px=15.0):
    """Triangulate (and filter) 2D tables; write `out`. rig_units: the length unit of a rig
    file that states none (None: the rule of geometry.units); pose_model: keypoint names of
    OpenPose JSON (read_points2d). Returns a dict of figures:
    frames, cameras, keypoints, rows, counts (cells, missing, low_score, triangulated,
    per-joint not triangulated), exports {format: path}, filter (temporal.Smoothed or
    None), notes, units (the rig's length unit, that of arrays['X']).
    progress: optim's iterations as a tqdm bar. subjects: None (one subject) or N (several:
    the module docstring; tracker_config a subjects.TrackerConfig, association_px the
    association's threshold), the dict then has 'subjects' (SubjectRows, unfiltered) and
    filter (subjects.offline.SmoothedSubjects or None).
    Raises ValueError / LabelError / ConfigError / OSError naming the file or option."""
    from monet_ros.commands.common import atomic_output_dir, check_new_output
    from monet_ros.commands.filter_options import check_filter_units
    from monet_ros.config import ConfigError
    from monet_ros.fusion import FusionConfig, fuse_frames
    from monet_ros.geometry import load_rig
    from monet_ros.geometry.units import rig_units as units_of
    from monet_ros.io.export_results import write_results
    from monet_ros.labels_import.points2d import read_points2d
    from monet_ros.skeleton import load_skeleton
    from monet_ros.temporal import FilterConfig, smooth_points

    fusion_config = fusion_config or FusionConfig()
    filter_config = filter_config or FilterConfig()
    notes = []
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ConfigError('monet triangulate', 'fps', f'must be a finite number > 0 (frames/s), '
                          f'got {fps}')
    if fps is None:
        if filter_config.method != 'none':
            raise ConfigError('monet triangulate', 'fps', f'--filter {filter_config.method} '
                              'needs the frame rate of the 2D frames (--fps F, Hz)')
        fps = 30.0
        notes.append('--fps not given: times in the outputs assume 30 frames/s')
    check_new_output(out, 'monet triangulate')
    rig_cameras = load_rig(rig, units=rig_units)
    check_filter_units(filter_config, units_of(rig_cameras))     # before the work
    names = [c.name for c in rig_cameras]
    sk = load_skeleton(skeleton) if skeleton else None
    if subjects is not None:
        return _triangulate_subjects(paths, rig_cameras, names, out, fmt, fps, sk, camera_map,
                                     fusion_config, filter_config, exports, trc_axes,
                                     pose_model, subjects, tracker_config, association_px,
                                     notes, progress)
    pts = read_points2d(paths, names, fmt, keypoints=sk.keypoints if sk else None,
                        camera_map=camera_map, pose_model=pose_model)
    notes += pts.notes
    instances = {k.split('/', 1)[0] for k in pts.keypoints if '/' in k}
    if instances:        # several instances per camera (a subject column, tracks) need N
        raise ConfigError('monet triangulate', 'subjects', f'{", ".join(map(str, paths))} '
                          f'holds {len(instances)} instances per camera (a subject column, '
                          f'SLEAP tracks or DeepLabCut individuals: {sorted(instances)[0]!r}'
                          ', ...): give --subjects N (the most subjects in a frame)')
    used = [v for v in range(len(names)) if np.isfinite(pts.points[:, v]).any()]
    if len(used) < max(2, fusion_config.min_views):
        raise ValueError(f'{", ".join(map(str, paths))}: detections in '
                         f'{len(used)} camera(s) ({", ".join(names[v] for v in used)}); '
                         f'triangulation needs at least {max(2, fusion_config.min_views)}')
    unused = [n for v, n in enumerate(names) if v not in used]
    if unused:
        notes.append(f'rig cameras without 2D detections, left out: {", ".join(unused)}')
    cameras = [rig_cameras[v] for v in used]
    points, score = pts.points[:, used], pts.score[:, used]
    T, V, C = score.shape
    present = np.isfinite(points).all(-1)
    low = present & ~(np.nan_to_num(score, nan=-1.0) >= fusion_config.confidence_threshold)
    a = fuse_frames(points, score, cameras, fusion_config)
    # source time: frame / fps from the source's frame 0 (export_tables TIME_BASE)
    a['stamps'] = np.round(pts.frames * (1e9 / fps)).astype(np.int64)
    a['conf2d'] = score
    a['K_heat'] = np.broadcast_to(np.stack([c.K for c in cameras]), (T, V, 3, 3))
    missing_points = ~np.isfinite(a['X']).all(-1)
    smoothed = None
    if filter_config.method != 'none':
        edges = sk.bone_indices if sk else ()
        smoothed = smooth_points(a['X'], a['score'], points, score, cameras, a['stamps'],
                                 edges, filter_config, error=a['error'], progress=progress)
    with atomic_output_dir(out) as staging:
        staging.mkdir(parents=True, exist_ok=True)
        written = write_results(staging, exports, cameras, pts.keypoints, a,
                                edges=sk.bone_indices if sk else None, trc_axes=trc_axes,
                                smoothed=smoothed, fnum=pts.frames, origin_ns=0, rate_hz=fps)
    counts = dict(cells=T * V * C, missing=int((~present).sum()), low_score=int(low.sum()),
                  points=T * C, triangulated=int((~missing_points).sum()),
                  not_triangulated=dict(zip(pts.keypoints,
                                            missing_points.sum(axis=0).tolist())))
    return dict(frames=T, first_frame=int(pts.frames[0]), last_frame=int(pts.frames[-1]),
                fps=fps, cameras=[c.name for c in cameras],
                keypoints=pts.keypoints, rows=pts.rows, nan_rows=pts.nan_rows, fmt=pts.fmt,
                counts=counts, filter=smoothed, notes=notes, arrays=a,
                units=rig_cameras[0].units,
                exports={f: Path(out) / Path(p).relative_to(staging)
                         for f, p in written.items()})


def _triangulate_subjects(paths, rig_cameras, names, out, fmt, fps, sk, camera_map,
                          fusion_config, filter_config, exports, trc_axes, pose_model,
                          num_subjects, tracker_config, association_px, notes,
                          progress=False):
    """triangulate_points with --subjects (the module docstring)."""
    from monet_ros.commands.common import ASSOCIATION_OPTIONS, atomic_output_dir, options_named
    from monet_ros.config import ConfigError
    from monet_ros.io.export_results import write_subject_results
    from monet_ros.labels import LabelError
    from monet_ros.labels_import.points2d import read_points2d
    from monet_ros.subjects import AssociationConfig
    from monet_ros.subjects.offline import (
        instance_arrays,
        smooth_subjects,
        split_instances,
        track_subjects,
    )

    if not num_subjects >= 1:
        raise ConfigError('monet triangulate', 'subjects', f'must be >= 1, got {num_subjects}')
    if 'npz' in exports:
        raise ConfigError('monet triangulate', 'export', 'npz is not written with '
                          '--subjects; use csv, trc, nwb')
    with options_named(AssociationConfig, ASSOCIATION_OPTIONS):     # as typed, not the field
        association = AssociationConfig(
            threshold_px=association_px, confidence_threshold=fusion_config.confidence_threshold,
            min_views=max(2, fusion_config.min_views), triangulation_px=fusion_config.threshold_px,
            method=fusion_config.method)
    pts = read_points2d(paths, names, fmt, camera_map=camera_map, pose_model=pose_model)
    notes += pts.notes
    try:
        instances, keypoints, index = split_instances(pts.keypoints,
                                                      sk.keypoints if sk else None)
    except ValueError as error:
        raise LabelError(f'{", ".join(map(str, paths))}: {error}') from None
    used = [v for v in range(len(names)) if np.isfinite(pts.points[:, v]).any()]
    if len(used) < 2:
        raise ValueError(f'{", ".join(map(str, paths))}: detections in {len(used)} '
                         'camera(s); triangulation needs at least 2')
    unused = [n for v, n in enumerate(names) if v not in used]
    if unused:
        notes.append(f'rig cameras without 2D detections, left out: {", ".join(unused)}')
    cameras = [rig_cameras[v] for v in used]
    points, score = instance_arrays(pts.points[:, used], pts.score[:, used], index)
    present = np.isfinite(points).all(-1)
    low = present & ~(np.nan_to_num(score, nan=-1.0) >= fusion_config.confidence_threshold)
    stamps = np.round(pts.frames * (1e9 / fps)).astype(np.int64)
    rows = track_subjects(points, score, cameras, stamps, num_subjects, association,
                          tracker_config)
    smoothed = None
    if filter_config.method != 'none':      # one filter per identity
        smoothed = smooth_subjects(rows, stamps, cameras, sk.bone_indices if sk else (),
                                   filter_config, progress=progress)
    with atomic_output_dir(out) as staging:
        staging.mkdir(parents=True, exist_ok=True)
        written = write_subject_results(staging, exports, cameras, keypoints, rows, stamps,
                                        pts.frames, edges=sk.bone_indices if sk else None,
                                        trc_axes=trc_axes, origin_ns=0, rate_hz=fps,
                                        smoothed=smoothed)
    return dict(frames=len(stamps), first_frame=int(pts.frames[0]),
                last_frame=int(pts.frames[-1]), fps=fps, cameras=[c.name for c in cameras],
                keypoints=keypoints, instance_names=instances, rows=pts.rows,
                nan_rows=pts.nan_rows, fmt=pts.fmt, subjects=rows, notes=notes,
                low_score=int(low.sum()),
                filter=smoothed,
                units=rig_cameras[0].units,
                exports={f: Path(out) / Path(p).relative_to(staging)
                         for f, p in written.items()})


def _rows_text(fig):
    """'8359 rows of the frames format' (the format's name is not an adjective of rows:
    'frames rows' read as a typo)."""
    return f'{fig["rows"]} rows of the {fig["fmt"]} format'


def _print_subjects(fig, name, args):
    s = fig['subjects']
    T = fig['frames']
    print(f'{name}: {T} frames (from frame {fig["first_frame"]}) x {len(fig["cameras"])} '
          f'cameras ({", ".join(fig["cameras"])}) x {len(fig["keypoints"])} keypoints, '
          f'{len(fig["instance_names"])} instance slots per camera from {_rows_text(fig)}; '
          f'3D in {fig["units"]}, the rig\'s unit')
    print(f'{name}: subjects: {s.identities_text()}; association + tracking '
          f'{1e3 * s.seconds / max(T, 1):.2f} ms/frame')
    print(f'{name}: skipped: {s.unmatched} of {s.instances} instances matched in no other '
          f'camera, {s.extra} subjects beyond --subjects, {s.untracked} untracked (too '
          'few keypoints for a track, or taken by no identity while N were alive)')
    print(f'{name}: skipped 2D: {fig["nan_rows"]} rows NaN (no detection), '
          f'{fig["low_score"]} below --confidence-threshold {args.confidence_threshold}')
    print(f'{name}: {s.untriangulated_text(fig["keypoints"])}')
    if fig.get('filter') is not None:
        print(f'{name}: {fig["filter"].summary()}')
        for ident, smoothed in fig['filter'].per_subject.items():
            for note in smoothed.notes:
                print(f'{name}: filter: subject {ident}: {note}')


def run(args):
    from monet_ros.commands.filter_options import filter_config_from_args
    from monet_ros.fusion import FusionConfig
    from monet_ros.io.export_results import parse_formats
    from monet_ros.labels import parse_name_map

    fusion = FusionConfig(threshold_px=args.threshold_px,
                          confidence_threshold=args.confidence_threshold,
                          min_views=args.min_views, method=args.method)
    filt = filter_config_from_args(args, args.confidence_threshold, args.threshold_px)
    exports = parse_formats(args.export)
    tracker = None
    from monet_ros.commands.common import check_subject_only_options, tracker_config_from_args
    check_subject_only_options(args, args.subjects is not None, 'monet triangulate')
    if args.subjects is not None:
        tracker = tracker_config_from_args(args)
    fig = triangulate_points(args.points2d, args.rig, args.out, fmt=args.format, fps=args.fps,
                             skeleton=args.skeleton,
                             camera_map=dict(parse_name_map(args.camera_map)),
                             fusion_config=fusion, filter_config=filt, exports=exports,
                             trc_axes=args.trc_axes, progress=not args.quiet,
                             rig_units=args.rig_units, pose_model=args.pose_model,
                             subjects=args.subjects, association_px=args.association_px,
                             tracker_config=tracker)
    name = 'monet triangulate'
    if args.subjects is not None:
        _print_subjects(fig, name, args)
        for note in fig['notes']:
            print(f'{name}: note: {note}', file=sys.stderr)
        for fmt, path in fig['exports'].items():
            print(f'{name}: wrote {fmt}: {path}')
        return 0
    n = fig['counts']
    print(f'{name}: {fig["frames"]} frames (from frame {fig["first_frame"]}) x '
          f'{len(fig["cameras"])} cameras ({", ".join(fig["cameras"])}) x '
          f'{len(fig["keypoints"])} keypoints from {_rows_text(fig)}; '
          f'{n["triangulated"]} of {n["points"]} points triangulated (3D in '
          f'{fig["units"]}, the rig\'s unit)')
    print(f'{name}: source frames {fig["first_frame"]}..{fig["last_frame"]} kept in the '
          f'exports: keypoints3d.csv fnum = frame, TRC Frame# = frame + 1, TRC Time and NWB '
          f'timestamps = frame / {fig["fps"]:g} s')
    nan = f'; {fig["nan_rows"]} rows NaN in the input' if fig['nan_rows'] else ''
    print(f'{name}: skipped views: {n["missing"]} of {n["cells"]} missing (no detection'
          f'{nan}), '
          f'{n["low_score"]} below --confidence-threshold {args.confidence_threshold}')
    lost = ', '.join(f'{k} {v}' for k, v in n['not_triangulated'].items() if v)
    print(f'{name}: frames not triangulated per keypoint (fewer than {args.min_views} '
          f'consistent views): {lost or "none"}')
    for note in fig['notes']:
        print(f'{name}: note: {note}', file=sys.stderr)
    if fig['filter'] is not None:
        print(f'{name}: {fig["filter"].summary()}')
        for note in fig['filter'].notes:
            print(f'{name}: filter: {note}')
    for fmt, path in fig['exports'].items():
        print(f'{name}: wrote {fmt}: {path}')
    return 0
