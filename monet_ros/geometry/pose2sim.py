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


def read_openpose_folder(folder, num_keypoints=25, person=0):
    """OpenPose JSON files of one camera (sorted by name) -> (F, K, 3) array of u, v,
    likelihood; NaN for frames without that person (Pose2Sim writes an empty `{}`)."""
    files = sorted(Path(folder).glob('*.json'))
    if not files:
        raise FileNotFoundError(f'no OpenPose .json files in {folder}')
    out = np.full((len(files), num_keypoints, 3), np.nan)
    for f, path in enumerate(files):
        try:
            people = json.loads(path.read_text())['people']
            found = len(people) > person and people[person].get('pose_keypoints_2d')
            values = np.asarray(people[person]['pose_keypoints_2d'], dtype=np.float64) \
                if found else None
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f'{path}: not an OpenPose JSON file ({exc})') from None
        if values is not None:
            if values.size != 3 * num_keypoints:
                raise ValueError(f'{path}: pose_keypoints_2d has {values.size} values, '
                                 f'expected {3 * num_keypoints}')
            out[f] = values.reshape(num_keypoints, 3)
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
