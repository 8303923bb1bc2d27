"""Skeleton presets load, index and mirror consistently; bad files name file and field."""
import pytest

from monet_ros.skeleton import SkeletonError, load_skeleton


@pytest.mark.parametrize('preset, count', [('human14', 14), ('quadruped13', 13)])
def test_presets_load(preset, count):
    skeleton = load_skeleton(preset)
    assert skeleton.num_keypoints == count
    perm = skeleton.flip_permutation
    assert sorted(perm) == list(range(count))
    assert [perm[p] for p in perm] == list(range(count)), 'mirroring twice is the identity'
    for a, b in skeleton.symmetric:
        assert perm[skeleton.index(a)] == skeleton.index(b)


def test_human14_bones_connect_every_keypoint():
    skeleton = load_skeleton('human14')
    touched = {i for bone in skeleton.bone_indices for i in bone}
    assert touched == set(range(14))


def test_bad_skeleton_names_file_and_field(tmp_path):
    path = tmp_path / 'bad.yaml'
    path.write_text('keypoints: [a, b]\nbones: [[a, c]]\n')
    with pytest.raises(SkeletonError, match=r'bad\.yaml.*bones'):
        load_skeleton(path)
    path.write_text('bones: []\n')
    with pytest.raises(SkeletonError, match=r'bad\.yaml.*keypoints'):
        load_skeleton(path)
    with pytest.raises(SkeletonError, match='not found'):
        load_skeleton(tmp_path / 'missing.yaml')
