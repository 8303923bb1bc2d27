"""`monet process`: the detector + fusion core over a recording, offline and as fast as
possible, writing /monet/keypoints3d (and optionally the heatmaps) to a rosbag2 MCAP.

    monet process REC... --model CKPT --out OUT [--jobs N] [--rig RIG] [--rig-units m|cm|mm]
        [--heatmaps] [--threads N] [--export csv,trc,nwb,npz] [--trc-axes xyz|yzx]
        [--filter none|kalman|optim]
        [--subjects N [--candidates 3] [--link-mm 600] [--crop-peaks 3] [--duplicate-mm 100]
         [--crop-missed 1] [--min-score 0.4] [--[no-]rival-peaks] [--[no-]foreign-views]
         [--settle-frames 3] [--settle-ratio 5] [--settle-px 5] [--association-px 15]
         [--gate-mm 400] [--max-speed-m-s 2] [--max-missed-s 0.5] [--min-keypoints 3]
         [--body-noise-mm 50] [--body-acceleration-m-s2 5]
         [--track-measurement-noise-mm 15] [--track-acceleration-m-s2 20]]

Beside the MCAP (inside OUT) it writes the per-frame results for analysis tools
(monet_ros.io.export_results): keypoints3d.csv (anipose's 3D CSV layout),
keypoints3d.trc (OpenSim / Pose2Sim), keypoints.nwb (NWB + ndx-pose, 3D and the 2D
detections per camera) and detections2d.npz (2D detections + crop cameras). 3D is in the
rig's length unit (--rig-units, the file's, else the rule of monet_ros.geometry.units; a
recording's /tf_static rig: m), stated in every file; the MCAP's messages are ROS messages,
in metres (REP 103) whatever the rig's unit.

--filter kalman|optim smooths the 3D over the whole recording (monet_ros.temporal): the
analysis files then hold the filtered points and the MCAP also /monet/keypoints3d_filtered
(/monet/keypoints3d stays the frame-by-frame result).

--subjects N (N >= 2): several subjects (commands/process_subjects.py; the algorithm in
monet_ros.subjects.detection): per-subject crops from each track's prediction, full-frame
top-k candidates to find subjects, identities over time; the outputs of `monet
triangulate --subjects N` (keypoints3d.csv with a `subject` column, one TRC and one NWB
series per subject). --subjects 1 (the default) is the one-subject path below. The options
after --subjects N are the fields of subjects.detection.SubjectsConfig and subjects.tracking.
TrackerConfig (commands.common.add_subjects_detection_arguments: defaults and help from the
configs; the tracker's joint noise and acceleration take a track- prefix, the --filter's
have the plain names) and apply only with N >= 2.

The same functions as the live nodes: Detector.predict (one batched forward per instant),
crop_rule.TrackedCrops (the detector node's crop rule: around the previous instant's 3D
keypoints), fusion.fuse_heatmaps.
"""
from collections import Counter
from dataclasses import dataclass
import math
from pathlib import Path
import sys
import time

import numpy as np

from monet_ros.commands.views import crop_views, read_frame_views
from monet_ros.config import ConfigError, config_subset, setting
from monet_ros.fusion import PEAKS_PER_VIEW, FusionConfig

HELP = 'run detector + fusion over a recording offline, write keypoints3d to an MCAP'


