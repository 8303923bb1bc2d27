"""Distillation rounds of `monet train --distill-rounds N` (issue 36 item 2).

After its steps the trainer's detector is the teacher: it runs over the training recording
exactly as `monet process --filter optim` runs a model (the detector node's tracked crops,
the fusion, the offline filter with bones, smoothness and robust reprojection); the filtered
3D is reprojected into every view as pseudo-labels (learning.distill.distilled_labels:
weighted and gated by the filter's reprojection error) and training goes on for
distill_round_steps more steps with their crops (L_D, the plan's 'D' part). Each round's
teacher checkpoint and `monet process` output stay in OUT/distill/ for inspection.

With labels of several subjects per instant the teacher runs with `--subjects S` (S: the
most subjects labelled at an instant) and each subject's crop rows get its own identity's
reprojected 3D (distill_round, learning.distill.match_identities). Its several-subject
settings are `monet train`'s options of the same names as `monet process --subjects`'
(--link-mm, --gate-mm, ...: commands.common.add_subject_settings_arguments, in mm whatever
the rig's unit; teacher_subject_configs).

The exact control of a distillation run is the same run at lambda_d 0: the same rounds,
teacher runs and crops, no L_D.
"""
import shutil
import sys

import numpy as np


def _say(line):
    print(f'monet train: {line}', file=sys.stderr, flush=True)


def teacher_process_config():
    """The commands.process.ProcessConfig of the teacher's `monet process` run: `monet
    process`' defaults."""
    from monet_ros.commands.process import ProcessConfig
    return ProcessConfig()


def teacher_subject_configs(args, subjects):
    """(SubjectsConfig, AssociationConfig, TrackerConfig) of the teacher's `monet process
    --subjects N` run from `monet train`'s teacher options (commands.common.
    add_subject_settings_arguments; process.subject_configs: the same validation, errors
    naming the option), N = `subjects`, the association on teacher_process_config()."""
    from monet_ros.commands.process import subject_configs
    return subject_configs(args, subjects, teacher_process_config())


def train_with_distillation(trainer, bag, rig=None, camera_map=(), rig_units=None,
                            skeleton=None, progress=True, say=_say, subjects=None,
                            association=None, tracker=None):
    """Train `trainer` to config.steps, then its config.distill_rounds rounds (resumes in
    the round trainer.distill_round where a resumed trainer stands). bag: the training
    recording (rosbag2 folder / .mcap) for the teacher's `monet process` run; rig,
    camera_map, rig_units, skeleton: as `monet process` takes them (skeleton: preset or
    YAML, for the filter's bone term); subjects, association, tracker: distill_round's.
    Returns the last Trainer.run summary with `distill`: a list of each round's figures
    (distill_round)."""
    c = trainer.config
    rounds = []
    while True:
        end = c.steps + trainer.distill_round * c.distill_round_steps
        summary = trainer.run(end, progress=progress)
        if trainer.distill_round >= c.distill_rounds:
            break
        try:
            rounds.append(distill_round(trainer, trainer.distill_round + 1, bag, rig=rig,
                                        camera_map=camera_map, rig_units=rig_units,
                                        skeleton=skeleton, progress=progress, say=say,
                                        subjects=subjects, association=association,
                                        tracker=tracker))
        except KeyboardInterrupt:
            _stopped_in_round(trainer)
            raise
    summary['distill'] = rounds
    return summary


def _stopped_in_round(trainer):
    """A stop signal during a round's teacher run: what was trained is written (the round is
    not done: --resume runs it again), as a stop between steps writes it (Trainer.run)."""
    from monet_ros.stop_signals import stop_signals_deferred

    if trainer.out_dir is None:
        return
    with stop_signals_deferred():             # a second signal: after the save
        path = trainer.save()
    print(f'stopped during distillation round {trainer.distill_round + 1} (its teacher run) '
          f'at step {trainer.step_count}: wrote {path} and '
          f'{trainer.out_dir / "trainer_state.pt"} (--resume runs the round again)',
          file=sys.stderr, flush=True)


