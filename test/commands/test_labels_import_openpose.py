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
