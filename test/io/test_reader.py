"""open_bag on written bags: round trip of every typed helper, bare .mcap, compression,
ordering, and the named errors/reports for bad input."""
from helpers.io_bags import make_camera, smooth_images, write_rig_bag
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from monet_ros.io import (
    BagError,
    BagWriter,
    any_image_to_numpy,
    camera_from_camera_info,
    cloud_to_keypoints3d,
    image_msg_to_heatmaps,
    open_bag,
)

T0 = 2_000_000_000


def test_round_trip_every_helper(tmp_path):
    rng = np.random.default_rng(1)
    cam = make_camera('cam0', size=(32, 24))
    rgb = smooth_images(rng, 3, 24, 32)
    heat = rng.random((3, 4, 5, 6), dtype=np.float32)
    X = rng.normal(size=(3, 4, 3))
    with BagWriter(tmp_path / 'b', compression='lz4') as bag:
        bag.write_tf_static(T0, [cam])
        for k in range(3):
            s = T0 + k * 1000
            bag.write_image('/cam0/image_raw', s, rgb[k], 'cam0_optical')
            bag.write_image('/cam0/mono', s, rgb[k][:, :, 1], 'cam0_optical', encoding='mono8')
            bag.write_compressed_image('/cam0/png', s, rgb[k], 'cam0_optical', fmt='png')
            bag.write_camera_info('/cam0/camera_info', s, cam, 'cam0_optical')
            bag.write_heatmaps('/monet/cam0/heatmaps', s, heat[k], 'cam0_heat')
            bag.write_keypoints3d('/monet/keypoints3d', s, 'world', X[k],
                                  reprojection_error=np.arange(4.0), units='m')
            bag.write_skeleton_markers('/monet/skeleton', s, 'world', X[k], [[0, 1], [2, 3]],
                                       units='m')
    reader = open_bag(tmp_path / 'b')
    got = {}
    for m in reader.messages():
        got.setdefault(m.topic, []).append(m)
    assert {t: len(v) for t, v in got.items()} == {
        '/tf_static': 1, '/cam0/image_raw': 3, '/cam0/mono': 3, '/cam0/png': 3,
        '/cam0/camera_info': 3, '/monet/cam0/heatmaps': 3, '/monet/keypoints3d': 3,
        '/monet/skeleton': 3}
    assert {t: i.count for t, i in reader.topics.items()} == {t: len(v) for t, v in got.items()}
    for k in range(3):
        assert got['/cam0/image_raw'][k].stamp_ns == T0 + k * 1000
        np.testing.assert_array_equal(any_image_to_numpy(got['/cam0/image_raw'][k].msg), rgb[k])
        np.testing.assert_array_equal(any_image_to_numpy(got['/cam0/mono'][k].msg),
                                      rgb[k][:, :, 1])
        np.testing.assert_array_equal(any_image_to_numpy(got['/cam0/png'][k].msg), rgb[k])
        np.testing.assert_array_equal(image_msg_to_heatmaps(got['/monet/cam0/heatmaps'][k].msg),
                                      heat[k])
        cloud = cloud_to_keypoints3d(got['/monet/keypoints3d'][k].msg, units='m')
        np.testing.assert_allclose(cloud['X'], X[k].astype(np.float32))
        np.testing.assert_array_equal(cloud['reprojection_error'], np.arange(4.0))
        markers = got['/monet/skeleton'][k].msg.markers
        assert [len(mk.points) for mk in markers] == [4, 4]
    info = camera_from_camera_info(got['/cam0/camera_info'][0].msg, 'cam0')
    np.testing.assert_array_equal(info.K, cam.K)
    assert got['/tf_static'][0].msg.transforms[0].child_frame_id == 'cam0_optical'
    assert reader.report.ok and reader.report.total_messages == 22
    # the bare .mcap file reads the same
    bare = open_bag(tmp_path / 'b' / 'b_0.mcap')
    assert sum(1 for _ in bare.messages()) == 22 and bare.metadata is None
    # recorded QoS: /tf_static latched, the rest volatile (from metadata.yaml and from the
    # MCAP channel metadata alike)
    for r in (reader, bare):
        assert [t for t, i in r.topics.items() if i.transient_local] == ['/tf_static']