def distill_round(trainer, index, bag, rig=None, camera_map=(), rig_units=None, skeleton=None,
                  progress=True, say=_say, subjects=None, association=None, tracker=None):
    """Round `index` (1-based): the teacher's checkpoint (OUT/distill/teacher_<index>.pt),
    its `monet process --filter optim` run over `bag` (OUT/distill/round_<index>/), the
    distilled pseudo-labels set on the trainer. Returns the round's figures (counts of
    learning.distill.Distilled, frames, seconds, median weight).

    Several subjects (labels with up to N > 1 subjects per instant; subjects: a
    subjects.detection.SubjectsConfig, default SubjectsConfig(subjects=N); association: a
    subjects.AssociationConfig, tracker: a subjects.tracking.TrackerConfig, default `monet
    process --subjects`' (teacher_subject_configs makes all three from `monet train`'s
    options); lengths in mm whatever the rig's unit): the teacher
    runs as `monet process --subjects N --filter optim` (one filter per identity), each of
    its identities is matched to the crop rows of the training data instant by instant
    (learning.distill.match_identities: the identity centred in the row's crop, Hungarian,
    gated) and its reprojected filtered 3D is that row's pseudo-labels: every subject's
    rows (TrainingData: the labelled (instant, subject) rows and each subject's unlabelled
    rows) get their own subject's. The figures add `subjects`, `rows_unmatched` (rows of
    instants the teacher ran on that got no identity) and `rows_per_subject` (rows that got
    a pseudo-label)."""
    from monet_ros.commands.common import (
        ASSOCIATION_OPTIONS,
        changed_options,
        subjects_options,
        tracker_options,
    )
    from monet_ros.commands.process import process_recording
    from monet_ros.learning.distill import align_to_instants, distilled_labels
    from monet_ros.models import save_checkpoint
    from monet_ros.temporal import FilterConfig

    c = trainer.config
    if trainer.out_dir is None:
        raise ValueError('distillation rounds need an output folder (the teacher checkpoint '
                         'and its monet process run are written there)')
    folder = trainer.out_dir / 'distill'
    run_dir = folder / f'round_{index}'
    if run_dir.exists():          # a round killed before it trained: run it again
        shutil.rmtree(run_dir)
    teacher = folder / f'teacher_{index}.pt'
    save_checkpoint(teacher, trainer.model, trainer.metadata())
    process = teacher_process_config()
    filter_config = FilterConfig(method='optim',
                                 confidence_threshold=process.confidence_threshold,
                                 threshold_px=process.threshold_px)
    if subjects is None and trainer.data.recording.num_subjects > 1:
        from monet_ros.subjects.detection import SubjectsConfig
        subjects = SubjectsConfig(subjects=trainer.data.recording.num_subjects)
    several = subjects is not None and subjects.subjects > 1
    as_process = '--filter optim'
    if several:      # the teacher's several-subject settings other than the defaults
        given = (changed_options(subjects, subjects_options())
                 + (changed_options(association, ASSOCIATION_OPTIONS) if association else [])
                 + (changed_options(tracker, tracker_options()) if tracker else []))
        as_process = ' '.join([f'--subjects {subjects.subjects}', *given, as_process])
    say(f'distillation round {index} of {c.distill_rounds} at step {trainer.step_count}: '
        f'the detector runs over {bag} as `monet process {as_process}` -> {run_dir}'
        + (f' (the labels hold up to {subjects.subjects} subjects per instant)'
           if several else ''))
    figures = process_recording(bag, teacher, run_dir, rig=rig, config=process,
                                device=str(trainer.device), skeleton=skeleton,
                                progress=progress, exports=('csv',), camera_map=camera_map,
                                precision=trainer.precision, filter_config=filter_config,
                                rig_units=rig_units, subjects=subjects if several else None,
                                association=association if several else None,
                                tracker=tracker if several else None)
    data = trainer.data
    recording = data.recording
    C = data.labels.shape[2]
    smoothed = figures['filter']
    if several:         # SmoothedSubjects: one row per frame and identity
        X, error, ncams, matched, unmatched = _subject_rows(data, figures)
    else:
        if smoothed is None:
            X, error, ncams = (np.full((0, C, 3), np.nan), np.zeros((0, C)), np.zeros((0, C)))
            stamps = np.zeros(0, np.int64)
        else:
            X, error, ncams = smoothed.X, smoothed.error, smoothed.ncams
            stamps = figures['filter_stamps']
        X, matched = align_to_instants(recording.stamps, stamps, X)
        error = align_to_instants(recording.stamps, stamps, error)[0]
        ncams = align_to_instants(recording.stamps, stamps, ncams, fill=0)[0]
    cells = distill_cells(data)
    distilled = distilled_labels(X, error, ncams, recording.cameras, cells,
                                 units=figures['units'], gate_px=c.distill_gate_px,
                                 min_views=c.distill_min_views,
                                 residual_px=c.distill_residual_px, matched=matched)
    if several:       # `matched` was by crop row: the summary counts instants
        ran = np.isin(recording.stamps, np.asarray(figures.get('filter_stamps', ()), np.int64))
        distilled.counts['frames_unmatched'] = int((~ran).sum())
    trainer.set_distilled(distilled.points, distilled.weight, index)
    kept = distilled.weight[distilled.weight > 0]
    stats = {'round': index, 'step': trainer.step_count, 'teacher': str(teacher),
             'process': str(run_dir), 'frames': figures['frames'],
             'process_seconds': round(figures['seconds'], 1),
             'median_weight': float(np.median(kept)) if kept.size else None,
             **distilled.counts}
    if several:
        stats['subjects'] = subjects.subjects
        stats['rows_unmatched'] = unmatched
        per = data.row_subjects[np.isfinite(distilled.points[..., 0]).any(axis=(1, 2))]
        stats['rows_per_subject'] = {int(k): int((per == k).sum()) for k in np.unique(
            data.row_subjects)}
        say(f"distillation round {index}: the teacher's identities matched to the subjects' "
            'crop rows (learning.distill.match_identities): crop rows with pseudo-labels per '
            'subject '
            + ', '.join(f'{k} {n}' for k, n in stats['rows_per_subject'].items())
            + f'; {unmatched} crop rows of instants the teacher ran on got no identity')
    say(f'distillation round {index}: {distilled.summary()}; median weight '
        f'{stats["median_weight"] if kept.size else 0:.2f}; training steps '
        f'{trainer.step_count + 1}-{trainer.step_count + c.distill_round_steps} with '
        f'{c.batch_distill} distilled crops per step'
        + ('' if c.lambda_d else ' at lambda_d 0 (the exact control: no L_D)'))
    if distilled.count == 0 and c.lambda_d:
        trainer.warn(f'distillation round {index} kept no pseudo-label ({distilled.summary()}): '
                     "L_D gets no data this round (check the teacher's output in "
                     f'{run_dir}, or raise distill_gate_px / lower distill_min_views)')
    return stats



