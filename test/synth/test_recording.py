"""A small synthetic recording read back with independent readers (mcap + mcap_ros2,
cv2.projectPoints, scipy): labels = projected ground truth, images, rig, tf_static,
determinism, labelled fraction."""
import cv2
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from monet_ros.geometry import load_rig
from monet_ros.labels import read_labels
from monet_ros.skeleton import load_skeleton
from monet_ros.synth.recording import SynthConfig, SynthError, labelled_indices, synthesize
from monet_ros.synth.rig import make_rig

SMALL = dict(cameras=4, frames=10, width=160, height=120, label_fraction=0.2, seed=11)


def read_messages(bag_dir):
    """[(topic, log_time, data bytes, decoded)] of the bag's MCAP file, CRCs checked."""
    (path,) = sorted(bag_dir.glob('*.mcap'))
    out = []
    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            out.append((channel.topic, message.log_time, bytes(message.data), decoded))
    return out


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp('synth') / 'rec'
    config = SynthConfig(**SMALL)
    result = synthesize(config, out, progress=False)
    return config, result, out, read_messages(out / 'recording')


def test_topics_and_images(recording):
    config, result, out, messages = recording
    counts = {}
    for topic, *_ in messages:
        counts[topic] = counts.get(topic, 0) + 1
    expected = {'/tf_static': 1, '/ground_truth/keypoints3d': 10}
    for k in range(4):
        expected.update({f'/cam{k}/image_raw': 10, f'/cam{k}/camera_info': 10})
    assert counts == expected
    gt = np.load(out / 'ground_truth.npz')
    images = [(t, m) for t, _, _, m in messages if t.endswith('image_raw')]
    for topic, msg in images:
        assert (msg.height, msg.width, msg.encoding, msg.step) == (120, 160, 'rgb8', 480)
        assert msg.header.frame_id == topic.split('/')[1] + '_optical'
        image = np.frombuffer(bytes(msg.data), np.uint8).reshape(120, 160, 3)
        assert image.std() > 10                      # textured, not blank
    stamps = sorted({m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                     for _, m in images})
    np.testing.assert_array_equal(stamps, gt['stamps'])
    np.testing.assert_array_equal(gt['stamps'] - gt['stamps'][0],
                                  [round(k * 1e9 / 30) for k in range(10)])
    assert (out / 'README.md').read_text().count('cam') >= 4
    assert result.labelled_instants == 2 and result.frames == 10


def test_rig_camera_info_and_tf_static(recording):
    config, _, out, messages = recording
    cams = load_rig(out / 'rig.yaml')
    expected = make_rig(config.rig, seed=config.seed)
    assert [c.name for c in cams] == ['cam0', 'cam1', 'cam2', 'cam3']
    for a, b in zip(cams, expected):
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_array_equal(a.R, b.R)
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.dist, b.dist)
    infos = {t.split('/')[1]: m for t, _, _, m in messages if t.endswith('camera_info')}
    for cam in cams:
        info = infos[cam.name]
        np.testing.assert_array_equal(np.reshape(info.k, (3, 3)), cam.K)
        np.testing.assert_array_equal(np.asarray(info.d)[:len(cam.dist)], cam.dist)
        assert (info.width, info.height) == (160, 120)
    (tf,) = [m for t, _, _, m in messages if t == '/tf_static']
    for transform in tf.transforms:
        cam = cams[int(transform.child_frame_id[3:].split('_')[0])]
        assert transform.header.frame_id == 'world'
        assert transform.child_frame_id == f'{cam.name}_optical'
        tr = transform.transform.translation
        np.testing.assert_allclose([tr.x, tr.y, tr.z], cam.center, atol=1e-12)
        q = transform.transform.rotation
        R_pose = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        np.testing.assert_allclose(R_pose, cam.R.T, atol=1e-9)


