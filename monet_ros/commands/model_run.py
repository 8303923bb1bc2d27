"""A model run over a recording as `monet process` runs it, and its figures against a
reference: the one place `monet eval --reference` and `monet train --holdout-labelled` run
and score a model (one subject or several)."""
from pathlib import Path
import tempfile

import numpy as np


def run_model(bag, model, cameras, rig=None, device=None, camera_map=(), rig_units=None,
              subjects=None, association=None, tracker=None):
    """`model` run over `bag` as `monet process` runs it (process.process_recording: the
    one-subject tracked crops; with `subjects` a subjects.detection.SubjectsConfig of
    N >= 2 as `monet process --subjects N`, with association / tracker its other configs,
    None: that command's defaults) -> dict: stamps (R,) ns, subject (R,) int track
    identities (None for one subject), X (R, C, 3) in the rig's unit, points2d
    (R, V, C, 2) px: the 2D detections in `cameras` (Camera list; matched by name, NaN
    for a camera the run lacks) - one row per processed instant, or per instant and track.
    The one place `monet eval --reference` and `monet train --holdout-labelled` run a
    model; raises as process_recording."""
    from monet_ros.commands.process import process_recording
    from monet_ros.io.export_tables import read_anipose_csv

    several = subjects is not None and subjects.subjects > 1
    with tempfile.TemporaryDirectory(prefix='monet-eval-') as tmp:
        out = Path(tmp) / 'run'
        figures = process_recording(bag, model, out, rig=rig, device=device, progress=False,
                                    exports=() if several else ('csv', 'npz'),
                                    camera_map=camera_map, rig_units=rig_units,
                                    subjects=subjects if several else None,
                                    association=association, tracker=tracker)
        if several:
            rows = figures['subjects']
            frame = np.asarray(rows.frame, np.int64)
            stamps = np.asarray(figures['subject_stamps'], np.int64)[frame]
            ident, X, p2 = np.asarray(rows.subject, np.int64), rows.X, rows.points2d
            names = list(figures['subject_cameras'])
            X = np.asarray(X, float).reshape(len(stamps), len(figures['subject_keypoints']), 3)
        else:
            table = read_anipose_csv(out / 'keypoints3d.csv')
            det = np.load(out / 'detections2d.npz')
            stamps, ident, X = table['stamps_ns'], None, table['X']
            p2, names = det['points2d'], list(det['cameras'])
    C = X.shape[1]
    points2d = np.full((len(stamps), len(cameras), C, 2), np.nan)
    if len(stamps):
        p2 = np.asarray(p2, float).reshape(len(stamps), len(names), C, 2)
        for v, cam in enumerate(cameras):
            if cam.name in names:
                points2d[:, v] = p2[:, names.index(cam.name)]
    return dict(stamps=np.asarray(stamps, np.int64), subject=ident, X=X, points2d=points2d)


def score_run(references, run, px_thresholds, mm_thresholds, instants=None):
    """evaluation.reference figures of a run_model result against load_references'
    references: one subject's run by score (one reference), several subjects' by
    score_subjects (pooled, with `subjects`: one dict per reference subject and its
    matched track)."""
    from monet_ros.evaluation.reference import score, score_subjects
    if run['subject'] is None:
        return score(references[0], run['stamps'], run['X'], run['points2d'], px_thresholds,
                     mm_thresholds, instants=instants)
    return score_subjects(references, run['stamps'], run['subject'], run['X'],
                          run['points2d'], px_thresholds, mm_thresholds, instants=instants)