def add_arguments(parser):
    from monet_ros.commands.common import add_precision_options, add_rig_units_argument
    parser.add_argument('bag', nargs='+', help='recording(s): rosbag2 folder, .mcap or `monet '
                        'synth` folder (with several, --out is their parent: OUT/<recording '
                        'name>/ each)')
    parser.add_argument('--jobs', type=int, default=1,
                        help='recordings processed at once, one worker process each (one GPU '
                        'per job when several; --threads default cores // jobs)')
    parser.add_argument('--model', required=True, help='detector checkpoint')
    parser.add_argument('--out', required=True, help='output rosbag2 folder (must not exist; '
                        'written atomically: a failed run leaves nothing behind)')
    parser.add_argument('--rig', help="rig file (default: the recording's camera_info + "
                        '/tf_static)')
    add_rig_units_argument(parser)
    parser.add_argument('--cameras', nargs='+', help='cameras to use (default: all)')
    parser.add_argument('--camera-map', action='append', default=[], metavar='SRC=DST',
                        help="rename --rig cameras to the recording's (e.g. cam_01=cam01)")
    parser.add_argument('--skeleton', default=None,
                        help='skeleton preset or YAML; checked against the model keypoints')
    parser.add_argument('--slop-ms', type=float, default=0.0,
                        help='stamp tolerance between cameras (0 = exact)')
    parser.add_argument('--threshold-px', type=float, default=15.0,
                        help='fusion inlier threshold (image pixels)')
    parser.add_argument('--confidence-threshold', type=float, default=0.1,
                        help='heatmap peak value below which a view is ignored')
    parser.add_argument('--min-views', type=int, default=2, help='fewest inlier views')
    parser.add_argument('--method', choices=('exclusion', 'ransac'), default='exclusion')
    parser.add_argument('--peaks-per-view', type=int, default=PEAKS_PER_VIEW,
                        help='heatmap local maxima per view and keypoint tried where a view '
                        'disagrees (1 = the highest peak only)')
    parser.add_argument('--no-track', action='store_true',
                        help='full-frame crops instead of following the subject')
    parser.add_argument('--heatmaps', action='store_true',
                        help='also write /monet/<cam>/heatmaps')
    parser.add_argument('--device', default=None, help='torch device (default: auto)')
    parser.add_argument('--threads', type=int, default=0,
                        help='CPU threads of the network (0 = the backend default) and of '
                        'decoding and cropping the views (0 = the cores the process may use)')
    add_precision_options(parser, 'the recording processed')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    parser.add_argument('--export', default=None,
                        help='analysis files written into OUT: any of csv (anipose), trc, '
                        'nwb (ndx-pose), npz (2D detections + crop cameras); "none" for none '
                        '(default csv,trc,nwb,npz; with --subjects N >= 2 csv,trc,nwb)')
    parser.add_argument('--trc-axes', choices=('xyz', 'yzx'), default='xyz',
                        help='TRC axes: world as is, or yzx = Y-up as Pose2Sim/OpenSim')
    from monet_ros.commands.filter_options import add_filter_arguments
    add_filter_arguments(parser)
    from monet_ros.commands.common import add_subjects_detection_arguments
    add_subjects_detection_arguments(parser)


@dataclass(frozen=True)
class ProcessConfig(FusionConfig):
    """Settings of `monet process` (validated on construction; errors name the option)."""
    slop_ms: float = setting(0.0, 'stamp tolerance between cameras (0 = exact)', minimum=0.0,
                             maximum=10_000.0)
    track: bool = setting(True, "crop around the previous instant's 3D keypoints")
    heatmaps: bool = setting(False, 'also write /monet/<cam>/heatmaps')


class RunningMean:
    """Count and mean of the finite values added (bounded state for any run length)."""

    def __init__(self):
        self.count, self.total = 0, 0.0

    def add(self, value):
        if math.isfinite(value):
            self.count += 1
            self.total += value

    @property
    def mean(self):
        return self.total / self.count if self.count else float('nan')


