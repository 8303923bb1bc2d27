"""BagWriter output read back by independent readers (rosbags AnyReader, mcap + mcap_ros2
with CRC validation), metadata.yaml checked field by field."""
from pathlib import Path

from helpers.io_bags import make_camera
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
import yaml

from monet_ros.io import convert
from monet_ros.io.fields import extrinsics_from_pose
from monet_ros.io.writer import BagWriter, BagWriterError

T0 = 1_700_000_000_000_000_000


def write_sample_bag(path, frames=3):
    rng = np.random.default_rng(0)
    cams = [make_camera(f'cam{i}', seed=i) for i in range(2)]
    data = {'rgb': [], 'heat': [], 'X': []}
    with BagWriter(path) as bag:
        bag.write_tf_static(T0, cams)
        for k in range(frames):
            stamp = T0 + k * 33_333_333
            for cam in cams:
                rgb = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
                data['rgb'].append(rgb)
                bag.write_image(f'/{cam.name}/image_raw', stamp, rgb, f'{cam.name}_optical')
                bag.write_camera_info(f'/{cam.name}/camera_info', stamp, cam,
                                      f'{cam.name}_optical')
            heat = rng.random((5, 6, 7), dtype=np.float32)
            data['heat'].append(heat)
            bag.write_heatmaps('/monet/cam0/heatmaps', stamp, heat, 'cam0_heat')
            X = rng.normal(size=(5, 3))
            data['X'].append(X)
            bag.write_keypoints3d('/monet/keypoints3d', stamp, 'world', X,
                                  confidence=np.ones(5), num_views=np.full(5, 2), units='m')
            bag.write_compressed_image('/cam0/image_raw/compressed', stamp, data['rgb'][-2],
                                       'cam0_optical', fmt='png')
            bag.write_skeleton_markers('/monet/skeleton', stamp, 'world', X, [[0, 1], [1, 2]],
                                       units='m')
    return cams, data


def test_metadata_yaml(tmp_path):
    bag = tmp_path / 'rec'
    write_sample_bag(bag)
    assert sorted(p.name for p in bag.iterdir()) == ['metadata.yaml', 'rec_0.mcap']
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 8 and info['storage_identifier'] == 'mcap'
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in info['topics_with_message_count']}
    assert counts == {'/tf_static': 1, '/cam0/image_raw': 3, '/cam0/camera_info': 3,
                      '/cam1/image_raw': 3, '/cam1/camera_info': 3, '/monet/cam0/heatmaps': 3,
                      '/monet/keypoints3d': 3, '/cam0/image_raw/compressed': 3,
                      '/monet/skeleton': 3}
    assert info['message_count'] == 25
    assert info['starting_time']['nanoseconds_since_epoch'] == T0
    assert info['duration']['nanoseconds'] == 2 * 33_333_333
    assert info['relative_file_paths'] == ['rec_0.mcap']
    assert info['files'][0]['message_count'] == 25
    types = {t['topic_metadata']['name']: t['topic_metadata']['type']
             for t in info['topics_with_message_count']}
    assert types['/tf_static'] == 'tf2_msgs/msg/TFMessage'
    assert types['/monet/skeleton'] == 'visualization_msgs/msg/MarkerArray'
    store = get_typestore(Stores.ROS2_JAZZY)
    for t in info['topics_with_message_count']:
        md = t['topic_metadata']
        assert md['serialization_format'] == 'cdr'
        assert md['type_description_hash'] == store.hash_rihs01(md['type'])
        assert 'durability: ' + ('1' if md['name'] == '/tf_static' else '2') in \
            md['offered_qos_profiles']


