"""SLEAP project / prediction files (.slp, read with h5py in SLEAP's own layout): the four
real .slp files of the sleap-anipose session give exactly the rows of the analysis .h5 files
SLEAP exported from them; a copy of one rewritten with h5py to hold two tracks per frame
(and a user instance correcting a predicted one, as proofreading leaves it) gives one
subject per track, the user's points where they replace the prediction; two untracked
instances in one frame are one error line."""
import json
import shutil

import h5py
import numpy as np
import pytest

from monet_ros.labels import LabelError
from monet_ros.labels_import import import_labels
from monet_ros.labels_import.points2d import read_points2d

SESSION = 'sleap_anipose_minimal_session'
CAMERAS = ('back', 'mid', 'side', 'top')


def rows_of(result):
    return sorted((r.camera, r.frame, r.keypoint, r.u, r.v, r.score, r.subject)
                  for r in result.rows)


def test_real_slp_files_read_as_their_analysis_exports(shared_data):
    root = shared_data / SESSION
    h5 = import_labels('sleap', sorted(root.glob('*/*.analysis.h5')), cameras=CAMERAS)
    slp = import_labels('sleap', sorted(root.glob('*/*.slp')), cameras=CAMERAS)
    assert len(slp.rows) == len(h5.rows) == 6576
    assert rows_of(slp) == rows_of(h5)                   # exact floats, scores, cameras
    assert slp.keypoints == h5.keypoints and slp.subjects == {}
    points = read_points2d(root / 'back' / 'minimal_back_proofread.slp', ['back'])
    assert points.fmt == 'sleap' and points.keypoints == h5.keypoints


def two_track_copy(source, out, untracked=False):
    """`source` .slp rewritten in SLEAP's layout with a second track: every predicted
    instance duplicated 40 px to the right as track_1; frame 3's track_0 prediction
    corrected by a user instance (10 px down) made from it. untracked: both instances of
    frame 0 without a track. Returns the shift and the corrected frame."""
    shutil.copy(source, out)
    with h5py.File(out, 'r+') as f:
        frames, inst, pred = f['frames'][()], f['instances'][()], f['pred_points'][()]
        assert (inst['instance_type'] == 1).all() and len(inst) == len(frames)
        new_inst, new_pred, user = [], [], []
        for k, i in enumerate(inst):
            pts = pred[i['point_id_start']:i['point_id_end']]
            for track in (0, 1):
                row = i.copy()
                row['instance_id'] = len(new_inst)
                row['track'] = -1 if untracked and k == 0 else track
                shifted = pts.copy()
                shifted['x'] += 40.0 * track
                row['point_id_start'] = sum(len(p) for p in new_pred)
                row['point_id_end'] = row['point_id_start'] + len(pts)
                new_pred.append(shifted)
                new_inst.append(row)
            if k == 3:                       # a user correction of track_0's prediction
                row = i.copy()
                row['instance_id'] = len(new_inst)
                row['instance_type'] = 0
                row['track'] = 0
                row['from_predicted'] = new_inst[-2]['instance_id']
                moved = np.zeros(len(pts), f['points'].dtype)
                for name in ('x', 'y', 'visible', 'complete'):
                    moved[name] = pts[name]
                moved['y'] += 10.0
                row['point_id_start'] = sum(len(p) for p in user)
                row['point_id_end'] = row['point_id_start'] + len(pts)
                user.append(moved)
                new_inst.append(row)
        frames = frames.copy()
        start = 0
        for k in range(len(frames)):
            n = 3 if k == 3 else 2
            frames[k]['instance_id_start'], frames[k]['instance_id_end'] = start, start + n
            start += n
        for name, data in (('frames', frames), ('instances', np.array(new_inst)),
                           ('pred_points', np.concatenate(new_pred)),
                           ('points', np.concatenate(user))):
            del f[name]
            f.create_dataset(name, data=data, maxshape=(None,))
        del f['tracks_json']
        f['tracks_json'] = np.array([json.dumps([0, 'track_0']).encode(),
                                     json.dumps([0, 'track_1']).encode()])
    return 40.0, 3


def test_two_tracks_in_a_slp_become_subjects(shared_data, tmp_path):
    root = shared_data / SESSION
    source = root / 'back' / 'minimal_back_proofread.slp'
    copy = tmp_path / 'back_two.slp'
    shift, fixed = two_track_copy(source, copy)
    one = import_labels('sleap', source, cameras=CAMERAS)
    two = import_labels('sleap', copy, cameras=CAMERAS)
    assert two.subjects == {'track_0': 0, 'track_1': 1}
    assert 'subjects: track_0=0, track_1=1 (SLEAP tracks)' in two.note
    expected = []
    for r in one.rows:
        down = 10.0 if r.frame == fixed else 0.0
        expected.append((r.camera, r.frame, r.keypoint, r.u, r.v + down,
                         None if down else r.score, 0))
        expected.append((r.camera, r.frame, r.keypoint, r.u + shift, r.v, r.score, 1))
    assert rows_of(two) == sorted(expected)
    assert two.instance_keypoints == tuple(f'track_{t}/{k}' for t in (0, 1)
                                           for k in one.keypoints)
    bad = tmp_path / 'untracked.slp'
    two_track_copy(source, bad, untracked=True)
    with pytest.raises(LabelError, match=r'untracked.slp: frame 0 video 0 instance 1: field '
                       'track: two instances without a track in frame 0 of camera back'):
        import_labels('sleap', bad, cameras=CAMERAS)