def test_log_time_order_across_chunks_and_topic_filter(tmp_path):
    """Messages written out of log-time order across small chunks come out sorted; a topic
    filter skips chunks without that topic via the chunk index."""
    rng = np.random.default_rng(2)
    times = rng.permutation(200) * 1000 + T0
    with BagWriter(tmp_path / 'b', chunk_size=2048) as bag:
        for i, t in enumerate(times):
            topic = '/a' if i < 100 else '/b'
            bag.write(topic, 'std_msgs/msg/String',
                      bag.message('std_msgs/msg/String', data=f'{i}'), int(t))
    reader = open_bag(tmp_path / 'b')
    got = [m.log_time_ns for m in reader.messages()]
    assert got == sorted(times.tolist())
    only_b = [int(m.msg.data) for m in reader.messages(topics='/b')]
    assert sorted(only_b) == list(range(100, 200))
    assert reader.report.ok
    # with a tiny buffer bound the order is given up (counted), no message is lost
    small = open_bag(tmp_path / 'b', max_buffer_bytes=100)
    got = [m.log_time_ns for m in small.messages()]
    assert sorted(got) == sorted(times.tolist())
    assert small.report.out_of_order > 0 and 'out of log-time order' in small.report.summary()


def test_path_errors_are_named(tmp_path):
    with pytest.raises(BagError, match='does not exist'):
        open_bag(tmp_path / 'nope')
    (tmp_path / 'empty.mcap').write_bytes(b'')
    with pytest.raises(BagError, match='empty.mcap is empty'):
        open_bag(tmp_path / 'empty.mcap')
    (tmp_path / 'folder').mkdir()
    with pytest.raises(BagError, match='no readable .mcap'):
        open_bag(tmp_path / 'folder')


def _first_chunk(mcap):
    """(offset, length) of the file's first chunk, from the mcap library's summary."""
    import io

    from mcap.reader import make_reader
    summary = make_reader(io.BytesIO(mcap.read_bytes())).get_summary()
    first = min(summary.chunk_indexes, key=lambda ci: ci.chunk_start_offset)
    return first.chunk_start_offset, first.chunk_length


def test_a_file_with_nothing_to_read_is_named_at_open(tmp_path):
    """Random bytes or a text file named .mcap, and a real MCAP cut inside its first chunk,
    opened as bags without topics: every command then said 'no image topic for camera
    cam0' or 'no CameraInfo topic'. Opening one now says, on one line, that it is not an
    MCAP file or not a complete one (its size and the reader's finding)."""
    noise = tmp_path / 'noise.mcap'
    noise.write_bytes(np.random.default_rng(0).integers(0, 256, 100_000, np.uint8).tobytes())
    text = tmp_path / 'notes.mcap'
    text.write_text('# a README renamed\n' * 200)
    for path in (noise, text):
        with pytest.raises(BagError) as error:
            open_bag(path)
        assert str(error.value) == (
            f'{path} is not an MCAP file (it does not start with the MCAP magic and no '
            'message in it can be read): give a rosbag2 folder, a .mcap file or a `monet '
            'synth` folder')
    cams = [make_camera(f'cam{i}', seed=i) for i in range(2)]
    write_rig_bag(tmp_path / 'b', cams, T0, 4)             # one chunk of 4 MiB at most
    mcap = next((tmp_path / 'b').glob('*.mcap'))
    start, length = _first_chunk(mcap)
    cut = start + length // 2
    mcap.write_bytes(mcap.read_bytes()[:cut])
    for path in (tmp_path / 'b', mcap):           # the rosbag2 folder (metadata.yaml), the file
        with pytest.raises(BagError) as error:
            open_bag(path)
        line = str(error.value)
        assert '\n' not in line
        assert line.startswith(
            f'{mcap} is not a complete MCAP file: no message can be read from its {cut} '
            f'bytes (record at byte {start} (opcode 0x06, length {length - 9}) runs past the '
            'end of the file (truncated?)'), line