def process_recording(bag, model, out, rig=None, cameras=(), config=None, device=None,
                      skeleton=None, progress=True, backend='auto', threads=0, exports=(),
                      trc_axes='xyz', camera_map=(), precision='auto', filter_config=None,
                      rig_units=None, reduced_decode=True, calibration=None, subjects=None,
                      association=None, tracker=None, log=None):
    """Detect + fuse every instant of `bag`; write `out` (a rosbag2 folder, written
    atomically). config: ProcessConfig. Returns a dict of figures: frames, views,
    missing_views, skipped_views (Counter camera -> views skipped), skip_reasons (camera ->
    first reason), seconds, mean_error, mean_views, report (the reader's ReadReport).
    backend: 'auto' (the command's default: models.detector.resolve_inference), 'torch' or
    'onnxruntime'; threads: CPU threads (0 = the library's default);
    precision: 'auto' (the command's default: models.detector.resolve_precision),
    'float32', 'bfloat16' or 'int8' (backend onnxruntime); `monet eval --reference`
    and `monet train --holdout-labelled` score models through this function, so as `monet
    process` runs them.
    exports: formats of monet_ros.io.export_results written inside `out` (figures['exports']:
    {format: path}; figures['summary']: per-joint dropout and inlier views).
    filter_config: a temporal.FilterConfig; with a method other than 'none' the exports
    hold the filtered points, figures['filter'] is the temporal.Smoothed and
    figures['filter_stamps'] (T,) ns the stamps of its rows.
    rig_units: the length unit of a rig file that states none (geometry.read_rig);
    figures['units'] is the rig's unit, that of the 3D outputs.
    reduced_decode: JPEG views are decoded at the crop's scale (io.jpeg_scale; False: full
    decodes, for comparison). calibration: precision int8's calibration data (a recording
    or a cached quant; None = `bag` itself), checked always but read only when the
    checkpoint has no cached quant of the run's crops: int8 calibrates on the crops the run makes
    (monet_ros.int8_calibration: tracked crops made by the float32 network with the
    tracked rule, or with config.track False full-frame crops; the quant's cache name says
    which, run_calibration). log: None, or a function given one-line notes (int8: what it
    calibrated on and which quant it wrote, or which cached quant it uses).
    subjects: a subjects.detection.SubjectsConfig; with subjects >= 2 several subjects
    (commands.process_subjects: figures then has 'subjects' (subjects.offline.SubjectRows)
    and 'subject_counts', and with a filter figures['filter'] is a subjects.offline.
    SmoothedSubjects (one filter per identity); association: subjects.AssociationConfig
    (None: from config's fusion settings), tracker: subjects.tracking.TrackerConfig).
    Raises ConfigError / ValueError / OSError naming the option, file or camera."""
    from tqdm import tqdm

    from monet_ros.commands.common import atomic_output_dir, check_new_output
    from monet_ros.commands.filter_options import check_filter_units
    from monet_ros.crop_rule import TrackedCrops
    from monet_ros.fusion import fuse_heatmaps
    from monet_ros.geometry.units import rig_units as units_of
    from monet_ros.io import BagWriter, iter_multiview_frames, open_bag
    from monet_ros.io.export_results import ResultsCollector
    from monet_ros.io.multiview import image_topics
    from monet_ros.models import Detector
    from monet_ros.rig_select import load_node_rig, select_cameras
    from monet_ros.skeleton import load_skeleton

    config = config or ProcessConfig()
    fusion_config = config_subset(config, FusionConfig)
    several = subjects is not None and subjects.subjects > 1
    if several:
        from monet_ros.commands.process_subjects import check_subject_options
        check_subject_options(config, subjects, exports)
    check_new_output(out, 'monet process')
    rig_cameras, frame_id = load_node_rig(rig or bag, rig_units)
    if rig is not None and Path(rig).is_file():    # a calibration file: fit it to the images
        from monet_ros.io.rig_fit import fit_rig_to_bag
        rig_cameras, _ = fit_rig_to_bag(rig_cameras, open_bag(bag), camera_map)
    cameras = select_cameras('monet process', rig_cameras, cameras or (), minimum=2)
    units = units_of(cameras)
    check_filter_units(filter_config, units)     # before the work
    if config.min_views > len(cameras):
        raise ConfigError('monet process', 'min_views', f'{config.min_views} > the '
                          f'{len(cameras)} cameras processed ({[c.name for c in cameras]})')
    int8_crops, calibration = run_calibration(config, calibration, bag, cameras, fusion_config,
                                              subjects, association, tracker)
    detector = Detector.from_checkpoint(model, device=device, backend=backend, threads=threads,
                                        precision=precision, calibration=calibration,
                                        int8_crops=int8_crops)
    if log is not None and detector.int8_note:
        log(detector.int8_note)
    edges = None
    if skeleton is not None:
        edges = load_skeleton(skeleton).bone_indices
        names = list(load_skeleton(skeleton).keypoints)
        if names != list(detector.keypoints):
            raise ConfigError('monet process', 'skeleton',
                              f'{skeleton} keypoints {names} differ from the keypoints of '
                              f'the model {model}: {list(detector.keypoints)}')
    reader = open_bag(bag)
    topics = image_topics(reader, cameras, bag)

    by_name = {cam.name: cam for cam in cameras}
    figures = dict(frames=0, views=0, missing_views=0, skipped_views=Counter(),
                   skip_reasons={}, seconds=0.0)
    if several:
        return _several(reader, topics, cameras, detector, units, frame_id, out, config,
                        subjects, association, tracker, exports, edges, trc_axes, progress,
                        figures, filter_config)
    errors, num_views = RunningMean(), RunningMean()
    collector = ResultsCollector(cameras, detector.keypoints)
    tracker = TrackedCrops(units=units)   # the detector node's defaults (track_* parameters)
    start = time.perf_counter()
    with atomic_output_dir(out) as staging, BagWriter(staging) as writer:
        frames = iter_multiview_frames(reader, topics, slop_ns=int(config.slop_ms * 1e6),
                                       decode=False)
        h_in, w_in = detector.input_size
        for frame in tqdm(frames, desc='monet process', unit='frame', disable=not progress,
                          file=sys.stderr):
            present, images = read_frame_views(frame, topics, by_name, reader,
                                               reduced_decode, figures)
            if len(present) < fusion_config.min_views:
                figures['missing_views'] += len(topics) - len(present)
                continue
            boxes = tracker.boxes(present, frame.stamp_ns if config.track else None)
            boxes = detector.boxes_for(present, boxes)
            # JPEG views decoded at the crop's scale (the detector node's rule): their
            # camera and box become the reduced image's; the heatmap cameras do not change
            # the views of an instant decoded (and cropped) in parallel, on `threads` threads
            # (0 = the usable cores: cores.view_threads)
            views = crop_views(images, present, boxes, (w_in, h_in), reader,
                               detector.view_threads)
            keep = [v is not None for v in views]
            present = [c for c, k in zip(present, keep) if k]
            views = [v for v in views if v is not None]
            figures['missing_views'] += len(topics) - len(present)
            if len(present) < fusion_config.min_views:
                continue
            heat, heat_cameras = detector.predict(
                [v[0] for v in views], [v[2] for v in views], np.array([v[3] for v in views]),
                keep_aspect=False, encodings=[v[1] for v in views])
            result = fuse_heatmaps(heat, np.stack([c.K for c in heat_cameras]), present,
                                   fusion_config)
            writer.write_keypoints3d('/monet/keypoints3d', frame.stamp_ns, frame_id,
                                     result.X, result.confidence, result.reprojection_error,
                                     result.num_views, units=units)
            if config.heatmaps:
                for cam, hm in zip(present, heat):
                    writer.write_heatmaps(f'/monet/{cam.name}/heatmaps', frame.stamp_ns, hm,
                                          cam.name)
            collector.add(frame.stamp_ns, present, result, heat_cameras)
            finite = np.isfinite(result.X).all(axis=1)
            if config.track:
                tracker.update(result.X, frame.stamp_ns)
            figures['frames'] += 1
            figures['views'] += len(present)
            errors.add(float(np.nanmean(result.reprojection_error)) if finite.any()
                       else float('nan'))
            num_views.add(float(result.num_views.mean()))
        smoothed = None
        if filter_config is not None and filter_config.method != 'none' and figures['frames']:
            from monet_ros.commands.filter_options import write_filtered
            from monet_ros.temporal import smooth_points
            a = collector.arrays()
            smoothed = smooth_points(a['X'], a['score'], a['points2d'], a['conf2d'], cameras,
                                     a['stamps'], edges or (), filter_config, error=a['error'],
                                     progress=progress)
            write_filtered(writer, frame_id, smoothed, a['stamps'], units)
            figures['filter_stamps'] = a['stamps']      # (T,) ns: the rows of smoothed
        figures['filter'] = smoothed
        written = collector.write(staging, exports, edges=edges, trc_axes=trc_axes,
                                  smoothed=smoothed)
    figures['exports'] = {fmt: Path(out) / Path(path).relative_to(staging)
                          for fmt, path in written.items()}
    figures['summary'] = collector.summary()
    figures['units'] = cameras[0].units
    figures['seconds'] = time.perf_counter() - start
    figures['mean_error'], figures['mean_views'] = errors.mean, num_views.mean
    figures['report'] = reader.report
    return figures


