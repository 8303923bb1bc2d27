"""Shipped keypoint name maps (config/keypoint_maps): every target is a human14 keypoint,
each set covers what it has, a map is selected by name through LabelOptions, and Pose2Sim's
real .trc marker names are covered by body25b."""
import pytest

from monet_ros.keypoint_maps import keypoint_map_names, load_keypoint_map
from monet_ros.labels import LabelError, LabelOptions
from monet_ros.skeleton import load_skeleton

HUMAN14 = set(load_skeleton('human14').keypoints)
# BODY_25 / BODY_25B / Halpe-26 have every human14 joint; COCO-17 has no neck
COVERED = {'body25': HUMAN14, 'body25b': HUMAN14, 'halpe26': HUMAN14,
           'coco17': HUMAN14 - {'neck'}}


def test_shipped_maps_point_at_human14():
    assert keypoint_map_names() == ('body25', 'body25b', 'coco17', 'halpe26')
    for name, covered in COVERED.items():
        pairs = load_keypoint_map(name)
        assert {t for _, t in pairs} == covered, name
        assert len({s for s, _ in pairs}) == len(pairs), name        # no source twice


def test_a_map_is_selected_by_name_and_pairs_still_work():
    options = LabelOptions(keypoint_map=('coco17', 'left_eye=head'))
    mapping = dict(options.keypoint_map)
    assert mapping['left_shoulder'] == 'l_shoulder' and mapping['RAnkle'] == 'r_ankle'
    assert mapping['left_eye'] == 'head'
    with pytest.raises(LabelError, match=r"--keypoint-map: 'body26' is not NAME=NEW_NAME or "
                       r'a map name \(body25, body25b, coco17, halpe26\)'):
        LabelOptions(keypoint_map=('body26',))


def test_real_pose2sim_trc_names_are_covered_by_body25b(shared_data):
    from monet_ros.io.export_tables import read_trc
    trc = next((shared_data / 'pose2sim_demo_balancing').rglob('*.trc'))
    names = read_trc(trc)['keypoints']
    mapping = dict(LabelOptions(keypoint_map=('body25b',)).keypoint_map)
    assert {mapping[n] for n in names if n in mapping} == HUMAN14
