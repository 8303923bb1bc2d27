"""OpenPose JSON folders, the 2D input of Pose2Sim (`pose/` and `pose-associated/`).

Layout: one folder per camera (e.g. cam01_json/) of one JSON file per video frame
(OpenPose: <video>_000000000012_keypoints.json; Pose2Sim: cam01.0012.json), each holding
`people[i].pose_keypoints_2d` = x, y, c triplets (pixels, confidence), one per keypoint of
the pose model. Read as:
- frame = the last number in the file name (12 above), the video's frame index;
- camera = the folder's name matched to the rig's cameras (as anipose matches file names:
  cam01_json -> cam01; --camera-map SRC=DST renames), else the name of the folder above
  it (cam01/json/);
- keypoint names = the stated pose model's (pose_model, geometry.pose2sim.POSE_MODELS:
  BODY_25, BODY_25B, COCO_18, COCO_17, HALPE_26), else the skeleton's names when it has as
  many keypoints as the files (in the model's output order), else the one model with that
  many keypoints (17, 18, 26); 25 is BODY_25 or BODY_25B and must be stated;
- one subject: in a file with several people the person with the highest mean confidence
  (over all its keypoints) is kept, the others are left out and counted in the note;
- a keypoint with c = 0 (OpenPose's "not detected") or non-finite x / y is missing (a
  row with u = v = NaN of the best person: labels_import's missing points);
- a folder's frame count is its largest file frame number + 1 (a file per frame, empty
  ones included).
With a skeleton and a stated model, the model's keypoints the skeleton lacks are left out
and named in the note.
"""
import numpy as np

from monet_ros.labels import LabelError, LabelRow
from monet_ros.labels_import import ImportResult, camera_for

RULE = 'the person with the highest mean confidence per file kept'


def json_folders(paths):
    """{folder: [json files sorted by name]} of paths (folders searched recursively, or
    JSON files): one folder = one camera. Raises LabelError when there is none."""
    groups = {}
    for p in paths:
        files = sorted(p.rglob('*.json')) if p.is_dir() else [p]
        for f in files:
            groups.setdefault(f.parent, []).append(f)
    if not groups:
        raise LabelError(f'{", ".join(map(str, paths))}: no OpenPose .json files found')
    return groups


def model_names(count, source, pose_model=None, keypoints=None):
    """Keypoint names of `count` keypoints per person (module docstring rule) -> (names,
    how). Raises LabelError naming the source."""
    from monet_ros.geometry.pose2sim import POSE_MODELS
    if pose_model:
        if pose_model not in POSE_MODELS:
            raise LabelError(f'--pose-model {pose_model!r} is not one of '
                             f'{", ".join(POSE_MODELS)}')
        names = POSE_MODELS[pose_model]
        if len(names) != count:
            raise LabelError(f'{source}: field pose_keypoints_2d: {count} keypoints per '
                             f'person, but {pose_model} has {len(names)}')
        return names, pose_model
    if keypoints is not None and len(keypoints) == count:
        return tuple(keypoints), 'the skeleton (in order)'
    fits = [m for m, names in POSE_MODELS.items() if len(names) == count]
    if len(fits) == 1:
        return POSE_MODELS[fits[0]], fits[0]
    which = f'one of {", ".join(fits)}' if fits else f'none of {", ".join(POSE_MODELS)}'
    raise LabelError(f'{source}: field pose_keypoints_2d: {count} keypoints per person '
                     f'({which}): state the model with --pose-model or give a --skeleton '
                     f"of {count} keypoints in the model's order")


def _mean_confidence(c):
    """Mean of a person's finite confidences, -1 when it has none."""
    c = c[np.isfinite(c)]
    return float(c.mean()) if c.size else -1.0


def import_openpose(paths, cameras=(), camera=None, min_score=0.0, camera_map=None,
                    pose_model=None, keypoints=None, keypoint_map=None):
    """ImportResult of OpenPose JSON folders (module docstring). pose_model: a name of
    POSE_MODELS or None; keypoints: the skeleton's names or None (the model's keypoints
    that are not in it, after keypoint_map {model name: skeleton name}, are left out and
    counted; the rows keep the model's names, renamed later by --keypoint-map); min_score:
    keypoints below it are left out and counted. LabelRow.source is the camera's folder, where the
    file name. Raises LabelError (one line naming the file and field)."""
    from monet_ros.geometry.pose2sim import read_openpose_json
    from monet_ros.labels_import.dlc import frame_of_image

    rows, counts = [], {}
    names = how = None
    files_read = several = others = dropped = 0
    for folder, files in json_folders(paths).items():
        cam = camera_for(folder.name, cameras, camera, camera_map)
        if cam not in cameras:          # e.g. cam01/json/: the camera is the folder above
            above = camera_for(folder.parent.name, cameras, camera, camera_map)
            cam = above if above in cameras else cam
        last = -1
        for path in files:
            frame = frame_of_image(path.name)
            if frame is None:
                raise LabelError(f'{path}: no frame number in the file name (expected e.g. '
                                 'cam01_000000000012_keypoints.json)')
            last = max(last, frame)
            try:
                people = [p for p in read_openpose_json(path) if p is not None]
            except ValueError as error:
                raise LabelError(str(error)) from None
            files_read += 1
            if not people:
                continue
            for p in people:
                if names is None:
                    names, how = model_names(len(p), path, pose_model, keypoints)
                if len(p) != len(names):
                    raise LabelError(f'{path}: field pose_keypoints_2d: {len(p)} keypoints '
                                     f'per person, expected {len(names)} ({how})')
            if len(people) > 1:
                several += 1
                others += len(people) - 1
            best = max(people, key=lambda p: _mean_confidence(p[:, 2]))
            for c, (u, v, score) in enumerate(best):
                if not (np.isfinite(u) and np.isfinite(v)) or score == 0:
                    u = v = score = np.nan  # a row without a position (labels_import)
                elif not score >= min_score and np.isfinite(score):
                    dropped += 1
                    continue
                rows.append(LabelRow(str(folder), frame + 1, None, frame, cam, names[c],
                                     float(u), float(v), path.name,
                                     float(score) if np.isfinite(score) else None))
        counts[str(folder)] = last + 1
    names = names or ()
    notes = [f'OpenPose JSON: keypoint names of {how}'] if how else []
    if several:
        notes.append(f'{several} of {files_read} files had several people: {RULE}, '
                     f'{others} others left out')
    if dropped:
        notes.append(f'{dropped} points below --min-score {min_score} left out')
    if keypoints is not None and pose_model and names:
        renamed = dict(keypoint_map or {})
        extra = [n for n in names if renamed.get(n, n) not in keypoints]
        if extra:
            lost = sum(r.keypoint in extra and np.isfinite(r.u) for r in rows)
            rows = [r for r in rows if r.keypoint not in extra]
            names = tuple(n for n in names if n in keypoints)
            notes.append(f'{pose_model} keypoints not in the skeleton, left out: '
                         f'{", ".join(extra)} ({lost} points)')
    return ImportResult(rows, tuple(names), '; '.join(notes), counts)
