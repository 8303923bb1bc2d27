"""`monet process --subjects N` (N >= 2): several subjects through the detector.

Each frame goes through monet_ros.subjects.detection.SubjectsStep (its module docstring
states the algorithm: per-subject crops from the tracks' predictions, full-frame top-k
candidates associated across views to find subjects, subjects.association across views,
subjects.tracking over time). The outputs are those of `monet triangulate --subjects N`
(io.export_results.write_subject_results): keypoints3d.csv with a `subject` column, one
TRC per subject (keypoints3d_subject<id>.trc), NWB with one 3D series per subject; the
MCAP holds /monet/keypoints3d as the live fusion publishes it with several subjects
(PointCloud2, metres, one cloud per frame, one point per keypoint and tracked subject, the
`subject` field its identity). Views are decoded in full (no reduced JPEG decode).
--filter kalman|optim filters each identity on its own (subjects.offline.smooth_subjects,
the one implementation `monet triangulate --subjects` uses: over the frames from the
identity's first to its last, with the 2D detections of its own crops): the exports hold
the filtered rows (subject column as without it) and the MCAP adds
/monet/keypoints3d_filtered beside /monet/keypoints3d, one cloud per frame with the
`subject` field. Not with --no-track, --heatmaps or --export npz (ConfigError).
"""
import sys
import time

import numpy as np

from monet_ros.config import ConfigError


def check_subject_options(config, subjects, exports):
    """ConfigError (naming the option) for an option `monet process --subjects N` (N >= 2)
    does not take."""
    where = 'monet process'
    if not config.track:
        raise ConfigError(where, 'subjects', '--no-track: several subjects are found by '
                          'their tracks (leave --no-track out)')
    if config.heatmaps:
        raise ConfigError(where, 'heatmaps', '--heatmaps is not written with --subjects')
    if 'npz' in exports:
        raise ConfigError(where, 'export', 'npz is not written with --subjects; use csv, '
                          'trc, nwb')