def distill_cells(data):
    """(R, V, C) bool of a TrainingData (R = data.num_rows, by crop row: the instants with
    one subject): the cells a distillation round can teach, the unlabelled view x keypoint
    cells of rows of training instants (not the eval_fraction tail, not validation)."""
    train = np.zeros(data.labels.shape[0], bool)
    train[data.train] = True
    train[data.validation_instants] = False
    return ~np.isfinite(data.row_labels[..., 0]) & train[data.row_instants][:, None, None]


def _subject_rows(data, figures):
    """The teacher's filtered rows of several subjects (figures of a `monet process
    --subjects` run: SmoothedSubjects, filter_stamps) placed on the crop rows of `data`
    (learning.distill.match_identities): (X (R, C, 3), error (R, C), ncams (R, C), matched
    (R,) rows whose instant the teacher ran on, unmatched: how many of those got no
    identity), R = data.num_rows."""
    from monet_ros.learning.distill import match_identities

    R, C = data.num_rows, data.labels.shape[2]
    X, error, ncams = np.full((R, C, 3), np.nan), np.full((R, C), np.nan), np.zeros((R, C))
    smoothed = figures['filter']
    stamps = np.asarray(figures.get('filter_stamps', np.zeros(0)), np.int64)
    index = {int(s): t for t, s in enumerate(data.recording.stamps)}
    ran = np.zeros(data.recording.num_instants, bool)
    ran[[index[int(s)] for s in stamps if int(s) in index]] = True
    matched = ran[data.row_instants]
    if smoothed is None or not len(smoothed.rows.frame):
        return X, error, ncams, matched, int(matched.sum())
    rows = smoothed.rows
    instants = np.array([index.get(int(stamps[f]), -1) for f in rows.frame], np.int64)
    match, _ = match_identities(rows.X, instants, data.row_instants, data.row_boxes,
                                data.recording.cameras, units=figures['units'],
                                row_points=data.row_labels)
    got = match >= 0
    X[got], error[got], ncams[got] = rows.X[match[got]], rows.error[match[got]], \
        rows.ncams[match[got]]
    return X, error, ncams, matched, int((matched & ~got).sum())
