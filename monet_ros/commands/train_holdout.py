"""Leave-instants-out check for `monet train --holdout-labelled N`: N labelled instants
(spread over the instants where any subject is labelled: learning.trainer.spread_instants,
the rule of the online learner's validation labels too) lose every subject's labels before
training (learning.trainer.TrainingData's holdout). After training they are scored two
ways: every subject's, pooled and per subject, in crops around each subject framed without
its labels, as `--validation-labels` scores its instants (Trainer.holdout_error); and,
with labels of one subject, as `monet process` runs the saved model (tracked crops), its
2D detections and 3D points against those labels (pixels on the labelled views; mm against
the labels' own triangulation) with monet_ros.evaluation.reference - an accuracy figure,
unlike the reprojection error.
"""
from pathlib import Path
import tempfile

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
    labelled_instants: any subject's) and write subject 0's labels there to
    OUT/heldout_labels.csv (what `monet eval --reference` scores, one subject) -> (instant
    indices, path) or ((), None) when n == 0. The recording is not changed: TrainingData
    removes every subject's labels there (its holdout)."""
    from monet_ros.labels import label_rows, write_labels
    held = choose_holdout(recording.labelled_instants, n)
    if not len(held):
        return held, None
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / 'heldout_labels.csv'
    write_labels(path, label_rows(recording.stamps[held], [c.name for c in recording.cameras],
                                  recording.keypoints, recording.labels[held]))
    return held, path


def score_holdout(bag, rig, model, labels_path, recording, camera_map=(), rig_units=None):
    """Figures (evaluation.reference.score) of `model` on the held-out labels (3D errors in
    mm whatever the rig's unit; rig_units: that of a rig file that states none)."""
    from monet_ros.commands.process import process_recording
    from monet_ros.evaluation.reference import load_reference, score
    from monet_ros.io.export_tables import read_anipose_csv
    from monet_ros.learning.recording_index import RecordingIndex

    index = RecordingIndex(bag, list(recording.cameras), {}, recording.stamps,
                           np.ones(len(recording.stamps), bool), None)
    reference = load_reference(labels_path, index, recording.keypoints, fmt='labels')
    with tempfile.TemporaryDirectory(prefix='monet-holdout-') as tmp:
        out = Path(tmp) / 'p'
        process_recording(bag, model, out, rig=rig, progress=False, exports=('csv', 'npz'),
                          camera_map=camera_map, rig_units=rig_units)
        table = read_anipose_csv(out / 'keypoints3d.csv')
        det = np.load(out / 'detections2d.npz')
    names = list(det['cameras'])
    p2 = np.full(det['points2d'].shape[:1] + (len(recording.cameras),)
                 + det['points2d'].shape[2:], np.nan)
    for v, cam in enumerate(recording.cameras):
        if cam.name in names:
            p2[:, v] = det['points2d'][:, names.index(cam.name)]
    return score(reference, table['stamps_ns'], table['X'], p2)
