"""Reading a Pose2Sim trial: OpenPose JSON detections and .trc marker files.

Pose2Sim conventions (github.com/perfanalytics/pose2sim, skeletons.py / triangulation.py):
the .trc lists the markers of the pose model's skeleton tree in pre-order, each marker is one
OpenPose keypoint (BODY_25B ids below), coordinates in metres with Y up:
trc (X, Y, Z) = world (Y, Z, X).
"""
import json
from pathlib import Path

import numpy as np

# BODY_25B keypoint id of each Pose2Sim marker name (Pose2Sim skeletons.py, BODY_25B tree).
BODY_25B_IDS = {
    'Nose': 0, 'LShoulder': 5, 'RShoulder': 6, 'LElbow': 7, 'RElbow': 8, 'LWrist': 9,
    'RWrist': 10, 'LHip': 11, 'RHip': 12, 'LKnee': 13, 'RKnee': 14, 'LAnkle': 15,
    'RAnkle': 16, 'Neck': 17, 'Head': 18, 'LBigToe': 19, 'LSmallToe': 20, 'LHeel': 21,
    'RBigToe': 22, 'RSmallToe': 23, 'RHeel': 24,
}


_EYES_EARS = ('LEye', 'REye', 'LEar', 'REar')
_COCO_17 = ('Nose',) + _EYES_EARS + ('LShoulder', 'RShoulder', 'LElbow', 'RElbow', 'LWrist',
                                     'RWrist', 'LHip', 'RHip', 'LKnee', 'RKnee', 'LAnkle',
                                     'RAnkle')
# Keypoint names of each pose model in its output order (the index of an x, y, c triplet in
# pose_keypoints_2d), with Pose2Sim's marker names (skeletons.py): OpenPose BODY_25,
# BODY_25B and COCO (18), AlphaPose HALPE_26, COCO_17 (MMPose, RTMPose, ...).
POSE_MODELS = {
    'BODY_25': ('Nose', 'Neck', 'RShoulder', 'RElbow', 'RWrist', 'LShoulder', 'LElbow',
                'LWrist', 'CHip', 'RHip', 'RKnee', 'RAnkle', 'LHip', 'LKnee', 'LAnkle',
                'REye', 'LEye', 'REar', 'LEar', 'LBigToe', 'LSmallToe', 'LHeel', 'RBigToe',
                'RSmallToe', 'RHeel'),
    'BODY_25B': _COCO_17 + ('Neck', 'Head', 'LBigToe', 'LSmallToe', 'LHeel', 'RBigToe',
                            'RSmallToe', 'RHeel'),
    'COCO_18': ('Nose', 'Neck', 'RShoulder', 'RElbow', 'RWrist', 'LShoulder', 'LElbow',
                'LWrist', 'RHip', 'RKnee', 'RAnkle', 'LHip', 'LKnee', 'LAnkle', 'REye',
                'LEye', 'REar', 'LEar'),
    'COCO_17': _COCO_17,
    'HALPE_26': _COCO_17 + ('Head', 'Neck', 'Hip', 'LBigToe', 'RBigToe', 'LSmallToe',
                            'RSmallToe', 'LHeel', 'RHeel'),
}


def read_openpose_json(path):
    """The people of one OpenPose JSON file (`people[i].pose_keypoints_2d` = x, y, c
    triplets) -> list of (K, 3) float arrays u, v (px), confidence, one per person in the
    file's order; a person without pose_keypoints_2d (Pose2Sim writes `{}`) is None.
    Raises ValueError naming the file and field."""
    path = Path(path)
    try:
        people = json.loads(path.read_text(encoding='utf-8'))['people']
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f'{path}: not an OpenPose JSON file ({exc})') from None
    except (KeyError, TypeError):
        raise ValueError(f'{path}: field people: missing; not an OpenPose JSON file') from None
    if not isinstance(people, list):
        raise ValueError(f'{path}: field people: expected a list')
    out = []
    for i, person in enumerate(people):
        values = person.get('pose_keypoints_2d') if isinstance(person, dict) else None
        if not values:
            out.append(None)
            continue
        try:
            values = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f'{path}: field people[{i}].pose_keypoints_2d: not numbers') \
                from None
        if values.ndim != 1 or values.size % 3:
            raise ValueError(f'{path}: field people[{i}].pose_keypoints_2d: {values.size} '
                             'values, not x, y, c triplets')
        out.append(values.reshape(-1, 3))
    return out


def read_openpose_folder(folder, num_keypoints=25, person=0):
    """OpenPose JSON files of one camera (sorted by name) -> (F, K, 3) array of u, v,
    likelihood; NaN for frames without that person (Pose2Sim writes an empty `{}`)."""
    files = sorted(Path(folder).glob('*.json'))
    if not files:
        raise FileNotFoundError(f'no OpenPose .json files in {folder}')
    out = np.full((len(files), num_keypoints, 3), np.nan)
    for f, path in enumerate(files):
        people = read_openpose_json(path)
        values = people[person] if len(people) > person else None
        if values is not None:
            if values.size != 3 * num_keypoints:
                raise ValueError(f'{path}: pose_keypoints_2d has {values.size} values, '
                                 f'expected {3 * num_keypoints}')
            out[f] = values
    return out


def read_trc(path):
    """A .trc marker file -> (marker names, frame numbers (F,), coordinates (F, M, 3)) in
    the file's axes and units (NaN for empty cells)."""
    try:
        lines = Path(path).read_text().splitlines()
        names = [n for n in lines[3].split('\t')[2:] if n.strip()]
        rows = [line.split('\t') for line in lines[5:] if line.strip()]
        frames = np.array([int(float(r[0])) for r in rows])
        values = np.full((len(rows), 3 * len(names)), np.nan)
        for i, r in enumerate(rows):
            cells = [float(c) if c.strip() else np.nan for c in r[2:2 + 3 * len(names)]]
            values[i, :len(cells)] = cells
    except (IndexError, ValueError, OverflowError, UnicodeDecodeError) as exc:
        raise ValueError(f'{path}: not a .trc marker file ({type(exc).__name__}: '
                         f'{exc})') from None
    if not names or not rows:
        raise ValueError(f'{path}: not a .trc marker file (no markers or no rows)')
    return names, frames, values.reshape(len(rows), len(names), 3)


def trc_to_world(xyz):
    """Pose2Sim .trc axes -> calibration world axes: trc (X, Y, Z) = world (Y, Z, X)."""
    xyz = np.asarray(xyz)
    return xyz[..., [2, 0, 1]]
