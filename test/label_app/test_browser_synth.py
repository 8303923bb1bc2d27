"""`monet label` in a real headless Chromium on a small `monet synth` recording: clicks in
two views give ghosts at the projections of their triangulation (checked against OpenCV's
triangulation and Camera.project), 'a' accepts them, the autosaved table round-trips through
the labels loader, a drag corrects a point, Ctrl+Z undoes it, Delete removes one, and a
reload finds the labels."""
import json
import subprocess
import sys
import time
import urllib.request

import cv2
from helpers.recordings import noise_recording, small_checkpoint
import numpy as np
import pytest

from monet_ros.geometry import load_rig
from monet_ros.labels import read_label_rows, resolve_labels

from .conftest import label_server

T = 2
KP = 'head'


@pytest.fixture(scope='module')
def synth(tmp_path_factory):
    out = tmp_path_factory.mktemp('label') / 'synth'
    subprocess.run([sys.executable, '-m', 'monet_ros.cli', 'synth', '--out', str(out),
                    '--cameras', '4', '--frames', '4', '--width', '320', '--height', '240',
                    '--quiet'], check=True)
    return out


def opencv_ghost(cam_a, uv_a, cam_b, uv_b, target):
    """Independent: OpenCV undistortPoints + triangulatePoints, then Camera.project."""
    ideal = []
    for cam, uv in ((cam_a, uv_a), (cam_b, uv_b)):
        xy = cv2.undistortPoints(np.array([[uv]], np.float64), cam.K, cam.dist).reshape(2, 1)
        ideal.append(xy)
    P = [np.hstack([c.R, c.t[:, None]]) for c in (cam_a, cam_b)]
    Xh = cv2.triangulatePoints(P[0], P[1], ideal[0], ideal[1]).ravel()
    return target.project((Xh[:3] / Xh[3])[None])[0]