def subject_association(config):
    """The subjects.AssociationConfig of a --subjects run without association options: the
    ProcessConfig's confidence threshold, min_views, threshold_px (the triangulation's
    inlier error) and method."""
    from monet_ros.subjects import AssociationConfig

    return AssociationConfig(confidence_threshold=config.confidence_threshold,
                             min_views=config.min_views, triangulation_px=config.threshold_px,
                             method=config.method)


def run_calibration(config, calibration, bag, cameras=None, fusion=None, subjects=None,
                    association=None, tracker=None):
    """(int8 crops key, calibration) of a `monet process` run (int8_calibration.
    int8_calibration): tracked crops (the tracked rule's defaults, as the run's
    TrackedCrops) unless config.track is False (--no-track: full-frame crops); with
    `subjects` (a SubjectsConfig, --subjects N >= 2) the crops of a several-subject run
    (int8_calibration.subject_crops: subject crops and discovery maps, with the run's
    association (None: from config, as the run's) and tracker configs). calibration None
    = `bag`, whose crops are then made with the run's `cameras` (another recording: its
    own rig), with the run's stamp tolerance and fusion settings."""
    from monet_ros.int8_calibration import int8_calibration

    several = subjects is not None and subjects.subjects > 1
    if several and association is None:
        association = subject_association(config)
    return int8_calibration(bag if calibration is None else calibration, config.track,
                            cameras=cameras if calibration is None else None,
                            slop_ns=int(config.slop_ms * 1e6),
                            fusion=fusion or config_subset(config, FusionConfig),
                            subjects=subjects if several else None,
                            association=association, tracker=tracker)