def process_subjects(reader, topics, cameras, detector, units, frame_id, staging, config,
                     subjects, association, tracker, exports, edges, trc_axes, progress,
                     figures, filter_config=None):
    """The frame loop of process.process_recording for several subjects: writes the MCAP
    (inside `staging`, already an open rosbag2 folder's staging path) and the exports.
    subjects: SubjectsConfig; association: AssociationConfig; tracker: TrackerConfig.
    Fills `figures` (process_recording's dict) and adds figures['subjects']: the
    subjects.offline.SubjectRows, figures['subject_keypoints'] its C keypoint names,
    figures['subject_stamps'] (F,) ns the stamps of its rows' frame indices,
    figures['subject_cameras'] the names of its V cameras (points2d's order),
    figures['subject_counts']: per-frame counts (frames
    with k subjects, discoveries, crops, duplicates, instances, unmatched, and discovery's
    3D points: found, explained by a track, loose), and figures['filter']: the
    subjects.offline.SmoothedSubjects of filter_config (a temporal.FilterConfig, method
    kalman or optim; None or 'none': no filter, figures['filter'] None) with
    figures['filter_stamps'] (F,) ns, the stamps of its rows' frame indices."""
    from collections import Counter

    from tqdm import tqdm

    from monet_ros.commands.filter_options import write_filtered_subjects
    from monet_ros.commands.views import read_frame_views
    from monet_ros.io import BagWriter, iter_multiview_frames
    from monet_ros.io.export_results import write_subject_results
    from monet_ros.io.export_tables import frame_numbers
    from monet_ros.subjects.detection import SubjectsStep, subject_keypoints
    from monet_ros.subjects.offline import RowCollector, smooth_subjects

    by_name = {cam.name: cam for cam in cameras}
    step = SubjectsStep(detector, units, subjects, association, tracker)
    rows = RowCollector(len(cameras))
    index = {cam.name: v for v, cam in enumerate(cameras)}
    stamps = []
    counts = dict(per_frame=Counter(), discoveries=0, discovered=0, crops=0, duplicates=0,
                  instances=0, unmatched=0, extra=0, points=0, explained=0, loose=0, repeated=0,
                  shared=0, detached=0, weak=0, foreign=0, settled=0)
    with BagWriter(staging) as writer:
        frames = iter_multiview_frames(reader, topics, slop_ns=int(config.slop_ms * 1e6),
                                       decode=False)
        for frame in tqdm(frames, desc='monet process', unit='frame', disable=not progress,
                          file=sys.stderr):
            present, views = read_frame_views(frame, topics, by_name, reader, False, figures)
            images = [view[0] for view in views]        # (array, layout): read_view's view
            layouts = [view[1] for view in views]
            figures['missing_views'] += len(topics) - len(present)
            if len(present) < config.min_views:
                continue
            r = step.step(images, present, frame.stamp_ns, layouts)
            a = r.association
            rows.add(len(stamps), a, r.ids, r.keep, [index[cam.name] for cam in present])
            stamps.append(frame.stamp_ns)
            counts['per_frame'][int((r.ids >= 0).sum())] += 1
            counts['discoveries'] += r.discovered >= 0
            counts['discovered'] += max(r.discovered, 0)
            for key in ('crops', 'duplicates', 'extra', 'points', 'explained', 'loose', 'repeated',
                        'shared', 'detached', 'weak', 'foreign', 'settled'):
                counts[key] += getattr(r, key)
            counts['instances'] += a.instances
            counts['unmatched'] += a.unmatched
            # the live fusion's message (subjects >= 2): one cloud per frame, one point per
            # keypoint and tracked subject, the subject field its identity
            ids, X, score, error, ncams = subject_keypoints(r)
            C = X.shape[1]
            writer.write_keypoints3d('/monet/keypoints3d', frame.stamp_ns, frame_id,
                                     X.reshape(-1, 3), score.reshape(-1), error.reshape(-1),
                                     ncams.reshape(-1), units=units,
                                     keypoint=np.tile(np.arange(C), len(ids)),
                                     subject=np.repeat(ids, C))
            figures['frames'] += 1
            figures['views'] += len(present)
        result = rows.result(step.tracker, instances=counts['instances'],
                             unmatched=counts['unmatched'], extra=counts['extra'],
                             seconds=time.perf_counter() - figures['start'])
        stamps = np.array(stamps, np.int64)
        smoothed = None
        if filter_config is not None and filter_config.method != 'none' and len(stamps):
            smoothed = smooth_subjects(result, stamps, cameras, edges if edges is not None
                                       else (), filter_config, progress=progress)
            write_filtered_subjects(writer, frame_id, smoothed, stamps, units)
            figures['filter_stamps'] = stamps     # (F,) ns: the frames of smoothed.rows.frame
    figures['seconds'] = time.perf_counter() - figures['start']
    figures['filter'] = smoothed
    triangulated = np.isfinite(result.X).all(-1)
    error = result.error[triangulated & np.isfinite(result.error)]
    figures['mean_error'] = float(error.mean()) if error.size else float('nan')
    figures['mean_views'] = (float(result.ncams[triangulated].mean()) if triangulated.any()
                             else float('nan'))
    written = {}
    if len(stamps):
        written = write_subject_results(staging, exports, cameras, detector.keypoints,
                                        result, stamps, frame_numbers(stamps), edges=edges,
                                        trc_axes=trc_axes, smoothed=smoothed)
    figures['subjects'] = result
    figures['subject_keypoints'] = list(detector.keypoints)
    figures['subject_stamps'] = stamps
    figures['subject_cameras'] = [cam.name for cam in cameras]
    figures['subject_counts'] = counts
    return written


def subject_lines(figures, out):
    """The summary lines of `monet process --subjects N` (process.recording_lines: without
    the 'monet process: ' prefix)."""
    s, n = figures['subjects'], figures['subject_counts']
    per_frame = ', '.join(f'{k}: {v}' for k, v in sorted(n['per_frame'].items()))
    return [
        f'{figures["frames"]} frames ({figures["views"]} views, {figures["missing_views"]} '
        f'missing) in {figures["seconds"]:.1f} s -> {out} (3D in {figures["units"]}, the '
        "rig's unit)",
        f'subjects: {s.identities_text()}; frames by subjects tracked: {per_frame or "none"}',
        s.untriangulated_text(figures['subject_keypoints']),
        f'detection: {n["crops"]} subject crops, {n["discoveries"]} full-frame discovery runs '
        f'finding {n["discovered"]} subjects from {n["points"]} 3D keypoint candidates '
        f'({n["explained"]} near a live track, {n["loose"]} in no subject: too few keypoints '
        f'or beyond --subjects, {n["repeated"]} in a second group of a subject found in the '
        'same frame)',
        f'skipped: {s.unmatched} of {s.instances} crop instances matched in no other camera, '
        f'{n["duplicates"]} duplicate subjects (one body from two crops), {n["weak"]} weak '
        f'subjects (median joint score below --min-score), {n["foreign"]} joint detections '
        "left out of a subject's triangulation as another subject's crop's (--foreign-views), "
        f'{n["shared"]} joints decoded by two subjects (kept by one), {n["detached"]} joints '
        f'not linked within --link-mm to the body of their subject, {n["settled"]} joints of '
        f'a settling track solved again by consistency (--settle-frames), {s.extra} subjects '
        f'beyond --subjects, {s.untracked} untracked (too few keypoints for a track, or taken '
        'by no identity while N were alive)']
