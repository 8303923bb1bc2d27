"""Multiview grouping on bags written with known stamps, drops, jitter and latencies."""
from helpers.io_bags import smooth_images
import numpy as np

from monet_ros.io import BagWriter, iter_multiview_frames, open_bag

T0 = 1_000_000_000_000
DT = 33_333_333
LATENCY = {'cam0': 0, 'cam1': 50_000_000, 'cam2': 5_000_000}     # log time = stamp + latency
JITTER = {'cam0': 0, 'cam1': 0, 'cam2': 2_000_000}               # header stamp offset


def write_rig_bag(path, frames=10, drop=(('cam1', 3), ('cam2', 7)), jitter=JITTER):
    rng = np.random.default_rng(0)
    images = {}
    with BagWriter(path) as bag:
        for k in range(frames):
            for cam in ('cam0', 'cam1', 'cam2'):
                if (cam, k) in drop:
                    continue
                img = smooth_images(rng, 1, 12, 16)[0]
                images[cam, k] = img
                stamp = T0 + k * DT + jitter[cam]
                bag.write_image(f'/{cam}/image_raw', stamp, img, f'{cam}_optical',
                                log_time_ns=stamp + LATENCY[cam])
    return images


def test_grouping_with_slop_drops_and_latency(tmp_path):
    images = write_rig_bag(tmp_path / 'b')
    reader = open_bag(tmp_path / 'b')
    topics = ['/cam0/image_raw', '/cam1/image_raw', '/cam2/image_raw']
    frames = list(iter_multiview_frames(reader, topics, slop_ns=5_000_000))
    assert [f.stamp_ns for f in frames] == [T0 + k * DT for k in range(10)]
    for k, f in enumerate(frames):
        expected_missing = {3: ['cam1'], 7: ['cam2']}.get(k, [])
        assert f.missing == expected_missing
        for cam, img in f.images.items():
            np.testing.assert_array_equal(img, images[cam, k])
            assert f.stamps[cam] == T0 + k * DT + JITTER[cam]


def test_exact_matching_splits_jittered_views(tmp_path):
    write_rig_bag(tmp_path / 'b', drop=())
    reader = open_bag(tmp_path / 'b')
    frames = list(iter_multiview_frames(reader, ['/cam0/image_raw', '/cam2/image_raw']))
    # cam2's stamps are 2 ms off: with slop 0 every instant is two half-frames
    assert len(frames) == 20
    assert [f.missing for f in frames[:2]] == [['cam2'], ['cam0']]
    assert frames[1].stamp_ns - frames[0].stamp_ns == 2_000_000


def test_absent_topic_is_reported_and_frames_still_come(tmp_path):
    write_rig_bag(tmp_path / 'b', frames=4, drop=())
    reader = open_bag(tmp_path / 'b')
    frames = list(iter_multiview_frames(reader, {'cam0': '/cam0/image_raw',
                                                 'camX': '/camX/image_raw'}))
    assert len(frames) == 4 and all(f.missing == ['camX'] for f in frames)
    assert reader.report.missing_topics == ['/camX/image_raw']


def test_pending_frames_are_bounded(tmp_path):
    """cam1 is silent for a long stretch: frames are released once max_pending is
    exceeded, never held without bound, and all instants still come out in order."""
    drops = tuple(('cam1', k) for k in range(2, 40))
    write_rig_bag(tmp_path / 'b', frames=45, drop=drops)
    reader = open_bag(tmp_path / 'b')
    seen_pending = []
    gen = iter_multiview_frames(reader, ['/cam0/image_raw', '/cam1/image_raw'],
                                max_pending=5)
    frames = []
    for f in gen:
        frames.append(f)
        seen_pending.append(len(gen.gi_frame.f_locals['sync'].pending) if gen.gi_frame else 0)
    assert [f.stamp_ns for f in frames] == [T0 + k * DT for k in range(45)]
    assert [k for k, f in enumerate(frames) if f.missing] == list(range(2, 40))
    assert max(seen_pending) <= 5


def test_decode_false_gives_messages(tmp_path):
    write_rig_bag(tmp_path / 'b', frames=2, drop=())
    frames = list(iter_multiview_frames(open_bag(tmp_path / 'b'), ['/cam0/image_raw'],
                                        decode=False))
    assert len(frames) == 2 and frames[0].images['cam0'].msg.encoding == 'rgb8'