def _several(reader, topics, cameras, detector, units, frame_id, out, config, subjects,
             association, tracker, exports, edges, trc_axes, progress, figures,
             filter_config=None):
    """process_recording with --subjects N >= 2 (commands.process_subjects)."""
    from monet_ros.commands.common import atomic_output_dir
    from monet_ros.commands.process_subjects import process_subjects

    if association is None:
        association = subject_association(config)
    figures['start'] = time.perf_counter()
    with atomic_output_dir(out) as staging:
        written = process_subjects(reader, topics, cameras, detector, units, frame_id,
                                   staging, config, subjects, association, tracker, exports,
                                   edges, trc_axes, progress, figures, filter_config)
    figures['exports'] = {fmt: Path(out) / Path(path).relative_to(staging)
                          for fmt, path in written.items()}
    figures['units'] = cameras[0].units
    figures['report'] = reader.report
    return figures


def subject_configs(args, subjects=None, config=None):
    """(SubjectsConfig, AssociationConfig, TrackerConfig) of the --subjects options
    (commands.common.add_subject_settings_arguments; ValueError naming the option:
    commands.common.config_from_options). subjects: N (default args.subjects); config: the
    ProcessConfig whose confidence threshold, min_views, threshold_px and method the
    association takes (subject_association's; default: those options of args, `monet
    process`'). Lengths are in mm whatever the rig's unit (the subjects step and the
    tracker convert them)."""
    from monet_ros.commands.common import (
        ASSOCIATION_OPTIONS,
        config_from_options,
        subjects_options,
        tracker_config_from_args,
    )
    from monet_ros.subjects import AssociationConfig
    from monet_ros.subjects.detection import SubjectsConfig

    if config is None:
        config = ProcessConfig(threshold_px=args.threshold_px,
                               confidence_threshold=args.confidence_threshold,
                               min_views=args.min_views, method=args.method)
    subjects = config_from_options(args, SubjectsConfig, subjects_options(),
                                   subjects=args.subjects if subjects is None else subjects)
    association = config_from_options(args, AssociationConfig, ASSOCIATION_OPTIONS,
                                      confidence_threshold=config.confidence_threshold,
                                      min_views=config.min_views,
                                      triangulation_px=config.threshold_px,
                                      method=config.method)
    return subjects, association, tracker_config_from_args(args)


