"""Leave-instants-out check for `monet train --holdout-labelled N`: N labelled instants
(spread over the instants where any subject is labelled: learning.trainer.spread_instants,
the rule of the online learner's validation labels too) lose every subject's labels before
training (learning.trainer.TrainingData's holdout). After training they are scored two
ways: every subject's, pooled and per subject, in crops around each subject framed without
its labels, as `--validation-labels` scores its instants (Trainer.holdout_error); and as
`monet process` runs the saved model (tracked crops; with labels of several subjects as
`monet process --subjects N`, N the most subjects labelled at an instant, with `monet
train`'s several-subject settings, those of the distillation teacher), its 2D detections
and 3D points against those labels (pixels on the labelled views; mm against the labels'
own triangulation) with monet_ros.evaluation.reference - an accuracy figure, unlike the
reprojection error: pooled over every subject and, with several, per subject against the
track matched to it (score_subjects: one-to-one, least mean 3D distance).
OUT/heldout_labels.csv holds every held-out subject's labels (a `subject` column when
there are several), what `monet eval --reference` scores too.
"""
from pathlib import Path

import numpy as np


def choose_holdout(labelled, n):
    """n of the labelled instant indices, evenly spread (deterministic); ValueError when
    fewer than n + 1 are labelled (training needs one)."""
    from monet_ros.learning.trainer import spread_instants
    labelled = np.asarray(labelled)
    if n > 0 and len(labelled) < n + 1:
        raise ValueError(f'--holdout-labelled {n} needs at least {n + 1} labelled instants, '
                         f'the recording has {len(labelled)}')
    return spread_instants(labelled, n)


def hold_out(recording, n, out):
    """Choose n labelled instants of `recording` (choose_holdout of Recording.
    labelled_instants: any subject's) and write every subject's labels there to
    OUT/heldout_labels.csv (labels CSV, stamp-keyed, px; the `subject` column when a
    subject other than 0 is labelled there: what score_holdout and `monet eval
    --reference` score) -> (instant indices, path) or ((), None) when n == 0. The
    recording is not changed: TrainingData removes every subject's labels there (its
    holdout)."""
    from monet_ros.labels import label_rows, write_labels
    held = choose_holdout(recording.labelled_instants, n)
    if not len(held):
        return held, None
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / 'heldout_labels.csv'
    names = [c.name for c in recording.cameras]
    rows = [(*row, 0) for row in label_rows(recording.stamps[held], names,
                                            recording.keypoints, recording.labels[held])]
    others = np.flatnonzero(np.isin(recording.other_instants, held))
    for j in others:
        rows += [(*row, int(recording.other_subjects[j])) for row in label_rows(
            recording.stamps[recording.other_instants[j:j + 1]], names, recording.keypoints,
            recording.other_labels[j:j + 1])]
    rows.sort(key=lambda r: (r[0], r[5]))
    write_labels(path, rows)
    return held, path


def score_holdout(bag, rig, model, labels_path, recording, camera_map=(), rig_units=None,
                  subjects=None, association=None, tracker=None):
    """Figures (evaluation.reference.score) of `model` run as `monet process` runs it
    (commands.model_run.run_model) on the held-out labels of `labels_path` (2D in px
    on the labelled views; 3D errors in mm against the labels' own triangulation whatever
    the rig's unit; rig_units: that of a rig file that states none). subjects (a
    subjects.detection.SubjectsConfig of N >= 2), association, tracker: the model runs as
    `monet process --subjects N` and every held-out subject is scored against the track
    matched to it (evaluation.reference.score_subjects: pooled figures plus `subjects`, one
    dict per labelled subject with its matched track and figures). Raises LabelError /
    ValueError / OSError as load_references and process_recording."""
    from monet_ros.commands.model_run import run_model, score_run
    from monet_ros.evaluation.reference import (
        MM_THRESHOLDS,
        PX_THRESHOLDS,
        load_references,
    )
    from monet_ros.learning.recording_index import RecordingIndex

    cameras = list(recording.cameras)
    index = RecordingIndex(bag, cameras, {}, recording.stamps,
                           np.ones(len(recording.stamps), bool), None)
    references = load_references(labels_path, index, recording.keypoints, fmt='labels')
    several = subjects is not None and subjects.subjects > 1
    if len(references) > 1 and not several:
        raise ValueError(f'{labels_path}: field subject: labels of several subjects are '
                         'scored by a run with several subjects (subjects N >= 2)')
    run = run_model(bag, model, cameras, rig=rig, camera_map=camera_map, rig_units=rig_units,
                    subjects=subjects, association=association, tracker=tracker)
    return score_run(references, run, PX_THRESHOLDS, MM_THRESHOLDS)
