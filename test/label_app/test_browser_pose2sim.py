"""`monet label` on the real Pose2Sim recording (4 cameras, JPEG, lens distortion): label 3
instants by clicking 2 views per joint at the reference's projections + 2 px noise and
accepting the ghosts; the triangulation of the saved labels lies within 20 mm of
Pose2Sim's .trc. With MONET_LABEL_SCREENSHOT=PATH it also writes the page's screenshot
(docs/label_pose2sim.png is made so)."""
import os
from pathlib import Path
import shutil

import numpy as np
import pytest
import yaml

from monet_ros.geometry.triangulation import triangulate
from monet_ros.io.export_tables import read_trc
from monet_ros.labels import read_label_rows, resolve_labels

from .conftest import label_server

BAG = 'derived_pose2sim_4cam_mcap/pose2sim_balancing_4cam'
TRC = ('pose2sim_demo_balancing/S00_P00_SingleParticipant/S00_P00_T01_BalancingTrial/'
       'pose-3d/S00_P00_T01_BalancingTrial_0-100.trc')
INSTANTS = (10, 50, 90)
BONES = [('RHip', 'RKnee'), ('RKnee', 'RAnkle'), ('RAnkle', 'RHeel'), ('RAnkle', 'RBigToe'),
         ('LHip', 'LKnee'), ('LKnee', 'LAnkle'), ('LAnkle', 'LHeel'), ('LAnkle', 'LBigToe'),
         ('RHip', 'LHip'), ('Neck', 'RHip'), ('Neck', 'LHip'), ('Neck', 'Head'),
         ('Head', 'Nose'), ('Neck', 'RShoulder'), ('RShoulder', 'RElbow'),
         ('RElbow', 'RWrist'), ('Neck', 'LShoulder'), ('LShoulder', 'LElbow'),
         ('LElbow', 'LWrist')]


def best_pair(cams, X):
    """The two views (indices) where X projects inside the image whose rays are closest to
    perpendicular (what a user clicks: views that see the joint from well apart, not
    facing each other along one line)."""
    seen = [j for j, cam in enumerate(cams)
            if cam.to_camera(X[None])[0, 2] > 0 and
            -0.5 <= cam.project(X[None])[0, 0] <= cam.width - 0.5 and
            -0.5 <= cam.project(X[None])[0, 1] <= cam.height - 0.5]
    best, score = None, -1.0
    for a in seen:
        for b in seen:
            if a < b:
                ra, rb = X - cams[a].center, X - cams[b].center
                sine = np.linalg.norm(np.cross(ra, rb)) / np.linalg.norm(ra) / np.linalg.norm(rb)
                if sine > score:
                    best, score = (a, b), sine
    return best


@pytest.mark.slow
def test_label_pose2sim_three_instants_within_20mm(shared_data, tmp_path, browser,
                                                    label_page):
    from monet_ros.learning.recording_index import recording_index

    bag, trc_path = shared_data / BAG, shared_data / TRC
    if not bag.exists() or not trc_path.exists():
        pytest.skip(f'{bag} or {trc_path} absent')
    trc = read_trc(trc_path, axes='yzx')        # world = trc(Z, X, Y): Pose2Sim is Y-up
    names = list(trc['keypoints'])
    skeleton = tmp_path / 'pose2sim.yaml'
    skeleton.write_text(yaml.safe_dump({'name': 'pose2sim', 'keypoints': names,
                                        'bones': [list(b) for b in BONES]}))
    index = recording_index(bag)
    cams = index.cameras
    cam_names = [c.name for c in cams]
    assert len(cams) == 4 and len(index.stamps) == 100
    rng = np.random.default_rng(0)
    out = tmp_path / 'labels.csv'
    with label_server(bag, out, '--skeleton', skeleton) as url:
        page = label_page(browser, url)
        for n, t in enumerate(INSTANTS):
            page.open(t)
            row = list(trc['frames']).index(t + 1)          # TRC Frame# t+1 = instant t
            for c, kp in enumerate(names):
                X = trc['X'][row, c]
                page.select(kp)
                for j in best_pair(cams, X):
                    noise = rng.normal(size=2)
                    uv = cams[j].project(X[None])[0] + 2.0 * noise / np.linalg.norm(noise)
                    page.click(cam_names[j], *uv)
                    page.wait_idle()
            assert len(page.state('assist')) == len(names)   # every joint triangulated
            if n == len(INSTANTS) - 1:
                page.select('RWrist')
                shot = tmp_path / 'label_pose2sim.png'
                browser.save_screenshot(str(shot))
                target = os.environ.get('MONET_LABEL_SCREENSHOT')
                if target:
                    Path(target).parent.mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(shot, target)
            page.key('a')
            page.wait_idle()
    labels, report = resolve_labels(read_label_rows(out), index.stamps, cams, names)
    assert report.kept == report.rows and report.total_skipped == 0
    assert labels.stamps == [int(index.stamps[t]) for t in INSTANTS]
    errors = []
    for t in INSTANTS:
        points = labels.points(index.stamps[t], cam_names)          # (V, C, 2)
        assert np.isfinite(points[..., 0]).sum(axis=0).min() >= 2
        X = triangulate(points, cams)
        reference = trc['X'][list(trc['frames']).index(t + 1)]
        errors.append(np.linalg.norm(X - reference, axis=1) * 1000.0)
    errors = np.concatenate(errors)
    assert errors.max() < 20.0, f'3D error mm: median {np.median(errors):.1f}, max ' \
        f'{errors.max():.1f}'
