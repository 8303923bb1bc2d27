"""`monet labels import openpose`: OpenPose JSON folders (one per camera, frame from the file
name) of a recording's labelled instants, with a second, less confident person in some
files, import to the recording's own labels; the keypoint names come from the skeleton or
--pose-model."""
import json

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import numpy as np

from monet_ros.cli import main
from monet_ros.labels import read_labels

SKELETON = 'name: blobs\nkeypoints: [k0, k1, k2]\n'


def test_openpose_folders_import_to_the_recordings_labels(tmp_path, capsys):
    rec = blob_recording(num_views=3, T=12, C=3, labelled=(2, 9))
    data = write_blob_folder(rec, tmp_path / 'data')
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text(SKELETON)
    for v, cam in enumerate(rec.cameras):
        folder = tmp_path / 'json' / f'{cam.name}_json'
        folder.mkdir(parents=True)
        for t in rec.labelled_instants:
            person = np.concatenate([rec.labels[t, v], np.full((3, 1), 0.9)], -1)
            people = [person]
            if v == 1:                                  # a bystander, less confident
                people.insert(0, np.concatenate([rec.labels[t, v] + 7.0,
                                                 np.full((3, 1), 0.4)], -1))
            (folder / f'{cam.name}_{t:012d}_keypoints.json').write_text(json.dumps(
                {'people': [{'pose_keypoints_2d': p.ravel().tolist()} for p in people]}))
    out = tmp_path / 'labels.csv'
    assert main(['labels', 'import', 'openpose', str(tmp_path / 'json'), '--rec', str(data),
                 '--out', str(out), '--skeleton', str(skeleton)]) == 0
    text = capsys.readouterr().out
    assert 'monet labels import: 18 labels at 2 instants x 3 cameras' in text
    assert 'keypoint names of the skeleton (in order)' in text
    assert '2 of 6 files had several people: the person with the highest mean confidence ' \
           'per file kept, 2 others left out' in text
    got, want = read_labels(out, rec.keypoints), read_labels(data / 'labels.csv', rec.keypoints)
    assert got.stamps == want.stamps
    for s in want.stamps:
        np.testing.assert_array_equal(got.points(s, ['cam0', 'cam1', 'cam2']),
                                      want.points(s, ['cam0', 'cam1', 'cam2']))
    # a stated model with another keypoint count: one line naming the file and the model
    assert main(['labels', 'import', 'openpose', str(tmp_path / 'json'), '--rec', str(data),
                 '--out', str(tmp_path / 'x.csv'), '--pose-model', 'COCO_17']) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert 'field pose_keypoints_2d: 3 keypoints per person, but COCO_17 has 17' in err


def test_pose2sim_json_maps_onto_a_skeleton_with_the_shipped_keypoint_map(shared_data,
                                                                          tmp_path, capsys):
    """The real Pose2Sim demo's BODY_25B JSON, --skeleton human14 --keypoint-map body25b:
    the map renames before the skeleton filters (it used to leave 0 labels, exit 0); each
    label is the JSON's point of the mapped marker, scaled to the half-size recording."""
    trial = shared_data / 'pose2sim_demo_balancing' / 'S00_P00_SingleParticipant' / \
        'S00_P00_T01_BalancingTrial' / 'pose-associated'
    rec = shared_data / 'derived_pose2sim_4cam_mcap' / 'pose2sim_balancing_4cam'
    out = tmp_path / 'labels.csv'
    args = ['labels', 'import', 'openpose', *map(str, sorted(trial.glob('cam*_json'))),
            '--rec', str(rec), '--pose-model', 'BODY_25B', '--label-scale', '0.5',
            '--skeleton', 'human14']
    assert main([*args, '--keypoint-map', 'body25b', '--out', str(out)]) == 0
    assert 'left out: Nose, LEye, REye, LEar, REar, LBigToe' in capsys.readouterr().out
    labels = read_labels(out)
    assert set(labels.keypoints) == {'head', 'neck', 'r_shoulder', 'r_elbow', 'r_wrist',
                                     'l_shoulder', 'l_elbow', 'l_wrist', 'r_hip', 'r_knee',
                                     'r_ankle', 'l_hip', 'l_knee', 'l_ankle'}
    # an independent read of one file: BODY_25B's Head (index 18) and RWrist (index 10)
    person = json.loads((trial / 'cam02_json' / 'cam02.0040.json').read_text())['people']
    best = max((np.reshape(p['pose_keypoints_2d'], (-1, 3)) for p in person),
               key=lambda p: p[p[:, 2] > 0, 2].mean())
    stamp = labels.stamps[40]
    points = labels.points(stamp, ['cam02'])[0]
    names = list(labels.keypoints)
    for marker, joint in ((18, 'head'), (10, 'r_wrist')):      # pixel centres scale
        np.testing.assert_allclose(points[names.index(joint)],
                                   (best[marker, :2] + 0.5) * 0.5 - 0.5, atol=1e-3)
    # no map: nothing of BODY_25B is in human14 -> one line, exit 2, nothing written
    empty = tmp_path / 'empty.csv'
    assert main([*args, '--out', str(empty)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'no label left to write' in err[0] and not empty.exists()


def test_points_without_a_position_are_counted(tmp_path, capsys):
    """Keypoints OpenPose did not detect (c = 0) and non-finite ones are left out of the
    labels and counted in the summary (they were left out without a word)."""
    rec = blob_recording(num_views=3, T=12, C=3, labelled=(2, 9))
    data = write_blob_folder(rec, tmp_path / 'data')
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text(SKELETON)
    for v, cam in enumerate(rec.cameras):
        folder = tmp_path / 'json' / f'{cam.name}_json'
        folder.mkdir(parents=True)
        for t in rec.labelled_instants:
            person = np.concatenate([rec.labels[t, v], np.full((3, 1), 0.9)], -1)
            if v == 0:
                person[1] = 0.0                         # not detected: 0, 0, c = 0
            if v == 2 and t == rec.labelled_instants[0]:
                person[2, 0] = np.nan                   # json.dumps writes NaN
            (folder / f'{cam.name}_{t:012d}_keypoints.json').write_text(json.dumps(
                {'people': [{'pose_keypoints_2d': person.ravel().tolist()}]}))
    out = tmp_path / 'labels.csv'
    assert main(['labels', 'import', 'openpose', str(tmp_path / 'json'), '--rec', str(data),
                 '--out', str(out), '--skeleton', str(skeleton)]) == 0
    text = capsys.readouterr().out
    assert 'monet labels import: 15 labels at 2 instants x 3 cameras' in text, text
    assert '3 points without a position in the source (NaN / inf, not detected or not ' \
        'placed) left out' in text, text