def distance_to_polyline(point, line):
    a, b = np.array(line[:-1]), np.array(line[1:])
    ab = b - a
    s = np.clip(((point - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
    return np.linalg.norm(a + s[:, None] * ab - point, axis=1).min()


def saved(path, synth_dir, cameras, keypoints):
    """The saved table through the labels loader (read_label_rows + resolve_labels)."""
    from monet_ros.learning.recording_index import recording_index
    index = recording_index(synth_dir)
    labels, report = resolve_labels(read_label_rows(path), index.stamps, cameras, keypoints)
    assert report.total_skipped == 0 and report.kept == report.rows
    return labels, index.stamps


def test_click_two_views_ghosts_accept_drag_undo_reload(synth, tmp_path, browser, label_page):
    cams = load_rig(synth / 'rig.yaml')
    names = [c.name for c in cams]
    from monet_ros.learning.recording_index import recording_index
    stamps = recording_index(synth).stamps
    gt = np.load(synth / 'ground_truth.npz')
    X = gt['keypoints3d'][list(gt['stamps']).index(stamps[T])]      # (C, 3) of instant T
    from monet_ros.skeleton import load_skeleton
    keypoints = tuple(load_skeleton('human14').keypoints)
    c = keypoints.index(KP)
    truth = {cam.name: cam.project(X[c][None])[0] for cam in cams}
    out = tmp_path / 'labels.csv'
    with label_server(synth, out) as url:
        page = label_page(browser, url)
        page.open(T)
        assert page.state('summary.keypoints[window.monetLabel.selected]') == KP
        # zoom into cam0 (wheel) and pan it (right drag): clicks still land on the pixel
        scale = page.state('views[0].s')
        page.wheel(names[0], *truth[names[0]], -300)
        assert page.state('views[0].s') > 1.3 * scale
        shift = page.state('views[0].tx'), page.state('views[0].ty')
        page.pan(names[0], truth[names[0]], truth[names[0]] + (20.0, -10.0))
        moved = page.state('views[0].tx') - shift[0], page.state('views[0].ty') - shift[1]
        scale = page.state('views[0].s')
        np.testing.assert_allclose(moved, (20.0 * scale, -10.0 * scale), atol=1.5)
        page.click(names[0], *truth[names[0]])
        page.wait_idle()
        # one view clicked: its epipolar curve in the others passes by the true projection
        curves = page.state('epipolar')
        for j in (1, 2, 3):
            lines = curves[names[j]][names[0]]
            assert min(distance_to_polyline(truth[names[j]], line) for line in lines) < 1.5
        page.click(names[1], *truth[names[1]])
        page.wait_idle()
        clicks = page.state('labels')
        assert sorted(clicks) == names[:2]
        for name in names[:2]:   # the click lands where it was aimed (screen pixel rounding)
            assert np.hypot(*(np.array(clicks[name][KP]) - truth[name])) < 1.0
        assist = page.state(f'assist["{KP}"]')
        for j in (2, 3):
            ghost = np.array(assist['views'][names[j]]['ghost'])
            expected = opencv_ghost(cams[0], clicks[names[0]][KP], cams[1],
                                    clicks[names[1]][KP], cams[j])
            assert np.hypot(*(ghost - expected)) < 1.0, (names[j], ghost, expected)
            assert np.hypot(*(ghost - truth[names[j]])) < 3.0
        for j in (0, 1):
            assert assist['views'][names[j]]['error'] < 1.0
            assert not assist['views'][names[j]]['flagged']

        page.key('a')
        page.wait_idle()
        labels, stamps = saved(out, synth, cams, keypoints)
        assert labels.stamps == [int(stamps[T])]
        points = labels.points(stamps[T], names)[:, c]          # (V, 2)
        for j in (2, 3):
            np.testing.assert_allclose(points[j], assist['views'][names[j]]['ghost'],
                                       atol=1e-9)
        for j in (0, 1):
            np.testing.assert_allclose(points[j], clicks[names[j]][KP], atol=1e-9)
        assert np.isfinite(labels.points(stamps[T], names)).sum() == 8   # 1 keypoint x 4 views

        # drag-correct the accepted ghost in cam2 by (+6, -4) px
        before = points[2].copy()
        target = before + (6.0, -4.0)
        page.drag(names[2], before, target)
        page.wait_idle()
        moved = labels_after = saved(out, synth, cams, keypoints)[0]
        moved = labels_after.points(stamps[T], names)[2, c]
        assert np.hypot(*(moved - target)) < 1.0, (moved, target)
        # the dragged view now disagrees with the others: its error shows it
        err = page.state(f'assist["{KP}"].views["{names[2]}"].error')
        assert err > 2.0
        assert 'flagged' not in browser.find_element(
            'css selector', f'.view[data-camera="{names[2]}"]').get_attribute('class')
        # a drag far off: the view is flagged (error above --flag-px), then undo it too
        page.drag(names[2], target, target + (30.0, 0.0))
        page.wait_idle()
        assert page.state(f'assist["{KP}"].views["{names[2]}"].flagged') is True
        assert 'flagged' in browser.find_element(
            'css selector', f'.view[data-camera="{names[2]}"]').get_attribute('class')
        page.key('z', ctrl=True)
        page.wait_idle()
        page.key('z', ctrl=True)
        page.wait_idle()
        undone = saved(out, synth, cams, keypoints)[0].points(stamps[T], names)[2, c]
        np.testing.assert_allclose(undone, before, atol=1e-9)

        # Delete in the view under the pointer
        page.hover(names[3])
        page.key('\ue017')                                          # Keys.DELETE
        page.wait_idle()
        after = saved(out, synth, cams, keypoints)[0].points(stamps[T], names)[:, c]
        assert np.isnan(after[3]).all() and np.isfinite(after[:3]).all()

        # reload: the page shows the saved labels
        page.open(T)
        shown = page.state('labels')
        assert sorted(shown) == names[:3]
        for j in range(3):
            np.testing.assert_allclose(shown[names[j]][KP], after[j], atol=1e-9)
        assert page.state('labelled') == [T]


def test_model_prefills_and_says_how_instants_are_suggested(tmp_path, browser, label_page):
    rig, stamps = noise_recording(tmp_path / 'bag', cameras=3, frames=4, width=96, height=64)
    model = small_checkpoint(tmp_path / 'model.pt')
    with label_server(tmp_path / 'bag', tmp_path / 'labels.csv', '--model', model) as url:
        with urllib.request.urlopen(url + '/api/labels/1', timeout=120) as response:
            served = json.loads(response.read())
        page = label_page(browser, url)
        page.open(1)
        assert page.state('prefill') is True
        assert page.state('labels') == served['labels']
        deadline = time.monotonic() + 60
        while page.state('suggest') is None:
            assert time.monotonic() < deadline, 'no suggestions'
            time.sleep(0.1)
        text = browser.find_element('id', 'suggest-method').text
        assert "detector's 3D poses" in text
        assert 'detector disagreement' in browser.find_element('id', 'disagreement').text
    assert not (tmp_path / 'labels.csv').exists()        # nothing saved before an edit
