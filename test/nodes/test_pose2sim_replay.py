"""Real data: the Pose2Sim 4-camera recording replayed by the player, heatmaps rendered from
its OpenPose detections (we ship no human model), fused by the fusion node, compared with
Pose2Sim's own triangulation (.trc)."""
import json

from diagnostic_msgs.msg import DiagnosticArray
from helpers.fusion_frames import fusion_statuses
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import gaussian_heatmaps, subject_box, to_crop
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
import yaml

from monet_ros.io import (
    camera_from_camera_info,
    camera_info_from_camera,
    cloud_to_keypoints3d,
    header_stamp_ns,
    heatmaps_to_image_msg,
)

CAMERAS = ('cam01', 'cam02', 'cam03', 'cam04')
T0_NS = 1_700_000_000 * 10**9
# The .trc markers (Pose2Sim's BODY_25B tree, pre-order) and their OpenPose BODY_25B index.
MARKERS = {'RHip': 12, 'RKnee': 14, 'RAnkle': 16, 'RBigToe': 22, 'RSmallToe': 23,
           'RHeel': 24, 'LHip': 11, 'LKnee': 13, 'LAnkle': 15, 'LBigToe': 19,
           'LSmallToe': 20, 'LHeel': 21, 'Neck': 17, 'Head': 18, 'Nose': 0,
           'RShoulder': 6, 'RElbow': 8, 'RWrist': 10, 'LShoulder': 5, 'LElbow': 7,
           'LWrist': 9}
BONES = [('RHip', 'RKnee'), ('RKnee', 'RAnkle'), ('LHip', 'LKnee'), ('LKnee', 'LAnkle'),
         ('Neck', 'Head'), ('RShoulder', 'RElbow'), ('RElbow', 'RWrist'),
         ('LShoulder', 'LElbow'), ('LElbow', 'LWrist')]
GRID = (48, 64)   # heatmap (w, h)
SIGMA = 1.5
LIKELIHOOD_MIN = 0.3   # Pose2Sim's likelihood_threshold_triangulation


def load_detections(trial):
    """(4, 100, 21, 3) OpenPose (u, v, likelihood) in full-resolution pixels, .trc order."""
    ids = list(MARKERS.values())
    out = np.zeros((len(CAMERAS), 100, len(ids), 3))
    for c, cam in enumerate(CAMERAS):
        for i in range(100):
            path = trial / 'pose-associated' / f'{cam}_json' / f'{cam}.{i:04d}.json'
            people = json.loads(path.read_text())['people']
            if people and 'pose_keypoints_2d' in people[0]:   # {} = nobody associated
                out[c, i] = np.reshape(people[0]['pose_keypoints_2d'], (-1, 3))[ids]
    return out


def load_trc(path):
    """(100, 21, 3) world points: trc (X, Y, Z) = world (Y, Z, X)."""
    rows = [line.split('\t') for line in path.read_text().splitlines()[5:] if line.strip()]
    data = np.array([[float(v) if v else np.nan for v in row[2:2 + 63]] for row in rows])
    trc = data.reshape(len(rows), 21, 3)
    return trc[..., [2, 0, 1]]


class OpenPoseDetector:
    """Stands in for the detector node: answers each replayed camera_info with heatmaps of
    the OpenPose detections of that frame (Gaussians whose grid maximum = likelihood)."""

    def __init__(self, ros, detections):
        self.detections = detections
        self.pubs = {}
        for c, cam in enumerate(CAMERAS):
            self.pubs[cam] = (ros.publisher(f'/monet/{cam}/heatmaps', Image, 50),
                              ros.publisher(f'/monet/{cam}/camera_info', CameraInfo, 50))
            ros.node.create_subscription(CameraInfo, f'/{cam}/camera_info',
                                         lambda m, c=c: self.on_info(c, m), 50)
        self.answered = 0

    def on_info(self, c, msg):
        stamp = header_stamp_ns(msg)
        frame = round((stamp - T0_NS) * 60 / 1e9)
        det = self.detections[c, frame]
        # The bag images are half resolution: u' = (u + 0.5) * 0.5 - 0.5.
        uv = (det[:, :2] + 0.5) * 0.5 - 0.5
        seen = det[:, 2] > 0
        uv[~seen] = np.nan
        camera = camera_from_camera_info(msg, CAMERAS[c])
        box = (subject_box(uv[seen], camera.width, camera.height, GRID[0] / GRID[1])
               if seen.any() else (0, 0, camera.width, camera.height))
        p = to_crop(uv, box, GRID)
        # Scale each Gaussian so that its grid maximum equals the likelihood.
        nearest = np.clip(np.round(p), 0, np.array(GRID) - 1)
        d2 = np.nansum((nearest - p) ** 2, axis=1)
        peak = np.where(seen, det[:, 2] * np.exp(d2 / (2 * SIGMA ** 2)), 0.0)
        heat = gaussian_heatmaps(p, GRID[::-1], SIGMA, peak)
        frame_id = msg.header.frame_id
        self.pubs[CAMERAS[c]][1].publish(camera_info_from_camera(camera.crop(box, GRID), stamp,
                                                                 frame_id))
        self.pubs[CAMERAS[c]][0].publish(heatmaps_to_image_msg(heat, stamp, frame_id))
        self.answered += 1