def test_labels_are_projected_ground_truth(recording):
    config, result, out, messages = recording
    cams = load_rig(out / 'rig.yaml')
    skeleton = load_skeleton('human14')
    labels = read_labels(out / 'labels.csv', skeleton)
    gt = np.load(out / 'ground_truth.npz')
    assert len(labels) == 2 and labels.num_points == result.label_rows
    assert list(gt['keypoint_names']) == list(skeleton.keypoints)
    stamps = list(gt['stamps'])
    max_error = 0.0
    for stamp in labels.stamps:
        X = gt['keypoints3d'][stamps.index(stamp)]
        assert gt['labelled'][stamps.index(stamp)]
        points = labels.points(stamp, [c.name for c in cams])
        for cam, uv in zip(cams, points):
            rvec, _ = cv2.Rodrigues(cam.R)
            ref, _ = cv2.projectPoints(X, rvec, cam.t, cam.K, cam.dist)
            ref = ref[:, 0]
            inside = np.all((ref >= -0.5) & (ref < [159.5, 119.5]), axis=1)
            # every keypoint inside the image is labelled (occluded ones too), no other
            np.testing.assert_array_equal(np.isfinite(uv[:, 0]), inside)
            assert inside.sum() >= 10
            max_error = max(max_error, np.abs(uv[inside] - ref[inside]).max())
            np.testing.assert_allclose(uv[inside], cam.project(X)[inside], atol=1e-9)
    assert max_error < 1e-6
    # the ground-truth clouds carry the same 3D points (float32)
    clouds = [m for t, _, _, m in messages if t == '/ground_truth/keypoints3d']
    for k, cloud in enumerate(clouds):
        assert cloud.point_step == 28 and cloud.width == 14 and cloud.header.frame_id == 'world'
        xyz = np.frombuffer(bytes(cloud.data), np.float32).reshape(14, 7)[:, :3]
        np.testing.assert_allclose(xyz, gt['keypoints3d'][k], atol=1e-6)
        index = np.frombuffer(bytes(cloud.data), np.uint32).reshape(14, 7)[:, 6]
        np.testing.assert_array_equal(index, np.arange(14))


def test_same_seed_same_bytes_other_seed_differs(recording, tmp_path):
    config, _, out, messages = recording
    synthesize(SynthConfig(**SMALL), tmp_path / 'again', progress=False)
    again = read_messages(tmp_path / 'again' / 'recording')
    assert [(t, s, d) for t, s, d, _ in again] == [(t, s, d) for t, s, d, _ in messages]
    assert (tmp_path / 'again' / 'labels.csv').read_bytes() == \
        (out / 'labels.csv').read_bytes()
    other = dict(SMALL, seed=12, frames=2)
    synthesize(SynthConfig(**other), tmp_path / 'other', progress=False)
    first = {t: d for t, _, d, _ in read_messages(tmp_path / 'other' / 'recording')
             if t == '/cam0/image_raw'}
    assert first['/cam0/image_raw'] != [d for t, _, d, _ in messages
                                        if t == '/cam0/image_raw'][0]


@pytest.mark.parametrize('frames, fraction, expected', [
    (100, 0.005, 1), (100, 0.0, 1), (1000, 0.005, 5), (1000, 0.009, 9), (10, 1.0, 10),
    (7, 0.5, 4)])
def test_labelled_fraction(frames, fraction, expected):
    config = SynthConfig(frames=frames, label_fraction=fraction, seed=3)
    idx = labelled_indices(config)
    assert len(idx) == expected == config.labelled_count
    assert np.all(np.diff(idx) > 0) and idx.min() >= 0 and idx.max() < frames
    if expected > 1:      # spread over the recording, not bunched
        assert np.diff(idx).min() >= frames // expected - 1


def test_refuses_to_overwrite(tmp_path):
    (tmp_path / 'full').mkdir()
    (tmp_path / 'full' / 'keep.txt').write_text('precious')
    with pytest.raises(SynthError, match='not overwriting'):
        synthesize(SynthConfig(**SMALL), tmp_path / 'full', progress=False)
    assert (tmp_path / 'full' / 'keep.txt').read_text() == 'precious'


@pytest.mark.parametrize('field, value', [
    ('cameras', 1), ('frames', 0), ('fps', 0.0), ('width', 4), ('label_fraction', 1.5),
    ('skeleton', 'no_such_skeleton'), ('layout', 'line'), ('distortion', (-0.9,)),
    ('seed', -1), ('noise', -1.0), ('hfov_deg', 179.0), ('radius', -2.0)])
