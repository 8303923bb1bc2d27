"""The fusion executable with subjects:=2 in its own process over DDS, fed the crop slots a
detector node publishes (docs/subjects.md "Live") for a `monet synth --subjects 2`
recording: heatmaps rendered from its ground truth (OpenCV projection, numpy Gaussians;
helpers.scenes), each crop showing both subjects (its own higher), the slot order shuffled
every frame, the full-frame slot for the first frames only (then empty, as a detector
tracking both sends it); discovery_tiles 0 (one whole-frame discovery slot per camera:
test_subjects_live.py has the tiles)."""
import signal
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray
from helpers.fusion_frames import fusion_statuses
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import cv2_project, gaussian_heatmaps, subject_box, to_crop
import numpy as np
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from visualization_msgs.msg import MarkerArray

from monet_ros.geometry import load_rig
from monet_ros.io import (
    camera_info_from_camera,
    cloud_to_keypoints3d,
    header_stamp_ns,
    heatmaps_to_image_msg,
)

GRID = (48, 64)          # subject crops' heatmap (w, h)
FULL = (64, 48)          # the full-frame crop's (the 160 x 120 images' aspect)
FRAMES = 60              # the subjects come within 0.6 m (centres) at frame 43
DISCOVERY = 3            # frames with a full-frame crop
TOLERANCE_M = 0.001      # per keypoint (exact Gaussians: measured 1e-7 m)


def synth(tmp_path, env):
    out = tmp_path / 'two'
    subprocess.run([sys.executable, '-m', 'monet_ros.cli', 'synth', '--out', str(out),
                    '--subjects', '2', '--frames', str(FRAMES), '--cameras', '4', '--width',
                    '160', '--height', '120', '--quiet'], check=True, env=env)
    truth = np.load(out / 'ground_truth.npz')
    return out / 'rig.yaml', load_rig(out / 'rig.yaml'), truth


def empty(stamp, name, C):
    """An empty slot: a 0 x 0 heatmap and camera_info of the instant."""
    heat = heatmaps_to_image_msg(np.zeros((C, 1, 1), np.float32), stamp, name)
    heat.width = heat.height = heat.step = 0
    heat.data = []
    return heat, CameraInfo(header=heat.header)


def crop_messages(cam, X, own, box, grid, stamp):
    """Heatmap + camera_info of a crop `box` of camera `cam` showing the subjects X (S, C, 3):
    subject `own` at peak 0.9, the others at 0.5 (None: all at 0.9)."""
    heat = np.zeros((X.shape[1], grid[1], grid[0]), np.float32)
    for s in range(len(X)):
        p = to_crop(cv2_project(cam, X[s]), box, grid)
        peak = 0.9 if own is None or s == own else 0.5
        heat = np.maximum(heat, gaussian_heatmaps(p, grid[::-1], sigma=1.5, peak=peak))
    return (heatmaps_to_image_msg(heat, stamp, cam.name),
            camera_info_from_camera(cam.crop(box, grid), stamp, cam.name))


def frame_messages(cams, X, stamp, index, rng):
    """{(camera, slot): (heatmap, camera_info)} of one instant: slots 0 and 1 the crops
    around the two subjects in a random order, slot 2 the full frame (first frames) or
    empty."""
    out = {}
    for cam in cams:
        order = rng.permutation(2)
        for slot, s in enumerate(order):
            uv = cv2_project(cam, X[s])
            box = subject_box(uv, cam.width, cam.height, GRID[0] / GRID[1])
            out[cam.name, slot] = crop_messages(cam, X, s, box, GRID, stamp)
        out[cam.name, 2] = (crop_messages(cam, X, None, (0.0, 0.0, cam.width, cam.height),
                                          FULL, stamp) if index < DISCOVERY
                            else empty(stamp, cam.name, X.shape[1]))
    return out


def crop_slot_publishers(ros, cams, qos, node):
    """{(camera, k): (heatmaps, camera_info) publishers} of the 3 crop slots of every
    camera, once the fusion node subscribes them all."""
    pubs = {(cam.name, k): (ros.publisher(f'/monet/{cam.name}/crop{k}/heatmaps', Image, qos),
                            ros.publisher(f'/monet/{cam.name}/crop{k}/camera_info',
                                          CameraInfo, qos))
            for cam in cams for k in range(3)}
    for heat_pub, info_pub in pubs.values():
        ros.wait_for_subscribers(heat_pub, process=node)
        ros.wait_for_subscribers(info_pub, process=node)
    return pubs