def test_a_split_bag_with_nothing_to_read_is_named_at_open(tmp_path):
    folder = tmp_path / 'split'
    folder.mkdir()
    for k in range(2):
        (folder / f'split_{k}.mcap').write_bytes(b'\x89MCAP0\r\n' + bytes(100))
    with pytest.raises(BagError) as error:
        open_bag(folder)
    line = str(error.value)
    assert line.startswith(f'bag {folder}: no message can be read from any of its 2 .mcap '
                           f'files; {folder / "split_0.mcap"} is not a complete MCAP file'), line


def test_a_cut_file_that_still_holds_messages_is_read_and_reported(tmp_path):
    """Cut after its first chunks: not an error at open; what is whole is read, the rest
    counted in the report (unchanged)."""
    cams = [make_camera(f'cam{i}', seed=i) for i in range(2)]
    write_rig_bag(tmp_path / 'b', cams, T0, 6, chunk_size=4000)
    mcap = next((tmp_path / 'b').glob('*.mcap'))
    start, length = _first_chunk(mcap)
    mcap.write_bytes(mcap.read_bytes()[:start + length + 20])
    reader = open_bag(tmp_path / 'b')
    assert len(list(reader.messages(decode=False))) >= 1
    assert not reader.report.ok and 'truncated' in reader.report.summary()


def test_a_synth_folder_opens_as_its_recording(tmp_path):
    """A `monet synth` output folder (recording/ beside rig.yaml, labels.csv) is a bag for
    every command, as for `monet train` (learning.find_recording_parts): one rule."""
    from monet_ros.learning.recording import find_recording_parts

    cams = [make_camera(f'cam{i}', seed=i) for i in range(2)]
    write_rig_bag(tmp_path / 'synth' / 'recording', cams, T0, 3)
    (tmp_path / 'synth' / 'labels.csv').write_text('')
    reader = open_bag(tmp_path / 'synth')
    assert reader.path == tmp_path / 'synth' / 'recording'
    direct = open_bag(tmp_path / 'synth' / 'recording')
    assert [(m.topic, m.log_time_ns) for m in reader.messages(decode=False)] == \
        [(m.topic, m.log_time_ns) for m in direct.messages(decode=False)]
    parts = find_recording_parts(tmp_path / 'synth')
    assert parts['bag'] == reader.path and parts['labels'] == tmp_path / 'synth' / 'labels.csv'


def test_damaged_metadata_and_missing_files_are_reported(tmp_path):
    with BagWriter(tmp_path / 'b') as bag:
        bag.write('/a', 'std_msgs/msg/String', bag.message('std_msgs/msg/String', data='x'), 1)
    (tmp_path / 'b' / 'metadata.yaml').write_text('rosbag2_bagfile_information: [oops')
    reader = open_bag(tmp_path / 'b')
    assert [m.msg.data for m in reader.messages()] == ['x']
    assert 'metadata.yaml unusable' in reader.report.summary()
    # a split file listed in metadata but gone
    with BagWriter(tmp_path / 'c') as bag:
        bag.write('/a', 'std_msgs/msg/String', bag.message('std_msgs/msg/String', data='y'), 1)
    meta = (tmp_path / 'c' / 'metadata.yaml').read_text()
    (tmp_path / 'c' / 'metadata.yaml').write_text(
        meta.replace('- c_0.mcap', '- c_0.mcap\n  - c_1.mcap', 1))
    reader = open_bag(tmp_path / 'c')
    assert [m.msg.data for m in reader.messages()] == ['y']
    assert any('c_1.mcap' in e and 'missing' in e for e in reader.report.errors)


