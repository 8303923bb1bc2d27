"""The detector executable with subjects:=2 in its own process over DDS: the crop slots
<cam>/crop<k>/heatmaps + camera_info (docs/subjects.md "Live"): a crop per subject of the
latest /monet/keypoints3d (its `subject` field), the full frame while fewer than 2 are
tracked (discovery_tiles 0: the tiles that are the default are test_subjects_live.py's),
empty slots elsewhere, every crop's heatmaps those of the network on that crop."""
import signal

from helpers.detector_crops import INPUT, expected_box, expected_K, make_checkpoint
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from monet_ros.crop_rule import subject_boxes
from monet_ros.geometry import save_rig
from monet_ros.io import (
    camera_info_from_camera,
    header_stamp_ns,
    image_msg_to_heatmaps,
    keypoints3d_to_cloud,
    numpy_to_image_msg,
)
from monet_ros.models import Detector, load_checkpoint

T0 = 1_650_000_000_000_000_000
SLOTS = 3          # subjects 2: crop0, crop1 (subjects), crop2 (full frame)


def detector_boxes(checkpoint, rig, boxes):
    model, metadata = load_checkpoint(checkpoint)
    return Detector(model, metadata, device='cpu').boxes_for(rig, boxes)


def reference(checkpoint, images, cameras, boxes):
    model, metadata = load_checkpoint(checkpoint)
    return Detector(model, metadata, device='cpu', precision='auto').predict(
        list(images), cameras, boxes, keep_aspect=False)[0]


class SlotStream:
    """Publishes images + camera_info of the rig and collects every crop slot."""

    def __init__(self, ros, rig):
        self.ros, self.rig = ros, rig
        self.pubs = {c.name: (ros.publisher(f'/{c.name}/image_raw', Image),
                              ros.publisher(f'/{c.name}/camera_info', CameraInfo))
                     for c in rig}
        self.heat = {(c.name, k): ros.collect(f'/monet/{c.name}/crop{k}/heatmaps', Image, 100)
                     for c in rig for k in range(SLOTS)}
        self.info = {(c.name, k): ros.collect(f'/monet/{c.name}/crop{k}/camera_info',
                                              CameraInfo, 100)
                     for c in rig for k in range(SLOTS)}
        self.one = ros.collect('/monet/cam0/heatmaps', Image, 100)

    def result(self, key, stamp):
        heat = [m for m in self.heat[key] if header_stamp_ns(m) == stamp]
        info = [m for m in self.info[key] if header_stamp_ns(m) == stamp]
        return (heat[-1], info[-1]) if heat and info else None

    def roundtrip(self, stamp, images, node, cloud=None, cloud_pub=None, tries=30):
        for _ in range(tries):
            if cloud is not None:
                cloud_pub.publish(cloud)
            for cam, image in zip(self.rig, images):
                self.pubs[cam.name][1].publish(camera_info_from_camera(cam, stamp, cam.name))
                self.pubs[cam.name][0].publish(numpy_to_image_msg(image, stamp, cam.name))
            if self.ros.spin_until(lambda: all(self.result(k, stamp) for k in self.heat),
                                   timeout=1.5, process=node):
                return {k: self.result(k, stamp) for k in self.heat}
        raise AssertionError(f'no crop slots for stamp {stamp}\n{node.output()}')


def crop_K(info):
    return np.reshape(info.k, (3, 3))