def test_fusion_publishes_two_subjects_with_stable_identities(ros_env, tmp_path):
    rig_path, cams, truth = synth(tmp_path, ros_env)
    X = truth['subjects_keypoints3d']                     # (T, 2, 14, 3) m
    stamps = truth['stamps']
    rng = np.random.default_rng(3)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE)
    params = dict(rig=str(rig_path), skeleton='human14', subjects=2, timeout_s=30.0,
                  input_reliability='reliable', discovery_tiles=0)
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        markers = ros.collect('/monet/skeleton', MarkerArray)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pubs = crop_slot_publishers(ros, cams, qos, node)
        got = {}
        for t in range(FRAMES):
            for key, (heat, info) in frame_messages(cams, X[t], int(stamps[t]), t,
                                                    rng).items():
                pubs[key][1].publish(info)
                pubs[key][0].publish(heat)

            def arrived(stamp=int(stamps[t])):
                got.update({header_stamp_ns(c): c for c in clouds})
                return stamp in got
            assert ros.spin_until(arrived, timeout=30, process=node), node.output()
        assert ros.spin_until(lambda: markers and 'monet fusion: subject 1' in
                              fusion_statuses(diagnostics), timeout=30,
                              process=node), node.output()
        status = fusion_statuses(diagnostics)
        # a bad slot message (3 channels, the skeleton has 14) is counted against its slot,
        # logged, and the node goes on
        bad = heatmaps_to_image_msg(np.zeros((3, 8, 8), np.float32), int(stamps[-1]) + 1,
                                    'cam0')
        pubs['cam0', 0][1].publish(camera_info_from_camera(
            cams[0].crop((0.0, 0.0, 40.0, 40.0), (8, 8)), int(stamps[-1]) + 1, 'cam0'))
        pubs['cam0', 0][0].publish(bad)

        def counted():
            slot = fusion_statuses(diagnostics).get('monet fusion: cam0/crop0')
            return slot is not None and {kv.key: kv.value for kv in slot.values}.get(
                'bad_messages') == '1'
        assert ros.spin_until(counted, timeout=30, process=node), node.output()
        assert node.running()
        assert node.stop(signal.SIGINT) == 0, node.output()

    # every frame: two subjects, 14 keypoints each, in identity order
    identity_of = {}                               # ground-truth subject -> identity
    worst = 0.0
    for t in range(FRAMES):
        k = cloud_to_keypoints3d(got[int(stamps[t])], units='m')
        assert len(k['X']) == 28, f'frame {t}: {len(k["X"])} points'
        ids = np.unique(k['subject'])
        assert len(ids) == 2
        np.testing.assert_array_equal(k['subject'], np.repeat(ids, 14))
        np.testing.assert_array_equal(k['keypoint'], np.tile(np.arange(14), 2))
        for ident in ids:
            mine = k['X'][k['subject'] == ident]
            errors = [np.linalg.norm(mine - X[t, s], axis=-1).max() for s in range(2)]
            s = int(np.argmin(errors))
            # the same identity for the same body in every frame: no switch, no new one
            assert identity_of.setdefault(s, int(ident)) == int(ident), f'frame {t}'
            worst = max(worst, errors[s])
            assert (k['num_views'][k['subject'] == ident] == 4).all()
    assert sorted(identity_of) == [0, 1] and len(set(identity_of.values())) == 2
    assert worst < TOLERANCE_M, worst
    # markers: one skeleton per subject, in its own namespace and colour
    last = markers[-1].markers
    spaces = {m.ns for m in last}
    assert spaces == {f'human14/subject{i}' for i in identity_of.values()}
    joints = {m.ns: (m.color.r, m.color.g, m.color.b) for m in last if m.id == 0}
    assert len(set(joints.values())) == 2
    summary = {kv.key: kv.value for kv in status['monet fusion'].values}
    assert summary['births'] == '2' and summary['deaths'] == '0', summary
    assert summary['subjects_tracked'] == '2'
    for ident in identity_of.values():
        values = {kv.key: kv.value for kv in status[f'monet fusion: subject {ident}'].values}
        assert values['keypoints'] == '14'
        assert float(values['mean_reprojection_error_px']) < 0.5


