"""The real bags in ../shared/data: the Pose2Sim 4-camera bag and ros2/rosbag2's test bags."""
import glob
import json

from mcap.reader import make_reader
import numpy as np
import pytest

from monet_ros.io import iter_multiview_frames, open_bag, rig_from_bag

POSE2SIM_BAG = 'derived_pose2sim_4cam_mcap/pose2sim_balancing_4cam'
TRIAL = 'pose2sim_demo_balancing/S00_P00_SingleParticipant/S00_P00_T01_BalancingTrial'
# Pose2Sim's BODY_25B skeleton: .trc marker -> OpenPose keypoint index
BODY_25B = dict(RHip=12, RKnee=14, RAnkle=16, RBigToe=22, RSmallToe=23, RHeel=24, LHip=11,
                LKnee=13, LAnkle=15, LBigToe=19, LSmallToe=20, LHeel=21, Neck=17, Head=18,
                Nose=0, RShoulder=6, RElbow=8, RWrist=10, LShoulder=5, LElbow=7, LWrist=9)


def test_pose2sim_bag_reads_completely(shared_data):
    reader = open_bag(shared_data / POSE2SIM_BAG)
    topics = reader.topics
    assert len(topics) == 9 and sum(t.count for t in topics.values()) == 801
    image_topics = reader.topics_of_type('sensor_msgs/msg/CompressedImage')
    assert image_topics == [f'/cam0{i}/image_raw/compressed' for i in range(1, 5)]
    frames = list(iter_multiview_frames(reader, image_topics))
    assert len(frames) == 100
    assert all(f.missing == [] and len(f.images) == 4 for f in frames)
    stamps = [f.stamp_ns for f in frames]
    assert stamps[0] == 1_700_000_000_000_000_000
    np.testing.assert_array_equal(np.diff(stamps), round(1e9 / 60))
    for f in frames:
        assert set(f.stamps.values()) == {f.stamp_ns}
        for cam, img in f.images.items():
            h = 960
            w = 540 if cam in ('cam01', 'cam02') else 544
            assert img.shape == (h, w, 3) and img.dtype == np.uint8
    # decoded pixels are OpenCV's decoding of the stored JPEG (independent mcap read)
    with open(next((shared_data / POSE2SIM_BAG).glob('*.mcap')), 'rb') as fh:
        from mcap_ros2.decoder import DecoderFactory
        first = next(make_reader(fh, decoder_factories=[DecoderFactory()])
                     .iter_decoded_messages('/cam03/image_raw/compressed'))
    import cv2
    ref = cv2.cvtColor(cv2.imdecode(np.frombuffer(first.decoded_message.data, np.uint8),
                                    cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    np.testing.assert_array_equal(frames[0].images['cam03'], ref)
    assert reader.report.ok and reader.report.total_messages == 400


def load_trc(path):
    lines = open(path).read().splitlines()
    names = [n for n in lines[3].split('\t')[2:] if n]
    rows = [[float(x) if x else np.nan for x in line.split('\t')[:2 + 3 * len(names)]]
            for line in lines[5:] if line.strip()]
    P = np.array(rows)[:, 2:].reshape(len(rows), len(names), 3)
    return names, np.stack([P[..., 2], P[..., 0], P[..., 1]], axis=-1)   # trc(X,Y,Z)=w(Y,Z,X)


def test_pose2sim_rig_reprojection_matches_manifest(shared_data):
    """Project the .trc with the bag's own CameraInfo + /tf_static; compare with the
    pose-associated OpenPose detections used for triangulation (likelihood > 0.3, Pose2Sim's
    threshold), mapped to the half-resolution images: medians per camera as in MANIFEST."""
    cams = rig_from_bag(shared_data / POSE2SIM_BAG)
    assert [c.name for c in cams] == ['cam01', 'cam02', 'cam03', 'cam04']
    assert [c.topic for c in cams] == [f'/cam0{i}/image_raw/compressed' for i in range(1, 5)]
    assert [(c.width, c.height) for c in cams] == [(540, 960)] * 2 + [(544, 960)] * 2
    names, W = load_trc(glob.glob(str(shared_data / TRIAL / 'pose-3d' / '*.trc'))[0])
    assert len(names) == 21 and W.shape == (100, 21, 3)
    kp_idx = np.array([BODY_25B[n] for n in names])
    medians = []
    for cam in cams:
        files = sorted(glob.glob(str(shared_data / TRIAL / 'pose-associated' /
                                     f'{cam.name}_json' / '*.json')))
        assert len(files) == 100
        errors = []
        for frame, path in enumerate(files):
            people = [p for p in json.load(open(path))['people'] if 'pose_keypoints_2d' in p]
            if not people:
                continue
            kp = np.array(people[0]['pose_keypoints_2d']).reshape(-1, 3)[kp_idx]
            det = (kp[:, :2] + 0.5) * 0.5 - 0.5          # full-res -> bag pixels
            uv = cam.project(W[frame])
            ok = (kp[:, 2] > 0.3) & np.isfinite(uv).all(axis=1)
            errors.append(np.linalg.norm(uv[ok] - det[ok], axis=1))
        medians.append(np.median(np.concatenate(errors)))
    np.testing.assert_allclose(medians, [5.69, 3.97, 8.60, 4.56], atol=0.006)


def test_rosbag2_talker_all_messages(shared_data):
    reader = open_bag(shared_data / 'rosbag2_mcap_testbags' / 'talker')
    msgs = list(reader.messages())
    assert len(msgs) == 20 and reader.report.ok
    by_topic = {}
    for m in msgs:
        by_topic.setdefault(m.topic, []).append(m)
    assert {k: len(v) for k, v in by_topic.items()} == {'/topic': 10, '/rosout': 10}
    assert [m.msg.data for m in by_topic['/topic']] == [f'Hello, world! {i}'
                                                        for i in range(10)]
    assert [m.msg.msg for m in by_topic['/rosout']] == [f"Publishing: 'Hello, world! {i}'"
                                                        for i in range(10)]
    times = [m.log_time_ns for m in msgs]
    assert times == sorted(times)
    assert reader.topics['/parameter_events'].count == 0


def test_rosbag2_split_bag_all_messages_in_order(shared_data):
    reader = open_bag(shared_data / 'rosbag2_mcap_testbags' / 'wbag')
    assert len(reader.files) == 5
    times, counts = [], {}
    for m in reader.messages():
        times.append(m.log_time_ns)
        counts[m.topic] = counts.get(m.topic, 0) + 1
        assert isinstance(m.msg.data, str)
    assert len(times) == 6074 and times == sorted(times)
    assert counts == {t: info.count for t, info in reader.topics.items()}
    assert reader.report.ok
    # a topic subset reads only that topic, same count as the metadata
    sub = list(reader.messages(topics=['AAA', 'HHH']))
    assert len(sub) == 804 + 726


def test_service_event_bag_reports_undecodable(shared_data):
    reader = open_bag(shared_data / 'rosbag2_mcap_testbags' /
                      'bag_with_topics_and_service_events')
    msgs = list(reader.messages())
    assert sorted(m.topic for m in msgs) == ['/test_topic1', '/test_topic2']
    rep = reader.report
    assert dict(rep.skipped) == {'/test_service1/_service_event': 4,
                                 '/test_service2/_service_event': 4}
    assert set(rep.undecodable_topics) == set(rep.skipped)
    assert 'BasicTypes_Event' in rep.skip_reasons['/test_service1/_service_event']
    assert not rep.ok and '/test_service2/_service_event' in rep.summary()
    # raw mode still gives every message record (8 + 2)
    assert len(list(reader.messages(decode=False))) == 10


@pytest.mark.parametrize('bag', ['talker', 'wbag'])
def test_counts_agree_with_mcap_library(shared_data, bag):
    """Same messages (topic, log time, payload) as the mcap library's own reader."""
    from mcap.reader import make_reader
    folder = shared_data / 'rosbag2_mcap_testbags' / bag
    ref = []
    for path in sorted(folder.glob('*.mcap')):
        with open(path, 'rb') as fh:
            ref += [(c.topic, m.log_time, bytes(m.data))
                    for _, c, m in make_reader(fh).iter_messages(log_time_order=True)]
    ours = [(m.topic, m.log_time_ns, bytes(m.data)) for m in open_bag(folder).messages()]
    assert sorted(ours) == sorted(ref)