def test_one_crop_per_subject_and_the_full_frame_while_fewer(ros_env, tmp_path):
    rig = ring_rig(2)
    rig_path = tmp_path / 'rig.yaml'
    save_rig(rig_path, rig)
    checkpoint = make_checkpoint(tmp_path / 'model.pt', 1)
    images = np.random.default_rng(0).integers(0, 255, (2, 480, 640, 3), dtype=np.uint8)
    aspect = INPUT[1] / INPUT[0]
    rng = np.random.default_rng(5)
    A = rng.uniform([-0.4, -0.4, 0.6], [-0.1, -0.1, 1.5], (14, 3))     # two bodies apart
    B = rng.uniform([0.1, 0.1, 0.6], [0.4, 0.4, 1.5], (14, 3))
    # discovery_period_s 0: the full frame in every frame while fewer (the stamps here are
    # ns apart: one window; the period is test_discovery_maps_in_the_first_frame_of_...)
    params = dict(rig=str(rig_path), model=str(checkpoint), subjects=2, device='cpu',
                  track_timeout_s=3600.0, discovery_tiles=0, discovery_period_s=0.0)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        stream = SlotStream(ros, rig)
        for image_pub, info_pub in stream.pubs.values():
            ros.wait_for_subscribers(image_pub, timeout=120, process=node)
            ros.wait_for_subscribers(info_pub, process=node)
        cloud_pub = ros.publisher('/monet/keypoints3d', PointCloud2)
        ros.wait_for_subscribers(cloud_pub, process=node)

        # 1. nothing tracked: the subject slots are empty, the full-frame slot the image
        got = stream.roundtrip(T0, images, node)
        full = expected_box((0, 0, 640, 480), aspect)
        want = reference(checkpoint, images, rig, np.array([full, full]))
        for v, cam in enumerate(rig):
            for k in (0, 1):
                heat, info = got[cam.name, k]
                assert (heat.width, heat.height, info.width, info.height) == (0, 0, 0, 0)
                assert heat.encoding == '32FC14'
            heat, info = got[cam.name, 2]
            assert (heat.width, heat.height) == (32, 24)
            np.testing.assert_allclose(crop_K(info), expected_K(cam.K, full, 32, 24),
                                       rtol=1e-12)
            np.testing.assert_allclose(image_msg_to_heatmaps(heat), want[v], atol=1e-4)

        # 2. two subjects (identities 9 and 4, sent in that order): crop0 around identity 4,
        # crop1 around 9 (by identity), no full frame
        X = np.concatenate([B, A]).astype(np.float32)
        cloud = keypoints3d_to_cloud(T0 + 1, 'world', X, units='m',
                                     keypoint=np.tile(np.arange(14), 2),
                                     subject=np.repeat([9, 4], 14))
        boxes = [detector_boxes(checkpoint, rig, subject_boxes(rig, S.astype(np.float32)))
                 for S in (A, B)]                                  # (slot, V, 4)

        def around_subjects(got):
            return all(got[c.name, k][1].width and np.allclose(
                crop_K(got[c.name, k][1]), expected_K(c.K, boxes[k][v], 32, 24), rtol=1e-9)
                for v, c in enumerate(rig) for k in (0, 1))
        for stamp in range(T0 + 100, T0 + 160):           # until the cloud is in
            got = stream.roundtrip(stamp, images, node, cloud, cloud_pub)
            if around_subjects(got):
                break
        assert around_subjects(got), node.output()
        # one batch of all crops: the network on each crop
        crops = np.array([boxes[k][v] for v in range(2) for k in (0, 1)])
        want = reference(checkpoint, [images[v] for v in range(2) for _ in (0, 1)],
                         [rig[v] for v in range(2) for _ in (0, 1)], crops)
        for v, cam in enumerate(rig):
            for k in (0, 1):
                np.testing.assert_allclose(image_msg_to_heatmaps(got[cam.name, k][0]),
                                           want[2 * v + k], atol=1e-4)
            assert got[cam.name, 2][0].width == 0 and got[cam.name, 2][1].width == 0

        # 3. one subject (identity 9): crop0 around it, crop1 empty, the full frame again
        one = keypoints3d_to_cloud(T0 + 2, 'world', B.astype(np.float32), units='m',
                                   subject=np.full(14, 9))

        def one_subject(got):
            return (got['cam0', 2][1].width > 0 and got['cam0', 1][1].width == 0
                    and np.allclose(crop_K(got['cam0', 0][1]),
                                    expected_K(rig[0].K, boxes[1][0], 32, 24), rtol=1e-9))
        for stamp in range(T0 + 200, T0 + 260):
            got = stream.roundtrip(stamp, images, node, one, cloud_pub)
            if one_subject(got):
                break
        assert one_subject(got), node.output()
        assert not stream.one, 'the one-subject topics are not published with subjects 2'
        assert node.stop(signal.SIGINT) == 0, node.output()


def test_discovery_maps_in_the_first_frame_of_each_period(ros_env, tmp_path):
    # nothing tracked, discovery_period_s 0.25, frames 0.1 s apart from a window start: the
    # discovery slot (crop2) carries the full frame in frames 0, 3, 5, 8 (at 0, 0.3, 0.5,
    # 0.8 s: the first of each 0.25 s window), its empty message in the others; the
    # subject slots are empty throughout
    rig = ring_rig(2)
    rig_path = tmp_path / 'rig.yaml'
    save_rig(rig_path, rig)
    checkpoint = make_checkpoint(tmp_path / 'model.pt', 1)
    images = np.random.default_rng(0).integers(0, 255, (2, 480, 640, 3), dtype=np.uint8)
    assert T0 % 250_000_000 == 0
    params = dict(rig=str(rig_path), model=str(checkpoint), subjects=2, device='cpu',
                  discovery_tiles=0, discovery_period_s=0.25)
    with RosHarness(ros_env) as ros, NodeProcess('detector', ros_env, params) as node:
        stream = SlotStream(ros, rig)
        for image_pub, info_pub in stream.pubs.values():
            ros.wait_for_subscribers(image_pub, timeout=120, process=node)
            ros.wait_for_subscribers(info_pub, process=node)
        sent = []
        for k in range(10):
            got = stream.roundtrip(T0 + k * 100_000_000, images, node)
            sent.append([got[cam.name, 2][0].width > 0 for cam in rig])
            for cam in rig:
                assert got[cam.name, 0][0].width == 0 and got[cam.name, 1][0].width == 0
        assert sent == [[k in (0, 3, 5, 8)] * 2 for k in range(10)], node.output()
        assert node.stop(signal.SIGINT) == 0, node.output()


def test_discovery_tiles_need_the_rig(ros_env, tmp_path):
    # the discovery slots are laid out for the rig cameras' image sizes: without a rig the
    # detector refuses to start (one line naming the parameter), with discovery_tiles 0 it
    # needs none (one whole-frame slot)
    checkpoint = make_checkpoint(tmp_path / 'model.pt', 1)
    params = dict(model=str(checkpoint), cameras=['cam0', 'cam1'], subjects=2, device='cpu')
    with NodeProcess('detector', ros_env, params) as node:
        assert node.wait(timeout=90) == 2, node.output()
        assert "parameter 'discovery_tiles': needs the rig" in node.output()
    with RosHarness(ros_env) as ros, \
            NodeProcess('detector', ros_env, {**params, 'discovery_tiles': 0}) as node:
        assert ros.spin_until(lambda: ros.node.count_publishers('/monet/cam1/crop2/heatmaps'),
                              timeout=120, process=node), node.output()
        assert node.stop(signal.SIGINT) == 0, node.output()