NOISE_M = 0.02      # per axis: the jitter of the subjects the heatmaps are rendered from


def test_fusion_filters_each_subject(ros_env, tmp_path):
    """subjects:=2 with filter:=true: the heatmaps are rendered from the ground truth plus
    20 mm of noise per joint and frame (exact Gaussians: fusion recovers the noisy points);
    every frame's keypoints3d_raw carries both subjects, the fused points, and keypoints3d
    the same subjects and fields, each identity's points being what a LiveFilter fed that
    identity's raw points alone gives (no state shared, whatever the slot order), closer to
    the noise-free ground truth than the raw ones."""
    from monet_ros.temporal.live import LiveFilter, LiveFilterConfig
    rig_path, cams, truth = synth(tmp_path, ros_env)
    X = truth['subjects_keypoints3d']                     # (T, 2, 14, 3) m
    noisy = X + np.random.default_rng(11).normal(0.0, NOISE_M, X.shape)
    stamps = truth['stamps']
    rng = np.random.default_rng(4)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE)
    params = dict(rig=str(rig_path), skeleton='human14', subjects=2, timeout_s=30.0,
                  input_reliability='reliable', filter=True, discovery_tiles=0)
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2)
        raws = ros.collect('/monet/keypoints3d_raw', PointCloud2)
        pubs = crop_slot_publishers(ros, cams, qos, node)
        got, got_raw = {}, {}
        for t in range(FRAMES):
            for key, (heat, info) in frame_messages(cams, noisy[t], int(stamps[t]), t,
                                                    rng).items():
                pubs[key][1].publish(info)
                pubs[key][0].publish(heat)

            def arrived(stamp=int(stamps[t])):
                got.update({header_stamp_ns(c): c for c in clouds})
                got_raw.update({header_stamp_ns(c): c for c in raws})
                return stamp in got and stamp in got_raw
            assert ros.spin_until(arrived, timeout=30, process=node), node.output()
        assert node.stop(signal.SIGINT) == 0, node.output()

    filters = {}                                   # identity -> LiveFilter, independent
    owner = {}                                     # identity -> ground-truth subject
    errors = {0: [[], []], 1: [[], []]}            # subject -> [raw, filtered] (m)
    for t in range(FRAMES):
        raw = cloud_to_keypoints3d(got_raw[int(stamps[t])], units='m')
        out = cloud_to_keypoints3d(got[int(stamps[t])], units='m')
        ids = np.unique(raw['subject'])
        assert len(ids) == 2 and len(raw['X']) == 28, f'frame {t}'
        for field in ('subject', 'keypoint', 'num_views'):
            np.testing.assert_array_equal(out[field], raw[field])
        np.testing.assert_array_equal(raw['subject'], np.repeat(ids, 14))
        for ident in ids.tolist():
            mine = raw['subject'] == ident
            s = owner.setdefault(ident, int(np.argmin(
                [np.linalg.norm(raw['X'][mine] - noisy[t, k], axis=-1).max()
                 for k in range(2)])))
            # raw: the fused noisy points of its own subject (no switch)
            assert np.linalg.norm(raw['X'][mine] - noisy[t, s], axis=-1).max() < 0.001
            live = filters.setdefault(ident, LiveFilter(LiveFilterConfig(filter=True), 'm'))
            expected, _ = live.update(int(stamps[t]), raw['X'][mine])
            np.testing.assert_allclose(out['X'][mine], expected, atol=1e-5)
            if t >= 5:
                errors[s][0].append(np.linalg.norm(raw['X'][mine] - X[t, s], axis=-1).mean())
                errors[s][1].append(np.linalg.norm(out['X'][mine] - X[t, s], axis=-1).mean())
    assert sorted(owner.values()) == [0, 1] and len(filters) == 2
    for s in (0, 1):
        raw_err, filt_err = np.mean(errors[s][0]), np.mean(errors[s][1])
        assert filt_err < 0.9 * raw_err, (s, filt_err, raw_err)
