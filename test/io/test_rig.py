"""rig_from_bag on written bags: direct world -> camera frames, chained TF, missing TF."""
from helpers.io_bags import make_camera, write_rig_bag
from helpers.mcap_layout import opcode_offsets
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from monet_ros.io import BagError, BagWriter, RigFromBagError, open_bag, rig_from_bag

T0 = 5_000_000_000


def assert_same_camera(got, cam):
    np.testing.assert_array_equal(got.K, cam.K)
    np.testing.assert_array_equal(got.dist, cam.dist)
    np.testing.assert_allclose(got.R, cam.R, atol=1e-12)
    np.testing.assert_allclose(got.t, cam.t, atol=1e-12)
    assert (got.width, got.height) == (cam.width, cam.height)


def test_rig_round_trip_with_images(tmp_path):
    cams = [make_camera(f'cam{i}', seed=i) for i in range(3)]
    write_rig_bag(tmp_path / 'b', cams, T0, 2)
    rig = rig_from_bag(tmp_path / 'b')
    assert [c.name for c in rig] == ['cam0', 'cam1', 'cam2']
    assert [c.topic for c in rig] == ['/cam0/image_raw', '/cam1/image_raw', '/cam2/image_raw']
    for got, cam in zip(rig, cams):
        assert_same_camera(got, cam)
    # same from an open reader, and projection agrees
    X = np.random.default_rng(0).normal(size=(10, 3))
    rig2 = rig_from_bag(open_bag(tmp_path / 'b'))
    for got, cam in zip(rig2, cams):
        np.testing.assert_allclose(got.project(X), cam.project(X), atol=1e-8)


def test_rig_from_chained_transforms(tmp_path):
    """world -> rig_base -> camK_optical: the camera pose is the composition."""
    cams = [make_camera(f'cam{i}', seed=10 + i) for i in range(2)]
    R_base = Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix()
    t_base = np.array([1.0, 2.0, 0.5])
    with BagWriter(tmp_path / 'b') as bag:
        T = bag._store.types

        def tf(parent, child, R, t):
            q = Rotation.from_matrix(R).as_quat()
            return T['geometry_msgs/msg/TransformStamped'](
                header=bag._header(T0, parent), child_frame_id=child,
                transform=T['geometry_msgs/msg/Transform'](
                    translation=T['geometry_msgs/msg/Vector3'](x=t[0], y=t[1], z=t[2]),
                    rotation=T['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2],
                                                               w=q[3])))
        transforms = [tf('world', 'rig_base', R_base, t_base)]
        for cam in cams:
            # pose of the camera in rig_base so that the composed pose is cam's pose
            Rwc, cw = cam.R.T, cam.center
            transforms.append(tf('rig_base', f'{cam.name}_optical', R_base.T @ Rwc,
                                 R_base.T @ (cw - t_base)))
        bag.write('/tf_static', 'tf2_msgs/msg/TFMessage',
                  bag.message('tf2_msgs/msg/TFMessage', transforms=transforms), T0)
        for cam in cams:
            bag.write_camera_info(f'/{cam.name}/camera_info', T0, cam, f'{cam.name}_optical')
    rig = rig_from_bag(tmp_path / 'b')
    for got, cam in zip(rig, cams):
        assert_same_camera(got, cam)
    with pytest.raises(RigFromBagError, match="does not chain to 'map'"):
        rig_from_bag(tmp_path / 'b', world_frame='map')


def test_rig_errors_name_the_problem(tmp_path):
    cam = make_camera('cam0')
    with BagWriter(tmp_path / 'notf') as bag:
        bag.write_camera_info('/cam0/camera_info', T0, cam, 'cam0_optical')
    with pytest.raises(RigFromBagError, match='camera cam0.*no transform'):
        rig_from_bag(tmp_path / 'notf')
    with BagWriter(tmp_path / 'noinfo') as bag:
        bag.write_tf_static(T0, [cam])
    with pytest.raises(RigFromBagError, match='no CameraInfo topic'):
        rig_from_bag(tmp_path / 'noinfo')


def test_rig_file_overrides_the_bag(tmp_path):
    """With a rig file the cameras come from monet_ros.geometry.load_rig, not the bag."""
    from monet_ros.geometry import save_rig
    cams = [make_camera(f'cam{i}', seed=20 + i) for i in range(2)]
    with BagWriter(tmp_path / 'b') as bag:
        bag.write_camera_info('/cam0/camera_info', T0, make_camera('cam0', seed=99),
                              'cam0_optical')
    save_rig(tmp_path / 'rig.yaml', cams)
    rig = rig_from_bag(tmp_path / 'b', rig_file=tmp_path / 'rig.yaml')
    assert [c.name for c in rig] == ['cam0', 'cam1']
    for got, cam in zip(rig, cams):
        assert_same_camera(got, cam)


def test_a_truncated_bag_is_named_as_truncated(tmp_path):
    """A recording cut short (a crashed recorder, a partial copy) whose one chunk runs past
    the end of the file was refused as 'no readable CameraInfo message' only, as if the
    topics were empty: nothing in it can be read, so opening it now says so, with the
    reader's own finding (truncated)."""
    cams = [make_camera(f'cam{i}', seed=i) for i in range(2)]
    write_rig_bag(tmp_path / 'b', cams, T0, 3)
    mcap = next((tmp_path / 'b').glob('*.mcap'))
    data = mcap.read_bytes()
    mcap.write_bytes(data[:len(data) // 2])
    with pytest.raises(BagError) as error:
        rig_from_bag(tmp_path / 'b')
    line = str(error.value)
    assert '\n' not in line
    assert line.startswith(f'{mcap} is not a complete MCAP file: no message can be read from '
                           f'its {len(data) // 2} bytes (record at byte ')
    assert 'runs past the end of the file (truncated?)' in line


def test_a_damaged_tf_static_is_named_not_only_missing(tmp_path):
    """../shared/cases' bag_message_opcode_flip kind: one flipped bit in the /tf_static
    message's record header; the reader skips and counts it, and the rig's error said only
    'no transform in /tf_static; pass a rig file': it now carries the reader's finding."""
    cams = [make_camera(f'cam{i}', seed=i) for i in range(2)]
    folder = tmp_path / 'b'
    with BagWriter(folder, compression='none', chunk_size=1500) as bag:
        bag.write_tf_static(T0, cams)
        for k in range(3):
            for cam in cams:
                bag.write_camera_info(f'/{cam.name}/camera_info', T0 + k, cam,
                                      f'{cam.name}_optical')
    mcap = next(folder.glob('*.mcap'))
    data = mcap.read_bytes()
    for offset in opcode_offsets(data):          # the message record that holds /tf_static
        if data[offset] != 0x05:
            continue
        damaged = bytearray(data)
        damaged[offset] ^= 0x10
        mcap.write_bytes(bytes(damaged))
        if '/tf_static' not in {m.topic for m in open_bag(folder).messages(decode=False)}:
            break
    else:
        raise AssertionError('no message record of /tf_static found')
    reader = open_bag(folder)
    with pytest.raises(RigFromBagError) as error:
        rig_from_bag(reader)
    line = str(error.value)
    assert '\n' not in line and 'has no transform' in line
    assert 'opcode 0x15' in line and reader.report.errors[0] in line
