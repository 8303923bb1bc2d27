"""OpenPose / Pose2Sim JSON folders as 2D tables: the real Pose2Sim demo's all-people
`pose/` folders (one subject kept by the stated rule, counted), generated OpenPose-named
files (frame numbers from the names, c = 0 missing, the model from the keypoint count),
and errors naming the file and field."""
import json

import numpy as np
import pytest

from monet_ros.geometry.pose2sim import BODY_25B_IDS, POSE_MODELS
from monet_ros.labels import LabelError
from monet_ros.labels_import.points2d import detect_format, read_points2d

TRIAL = 'pose2sim_demo_balancing/S00_P00_SingleParticipant/S00_P00_T01_BalancingTrial'
CAMS = ('cam_01', 'cam_02', 'cam_03', 'cam_04')
MAP = {f'cam0{i}': f'cam_0{i}' for i in range(1, 5)}


def test_pose_models_name_the_pose2sim_markers_at_their_ids():
    for name, index in BODY_25B_IDS.items():
        assert POSE_MODELS['BODY_25B'][index] == name
    assert {len(v) for v in POSE_MODELS.values()} == {17, 18, 25, 26}
    for names in POSE_MODELS.values():
        assert len(set(names)) == len(names)
    # the first 17 of BODY_25B and HALPE_26 are COCO-17's
    assert POSE_MODELS['BODY_25B'][:17] == POSE_MODELS['HALPE_26'][:17] == POSE_MODELS['COCO_17']


def test_several_people_keep_the_most_confident_one_and_are_counted(shared_data):
    pose = shared_data / TRIAL / 'pose'
    assert detect_format([pose]) == 'openpose'
    p = read_points2d([pose], CAMS, camera_map=MAP, pose_model='BODY_25B')
    assert p.fmt == 'openpose' and p.keypoints == POSE_MODELS['BODY_25B']
    np.testing.assert_array_equal(p.frames, np.arange(100))
    several = others = 0
    expect = np.full((100, 4, 25, 2), np.nan)
    for v in range(4):
        for path in sorted((pose / f'cam0{v + 1}_json').glob('*.json')):
            frame = int(path.stem.split('.')[-1])
            people = [np.reshape(q['pose_keypoints_2d'], (25, 3))
                      for q in json.loads(path.read_text())['people']]
            several += len(people) > 1
            others += max(len(people) - 1, 0)
            if people:
                best = people[int(np.argmax([q[:, 2].mean() for q in people]))]
                seen = best[:, 2] > 0
                expect[frame, v, seen] = best[seen, :2]
    assert several > 100                        # the demo's second person is real
    np.testing.assert_array_equal(p.points, expect)
    assert any(f'{several} of 400 files had several people: the person with the highest '
               f'mean confidence per file kept, {others} others left out' in n
               for n in p.notes), p.notes


def write_openpose(folder, frames, people_per_frame):
    """OpenPose's own naming: <video>_<12 digits>_keypoints.json."""
    folder.mkdir(parents=True)
    for frame, people in zip(frames, people_per_frame):
        data = {'version': 1.3, 'people': [{'person_id': [-1],
                                            'pose_keypoints_2d': np.ravel(q).tolist()}
                                           for q in people]}
        (folder / f'{folder.name}_{frame:012d}_keypoints.json').write_text(json.dumps(data))


def test_generated_openpose_files_frame_numbers_from_names_and_model_from_count(tmp_path):
    rng = np.random.default_rng(0)
    frames = [12, 13, 15]                                    # starts late, frame 14 absent
    det = {}
    for cam in ('left', 'right'):
        q = np.concatenate([rng.uniform(0, 640, (3, 17, 2)), rng.uniform(0.2, 1, (3, 17, 1))],
                           -1)
        q[1, 4] = 0.0                                        # OpenPose: not detected
        det[cam] = q
        write_openpose(tmp_path / 'json' / cam, frames, [[x] for x in q])
    p = read_points2d([tmp_path / 'json'], ['left', 'right'])
    assert p.fmt == 'openpose' and p.keypoints == POSE_MODELS['COCO_17']
    assert 'keypoint names of COCO_17' in p.notes[0]
    np.testing.assert_array_equal(p.frames, [12, 13, 14, 15])
    for v, cam in enumerate(('left', 'right')):
        np.testing.assert_array_equal(p.points[[0, 1, 3], v], det[cam][..., :2][[0, 1, 2]]
                                      * np.where(det[cam][..., 2:] > 0, 1, np.nan))
        np.testing.assert_array_equal(p.score[[0, 1, 3], v][det[cam][..., 2] > 0],
                                      det[cam][..., 2][det[cam][..., 2] > 0])
    assert np.isnan(p.points[2]).all() and np.isnan(p.points[1, :, 4]).all()
    # OpenPose's --write_json into <camera>/json/: the camera is the folder above
    for cam in ('left', 'right'):
        (tmp_path / 'nested' / cam).mkdir(parents=True)
        (tmp_path / 'json' / cam).rename(tmp_path / 'nested' / cam / 'json')
    q = read_points2d([tmp_path / 'nested'], ['left', 'right'])
    np.testing.assert_array_equal(q.points, p.points)


def test_bad_openpose_input_is_named(tmp_path, shared_data):
    assoc = shared_data / TRIAL / 'pose-associated'
    with pytest.raises(LabelError, match=r'cam01\.0000\.json: field pose_keypoints_2d: 25 '
                       r'keypoints per person \(one of BODY_25, BODY_25B\): state the model '
                       'with --pose-model'):
        read_points2d([assoc], CAMS, camera_map=MAP)
    with pytest.raises(LabelError, match='25 keypoints per person, but HALPE_26 has 26'):
        read_points2d([assoc], CAMS, camera_map=MAP, pose_model='HALPE_26')
    bad = tmp_path / 'bad' / 'cam1'
    bad.mkdir(parents=True)
    (bad / 'cam1_000000000000_keypoints.json').write_text('{"people": [')
    with pytest.raises(LabelError, match='cam1_000000000000_keypoints.json: not an OpenPose'):
        read_points2d([bad], ['cam1', 'cam2'])
    (bad / 'cam1_000000000000_keypoints.json').write_text(
        '{"people": [{"pose_keypoints_2d": [1, 2, 0.5, 3]}]}')
    with pytest.raises(LabelError, match=r'people\[0\]\.pose_keypoints_2d: 4 values, not x, '
                       'y, c triplets'):
        read_points2d([bad], ['cam1', 'cam2'])
    (bad / 'cam1_000000000000_keypoints.json').unlink()
    (bad / 'nonumber.json').write_text('{"people": []}')
    with pytest.raises(LabelError, match='nonumber.json: no frame number in the file name'):
        read_points2d([bad], ['cam1', 'cam2'])
    empty = tmp_path / 'empty'
    empty.mkdir()
    with pytest.raises(LabelError, match='no 2D tables found in the folder; read: DeepLabCut '
                       '.* OpenPose / Pose2Sim JSON folders'):
        read_points2d([empty], ['cam1'])