def test_config_errors_name_the_field(field, value):
    with pytest.raises(SynthError, match=f"'{field}'"):
        SynthConfig(**{field: value})


def test_quadruped_dome_and_visible_only(tmp_path):
    config = SynthConfig(cameras=3, frames=3, width=96, height=64, skeleton='quadruped13',
                         layout='dome', label_fraction=1.0, label_occluded=False, seed=2)
    synthesize(config, tmp_path / 'q', progress=False)
    gt = np.load(tmp_path / 'q' / 'ground_truth.npz')
    labels = read_labels(tmp_path / 'q' / 'labels.csv', load_skeleton('quadruped13'))
    assert gt['keypoints3d'].shape == (3, 13, 3) and len(labels) == 3
    expected = gt['in_image'] & ~gt['occluded']
    assert labels.num_points == expected.sum()
    for k, stamp in enumerate(gt['stamps']):
        points = labels.points(stamp, list(gt['camera_names']))
        np.testing.assert_array_equal(np.isfinite(points[..., 0]), expected[k])


def test_project_reader_reads_it_back(recording):
    """The recording through monet_ros.io (what training uses): the rig from CameraInfo +
    /tf_static equals rig.yaml, every instant has all views, nothing is skipped."""
    from monet_ros.io import iter_multiview_frames, open_bag, rig_from_bag

    config, _, out, messages = recording
    cams = load_rig(out / 'rig.yaml')
    from_bag = rig_from_bag(out / 'recording')
    assert [c.name for c in from_bag] == [c.name for c in cams]
    for a, b in zip(from_bag, cams):
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_allclose(a.R, b.R, atol=1e-12)
        np.testing.assert_allclose(a.t, b.t, atol=1e-12)
        assert a.topic == b.topic
    reader = open_bag(out / 'recording')
    frames = list(iter_multiview_frames(reader, [c.topic for c in cams]))
    gt = np.load(out / 'ground_truth.npz')
    assert [f.stamp_ns for f in frames] == list(gt['stamps'])
    raw = {(t, m.header.stamp.sec * 10**9 + m.header.stamp.nanosec): bytes(m.data)
           for t, _, _, m in messages if t.endswith('image_raw')}
    for frame in frames:
        assert frame.missing == [] and sorted(frame.images) == [c.name for c in cams]
        for name, image in frame.images.items():
            assert image.shape == (120, 160, 3)
            assert image.tobytes() == raw[(f'/{name}/image_raw', frame.stamp_ns)]


def test_distinct_sides_recolours_only_the_left_limbs(tmp_path):
    """--distinct-sides: the same seed renders the same images except on the subject's left
    limbs, which take their own colour (the detector can tell left from right)."""
    from monet_ros.learning.recording import load_recording
    from monet_ros.synth.recording import plan

    base = dict(SMALL, frames=3, label_fraction=0.0)
    frames = {}
    for sided in (False, True):
        config = SynthConfig(**base, distinct_sides=sided)
        synthesize(config, tmp_path / str(sided), progress=False)
        frames[sided] = load_recording(tmp_path / str(sided)).frames
    p = plan(config)
    left = [i for i, c in enumerate(p['subject'].capsules) if c.a.startswith('l_')]
    assert len(left) == 6
    changed = 0
    for v, cam in enumerate(p['cameras']):
        diff = np.abs(frames[True][v].astype(int) - frames[False][v].astype(int)).max(-1)
        for t in range(3):
            ys, xs = np.nonzero(diff[t] > 0)
            changed += len(xs)
            if not len(xs):
                continue
            # every changed pixel lies on a left limb: near a projected left capsule axis
            a = cam.project(p['A'][t, left])
            b = cam.project(p['B'][t, left])
            px = np.stack([xs, ys], axis=1).astype(float)[:, None]
            ab = b - a
            s = np.clip(((px - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-9), 0, 1)
            dist = np.linalg.norm(px - (a + s[..., None] * ab), axis=-1).min(axis=1)
            assert dist.max() < 0.25 * cam.K[0, 0] / 4.0, dist.max()  # within ~0.25 m
    assert changed > 50