def write_odd_mcap(path):
    """A bare MCAP with a json channel, an unparseable ros2msg schema, a missing-type-free
    ros2idl schema, and an Image channel where one message is cut short."""
    store = get_typestore(Stores.ROS2_JAZZY)
    img_def, _ = store.generate_msgdef('sensor_msgs/msg/Image', ros_version=2)
    Image = store.types['sensor_msgs/msg/Image']
    Header = store.types['std_msgs/msg/Header']
    Time = store.types['builtin_interfaces/msg/Time']
    good = bytes(store.serialize_cdr(Image(header=Header(stamp=Time(sec=1, nanosec=0),
                                                         frame_id='c'),
                                           height=2, width=2, encoding='mono8', is_bigendian=0,
                                           step=2, data=np.arange(4, dtype=np.uint8)),
                                     'sensor_msgs/msg/Image'))
    with open(path, 'wb') as f:
        w = McapWriter(f, compression=CompressionType.ZSTD)
        w.start(profile='ros2')
        s_json = w.register_schema('Thing', 'jsonschema', b'{}')
        s_bad = w.register_schema('pkg/msg/Bad', 'ros2msg', b'this is not a field list !!')
        s_idl = w.register_schema('pkg/msg/Idl', 'ros2idl', b'module pkg {};')
        s_img = w.register_schema('sensor_msgs/msg/Image', 'ros2msg', img_def.encode())
        c_json = w.register_channel('/json', 'json', s_json)
        c_bad = w.register_channel('/bad', 'cdr', s_bad)
        c_idl = w.register_channel('/idl', 'cdr', s_idl)
        c_img = w.register_channel('/img', 'cdr', s_img)
        for k in range(3):
            w.add_message(c_json, 10 + k, b'{"a": 1}', 10 + k)
            w.add_message(c_bad, 10 + k, b'\x00\x01\x00\x00abcd', 10 + k)
            w.add_message(c_idl, 10 + k, b'\x00\x01\x00\x00abcd', 10 + k)
            w.add_message(c_img, 10 + k, good if k != 1 else good[:20], 10 + k)
        w.finish()


def test_unknown_schemas_encodings_and_bad_messages_are_reported(tmp_path):
    write_odd_mcap(tmp_path / 'odd.mcap')
    reader = open_bag(tmp_path / 'odd.mcap')
    msgs = list(reader.messages())
    assert [m.topic for m in msgs] == ['/img', '/img']
    np.testing.assert_array_equal(any_image_to_numpy(msgs[0].msg), [[0, 1], [2, 3]])
    rep = reader.report
    assert dict(rep.skipped) == {'/json': 3, '/bad': 3, '/idl': 3, '/img': 1}
    assert 'not cdr' in rep.skip_reasons['/json']
    assert 'does not parse' in rep.skip_reasons['/bad']
    assert 'ros2idl' in rep.skip_reasons['/idl']
    assert 'decode failed' in rep.skip_reasons['/img']
    assert set(rep.undecodable_topics) == {'/json', '/bad', '/idl'}
    # raw mode gives all 12 records
    assert len(list(reader.messages(decode=False))) == 12
    # a missing topic is reported, the others still come
    got = list(reader.messages(topics=['/img', '/nothere']))
    assert len(got) == 2 and reader.report.missing_topics == ['/nothere']


def test_a_recording_cut_short_without_metadata_lists_its_topics(tmp_path):
    """rosbag2 writes metadata.yaml and the MCAP footer (summary) when a recording ends: a
    recorder killed or a power cut leaves neither. Its messages are readable from the
    start, but the topic listing came from those two only, so the recording read as having
    no topics ('no CameraInfo topic'); the topics now come from the channel records."""
    from monet_ros.io import rig_from_bag

    cams = [make_camera(f'cam{i}', seed=i) for i in range(2)]
    write_rig_bag(tmp_path / 'b', cams, T0, 4, chunk_size=4000)
    whole = open_bag(tmp_path / 'b')
    want = {t: (info.msgtype, info.count) for t, info in whole.topics.items()}
    total = len(list(whole.messages(decode=False)))
    (tmp_path / 'b' / 'metadata.yaml').unlink()
    mcap = next((tmp_path / 'b').glob('*.mcap'))
    mcap.write_bytes(mcap.read_bytes()[:-100])          # the footer and the summary's end
    for path in (tmp_path / 'b', mcap):                 # the folder, and the bare file
        reader = open_bag(path)
        assert {t: info.msgtype for t, info in reader.topics.items()} == \
            {t: msgtype for t, (msgtype, _) in want.items()}
        assert all(info.count is None for info in reader.topics.values())   # not known
        assert len(list(reader.messages(decode=False))) == total
        assert not reader.report.ok and 'no usable summary' in reader.report.summary()
        assert [c.name for c in rig_from_bag(path)] == ['cam0', 'cam1']