def test_replay_matches_pose2sim_triangulation(ros_env, shared_data, tmp_path):
    bag = shared_data / 'derived_pose2sim_4cam_mcap' / 'pose2sim_balancing_4cam'
    trial = (shared_data / 'pose2sim_demo_balancing' / 'S00_P00_SingleParticipant'
             / 'S00_P00_T01_BalancingTrial')
    if not bag.is_dir() or not trial.is_dir():
        pytest.skip('Pose2Sim data not in shared data')
    detections = load_detections(trial)
    truth = load_trc(trial / 'pose-3d' / 'S00_P00_T01_BalancingTrial_0-100.trc')
    skeleton = tmp_path / 'body21.yaml'
    skeleton.write_text(yaml.safe_dump({'name': 'pose2sim_body21',
                                        'keypoints': list(MARKERS),
                                        'bones': [list(b) for b in BONES]}))
    fusion_params = dict(rig=str(bag), skeleton=str(skeleton), threshold_px=7.5,
                         confidence_threshold=LIKELIHOOD_MIN, timeout_s=1.0,
                         input_reliability='reliable')
    player_params = dict(bag=str(bag), rate=0.25, wait_for_subscribers=1, start_delay_s=1.0,
                         topics=[f'/{cam}/camera_info' for cam in CAMERAS])
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, fusion_params) as fusion:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 200)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray, 50)
        detector = OpenPoseDetector(ros, detections)
        for heat_pub, info_pub in detector.pubs.values():
            ros.wait_for_subscribers(heat_pub, process=fusion)
            ros.wait_for_subscribers(info_pub, process=fusion)
        def ours():
            return len({header_stamp_ns(c) for c in clouds if c.width == len(MARKERS)
                        and 0 <= round((header_stamp_ns(c) - T0_NS) * 60 / 1e9) < 100})
        with NodeProcess('player', ros_env, player_params) as player:
            # until every frame is fused (not a pause): the counts are asserted below
            ros.spin_until(lambda: ours() >= 100, timeout=120, process=fusion)
            assert player.stop() == 0, player.output()
        assert fusion.stop() == 0, fusion.output()
    assert detector.answered >= 380
    for status in fusion_statuses(diagnostics).values():
        print(status.name, status.message, [(kv.key, kv.value) for kv in status.values])
    # Only this replay's frames (a parallel test run on the same random domain id is
    # possible on a shared machine: ignore clouds that are not ours).
    clouds = [c for c in clouds if c.width == len(MARKERS)
              and 0 <= round((header_stamp_ns(c) - T0_NS) * 60 / 1e9) < 100]
    errors = []
    for cloud in clouds:
        frame = round((header_stamp_ns(cloud) - T0_NS) * 60 / 1e9)
        assert cloud.header.frame_id == 'world'
        k = cloud_to_keypoints3d(cloud, units='m')
        confident = (detections[:, frame, :, 2] >= LIKELIHOOD_MIN).all(axis=0)
        errors.append(np.linalg.norm(k['X'] - truth[frame], axis=1)[confident])
    errors = np.concatenate(errors) * 1000   # mm
    missing = np.isnan(errors)
    errors = errors[~missing]
    print(f'{errors.size} confident joints: median {np.median(errors):.4f} mm, '
          f'p95 {np.percentile(errors, 95):.4f} mm, max {errors.max():.3f} mm; '
          f'{missing.sum()} not triangulated')
    assert len(clouds) >= 90, f'only {len(clouds)} of 100 frames fused'
    assert errors.size > 1500
    assert np.median(errors) < 0.5
    assert np.percentile(errors, 95) < 1.0