def run(args):
    from monet_ros.commands.common import (
        check_subject_only_options,
        check_threads,
        print_precision,
    )
    from monet_ros.commands.filter_options import filter_config_from_args
    from monet_ros.io.export_results import parse_formats
    from monet_ros.labels import parse_name_map
    from monet_ros.models.device import check_device

    config = ProcessConfig(threshold_px=args.threshold_px,
                           confidence_threshold=args.confidence_threshold,
                           min_views=args.min_views, method=args.method,
                           slop_ms=args.slop_ms, track=not args.no_track,
                           heatmaps=args.heatmaps, peaks_per_view=args.peaks_per_view)
    filter_config = filter_config_from_args(args, args.confidence_threshold, args.threshold_px)
    device = check_device('monet process', args.device)
    check_threads('monet process', args.threads)
    print_precision('monet process', args.precision, args.backend, device, args.model,
                    calibration=args.calibration)

    def note(line):            # the notes of the run (int8's quant), as the other notes
        print(f'monet process: {line}', file=sys.stderr, flush=True)

    options = dict(model=args.model, rig=args.rig, cameras=args.cameras or (), config=config,
                   skeleton=args.skeleton, backend=args.backend,
                   exports=parse_formats(args.export if args.export is not None else
                                         'csv,trc,nwb' if args.subjects > 1 else
                                         'csv,trc,nwb,npz'), trc_axes=args.trc_axes,
                   camera_map=parse_name_map(args.camera_map), precision=args.precision,
                   filter_config=filter_config, rig_units=args.rig_units,
                   calibration=args.calibration)
    check_subject_only_options(args, args.subjects != 1, 'monet process')
    if args.subjects != 1:
        subjects, association, tracker = subject_configs(args, config=config)
        options.update(subjects=subjects, association=association, tracker=tracker)
    if len(args.bag) > 1 and args.precision == 'int8':   # quantised once, before the workers
        from monet_ros.models import Detector
        int8_crops, calibration = run_calibration(
            config, args.calibration, args.bag[0], subjects=options.get('subjects'),
            association=options.get('association'), tracker=options.get('tracker'))
        detector = Detector.from_checkpoint(args.model, device='cpu', backend=args.backend,
                                            precision='int8', calibration=calibration,
                                            int8_crops=int8_crops)
        note(detector.int8_note)
    if len(args.bag) > 1:         # several recordings: worker processes (process_many.py)
        from monet_ros.commands.process_many import run_many
        return run_many(args, options, process_recording, recording_lines)
    args.bag = args.bag[0]
    figures = process_recording(args.bag, out=args.out, device=device,
                                progress=not args.quiet, threads=args.threads, log=note,
                                **options)
    for line in recording_lines(figures, args.out):
        print(f'monet process: {line}')
    print_reading(figures, args.bag)
    return 0


def recording_lines(figures, out):
    """The summary of one recording's run (process_recording's figures, its results in
    `out`): stdout lines without the 'monet process: ' prefix, for one subject and for
    --subjects N (process_subjects.subject_lines): frames and errors, the subjects'
    counts, the filter's summary and notes, the files written. A run of one recording
    prints them as they are, a run of several each recording's after its name
    (process_many)."""
    lines = []
    if 'subjects' in figures:
        from monet_ros.commands.process_subjects import subject_lines
        lines += subject_lines(figures, out)
        if figures['filter'] is not None:
            lines.append(figures['filter'].summary())
            lines += [f'filter: subject {ident}: {note}'
                      for ident, smoothed in figures['filter'].per_subject.items()
                      for note in smoothed.notes]
        return lines + [f'wrote {fmt}: {path}' for fmt, path in figures['exports'].items()]
    fps = figures['frames'] / figures['seconds'] if figures['seconds'] else 0.0
    skipped = figures['skipped_views']
    views = figures['mean_views']
    lines.append(f'{figures["frames"]} frames ({figures["views"]} views, '
                 f'{figures["missing_views"]} missing'
                 f'{f", {sum(skipped.values())} of them skipped" if skipped else ""}) in '
                 f'{figures["seconds"]:.1f} s ({fps:.1f} frames/s); mean reprojection error '
                 f'{figures["mean_error"]:.2f} px; mean inlier views '
                 f'{0.0 if views != views else views:.2f} -> {out} (3D in '
                 f'{figures["units"]}, the rig\'s unit)')
    summary = figures['summary']
    if summary['frames']:
        dropout = ', '.join(f'{k} {100 * v:.0f}%' for k, v in summary['dropout'].items())
        views = ', '.join(f'{k} {v:.1f}' if v == v else f'{k} none (never triangulated)'
                          for k, v in summary['inlier_views'].items())
        lines += [f'per-joint dropout (not triangulated): {dropout}',
                  f'mean inlier views per joint: {views}',
                  'reprojection error measures agreement between the views used, not '
                  'accuracy: score accuracy with `monet eval --reference`']
    if figures['filter'] is not None:
        lines.append(figures['filter'].summary())
        lines += [f'filter: {note}' for note in figures['filter'].notes]
    return lines + [f'wrote {fmt}: {path}' for fmt, path in figures['exports'].items()]


def print_reading(figures, bag):
    """What reading the recording skipped (stderr): views per camera with their first
    reason, and the reader's report when it is not clean (a truncated file, records that
    do not decode); the same for one subject and for --subjects N."""
    skipped = figures['skipped_views']
    for name, count in sorted(skipped.items()):
        print(f'monet process: skipped {count} views of {name}: '
              f'{figures["skip_reasons"][name]}', file=sys.stderr)
    report = figures['report']
    if report is not None and not report.ok:
        print(f'monet process: reading {bag}: {report.summary()}', file=sys.stderr)