def test_rosbags_anyreader_reads_everything(tmp_path):
    bag = tmp_path / 'rec'
    cams, data = write_sample_bag(bag)
    rgb_iter = iter(data['rgb'])
    heat_iter = iter(data['heat'])
    seen = {}
    with AnyReader([Path(bag)], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        last = 0
        for conn, ts, raw in reader.messages():
            assert ts >= last
            last = ts
            msg = reader.deserialize(raw, conn.msgtype)
            seen[conn.topic] = seen.get(conn.topic, 0) + 1
            if conn.topic.endswith('/image_raw'):
                np.testing.assert_array_equal(convert.image_to_numpy(msg), next(rgb_iter))
                assert convert.header_stamp_ns(msg) == ts
            elif conn.topic == '/monet/cam0/heatmaps':
                np.testing.assert_array_equal(convert.image_msg_to_heatmaps(msg),
                                              next(heat_iter))
            elif conn.topic == '/tf_static':
                assert [t.child_frame_id for t in msg.transforms] == ['cam0_optical',
                                                                     'cam1_optical']
                for cam, tf in zip(cams, msg.transforms):
                    tr, q = tf.transform.translation, tf.transform.rotation
                    R, t = extrinsics_from_pose([tr.x, tr.y, tr.z], [q.x, q.y, q.z, q.w])
                    np.testing.assert_allclose(R, cam.R, atol=1e-12)
                    np.testing.assert_allclose(t, cam.t, atol=1e-12)
    assert sum(seen.values()) == 25


def test_mcap_library_validates_crcs_and_decodes(tmp_path):
    bag = tmp_path / 'rec'
    cams, data = write_sample_bag(bag)
    with open(bag / 'rec_0.mcap', 'rb') as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert summary.statistics.message_count == 25
        clouds = [m.decoded_message for m in reader.iter_decoded_messages('/monet/keypoints3d')]
        infos = [m.decoded_message for m in reader.iter_decoded_messages('/cam1/camera_info')]
    assert len(clouds) == 3
    for X, msg in zip(data['X'], clouds):
        got = convert.cloud_to_keypoints3d(msg, units='m')
        np.testing.assert_allclose(got['X'], X.astype(np.float32))
        np.testing.assert_array_equal(got['num_views'], 2)
        assert np.isnan(got['reprojection_error']).all()
    cam = convert.camera_from_camera_info(infos[0], 'cam1', cams[1].R, cams[1].t)
    np.testing.assert_array_equal(cam.K, cams[1].K)
    np.testing.assert_array_equal(cam.dist, cams[1].dist)


def test_writer_refuses_bad_use(tmp_path):
    (tmp_path / 'full').mkdir()
    (tmp_path / 'full' / 'x').write_text('x')
    with pytest.raises(BagWriterError, match='exists already'):
        BagWriter(tmp_path / 'full')
    with BagWriter(tmp_path / 'b') as bag:
        bag.write_image('/a', 1, np.zeros((2, 2, 3), np.uint8), 'f')
        with pytest.raises(BagWriterError, match='has type sensor_msgs/msg/Image'):
            bag.write_keypoints3d('/a', 1, 'world', np.zeros((2, 3)), units='m')
        with pytest.raises(BagWriterError, match='unknown message type'):
            bag.write('/b', 'nope_msgs/msg/Nope', b'', 1)
    with pytest.raises(BagWriterError, match='closed'):
        bag.write_image('/a', 2, np.zeros((2, 2, 3), np.uint8), 'f')


def test_write_rclpy_message_and_raw_bytes(tmp_path):
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    msg = convert.numpy_to_image_msg(rgb, 5, 'f')
    with BagWriter(tmp_path / 'b', compression='zstd') as bag:
        bag.write('/img', 'sensor_msgs/msg/Image', msg, 5)
        from rclpy.serialization import serialize_message
        bag.write('/img', 'sensor_msgs/msg/Image', serialize_message(msg), 6)
    with open(tmp_path / 'b' / 'b_0.mcap', 'rb') as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        got = [convert.image_to_numpy(m.decoded_message) for m in reader.iter_decoded_messages()]
    assert len(got) == 2
    for g in got:
        np.testing.assert_array_equal(g, rgb)
