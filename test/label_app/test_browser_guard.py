"""`monet label` in a real headless Chromium against what a labelling page left open meets:
a page of another site whose name is rebound to 127.0.0.1 (DNS rebinding) can neither load
the page nor change labels; camera and keypoint names that are HTML stay text (and the
Content-Security-Policy stops inline script); a stale second tab's save is refused by the
server and merged per keypoint by the page, so neither tab's labels are lost and autosave
goes on."""
import re
import subprocess
import sys

from helpers.label_app import page_token, request
import numpy as np
import pytest

from monet_ros.geometry import load_rig
from monet_ros.labels import read_label_rows, resolve_labels
from monet_ros.learning.recording_index import recording_index
from monet_ros.skeleton import load_skeleton

from .conftest import REBOUND_HOST, label_server

T = 1


@pytest.fixture(scope='module')
def synth(tmp_path_factory):
    out = tmp_path_factory.mktemp('guard') / 'synth'
    subprocess.run([sys.executable, '-m', 'monet_ros.cli', 'synth', '--out', str(out),
                    '--cameras', '4', '--frames', '3', '--width', '160', '--height', '120',
                    '--quiet'], check=True)
    return out


def fetch_in_page(browser, method, path, body=None, headers=None):
    """fetch() from the page's own origin (what any script of that origin can do):
    [status, text]."""
    return browser.execute_async_script(
        'const done = arguments[arguments.length - 1];'
        'const [method, path, body, headers] = arguments;'
        'fetch(path, {method, headers: Object.assign({"Content-Type": "application/json"},'
        ' headers || {}), body: body === null ? undefined : JSON.stringify(body)})'
        '.then(async (r) => done([r.status, await r.text()]))'
        '.catch((e) => done([0, String(e)]));', method, path, body, headers)


def test_a_rebound_name_gets_neither_the_page_nor_a_change(synth, tmp_path, browser):
    labels = tmp_path / 'labels.csv'
    labels.write_bytes((synth / 'labels.csv').read_bytes())
    before = labels.read_bytes()
    with label_server(synth, labels) as url:
        port = int(url.rsplit(':', 1)[1])
        # the attacker's page: its own name, resolved (rebound) to this machine
        browser.get(f'http://{REBOUND_HOST}:{port}/')
        assert browser.execute_script('return Boolean(window.monetLabel);') is False
        assert 'is not served here' in browser.find_element('tag name', 'body').text
        assert 'monet-token' not in browser.page_source
        # its script, same-origin with the rebound name, tries what the issue did
        status, text = fetch_in_page(browser, 'PUT', f'/api/labels/{T}',
                                     {'labels': {}, 'version': 'x'})
        assert status == 421 and REBOUND_HOST in text
        status, _ = fetch_in_page(browser, 'GET', '/api/summary')
        assert status == 421
        # ... even holding the real token (it cannot read it; a guess or a leak)
        status, _ = fetch_in_page(browser, 'PUT', f'/api/labels/{T}',
                                  {'labels': {}, 'version': 'x'},
                                  {'X-Monet-Token': page_token(url)})
        assert status == 421
        # the same server under its own name: the page loads and has the token
        browser.get(url + f'/?t={T}')
        assert browser.execute_script(
            'return document.querySelector("meta[name=monet-token]").content;'
        ) == page_token(url)
        # a script of the page's own origin without the token: refused all the same
        status, text = fetch_in_page(browser, 'PUT', f'/api/labels/{T}',
                                     {'labels': {}, 'version': 'x'})
        assert status == 403 and 'X-Monet-Token' in text
    assert labels.read_bytes() == before


def test_html_in_camera_and_keypoint_names_stays_text(synth, tmp_path, browser, label_page):
    evil_cam = '<img src=x onerror="document.title=1">'
    evil_kp = '<img src=y onerror="document.title=2">'
    rig_text = (synth / 'rig.yaml').read_text().replace("name: 'cam0'",
                                                        f"name: '{evil_cam}'", 1)
    assert evil_cam in rig_text
    (tmp_path / 'rig.yaml').write_text(rig_text)
    keypoints = list(load_skeleton('human14').keypoints)
    keypoints[1] = evil_kp
    (tmp_path / 'sk.yaml').write_text(
        'name: evil\nkeypoints:\n' + ''.join(f"  - '{k}'\n" for k in keypoints) +
        f"bones: [[head, '{evil_kp}']]\n")
    with label_server(synth, tmp_path / 'labels.csv', '--rig', tmp_path / 'rig.yaml',
                      '--skeleton', tmp_path / 'sk.yaml') as url:
        page = label_page(browser, url)
        page.open(T)
        assert page.state('summary.keypoints[1]') == evil_kp
        assert browser.title == 'monet label'
        assert browser.execute_script('return document.images.length;') == 0
        shown = browser.find_elements('css selector', '#keypoints li')[1]
        assert shown.text.startswith(evil_kp)                    # the name, as text
        title = browser.find_element('css selector', '#views .view .title')
        assert title.text.startswith(evil_cam)
        # a second line: the Content-Security-Policy stops inline script that got in
        # (an image that fails to load: its inline onerror would run first, if allowed)
        outcome = browser.execute_async_script(
            'const done = arguments[1];'
            'document.body.insertAdjacentHTML("beforeend", arguments[0]);'
            'const img = document.body.lastElementChild;'
            'img.addEventListener("error", () => done("error"));'
            'img.addEventListener("load", () => done("load"));',
            '<img src="/static/app.css" onerror="document.title=\'inline\'">')
        assert outcome == 'error' and browser.title == 'monet label'
        assert 'script-src' in request(url + '/')[1]['Content-Security-Policy']


def saved(path, synth, names, keypoints):
    """{(camera, keypoint): (u, v)} of the saved table's instant T (via the labels
    loader, every row kept)."""
    stamps = recording_index(synth).stamps
    cams = load_rig(synth / 'rig.yaml')
    labels, report = resolve_labels(read_label_rows(path), stamps, cams, keypoints)
    assert report.total_skipped == 0
    if int(stamps[T]) not in labels.stamps:
        return {}
    points = labels.points(stamps[T], names)
    return {(names[j], keypoints[c]): tuple(points[j, c])
            for j, c in zip(*np.nonzero(np.isfinite(points[..., 0])))}


def test_a_stale_tab_merges_and_nothing_is_lost(synth, tmp_path, browser, label_page):
    names = [c.name for c in load_rig(synth / 'rig.yaml')]
    keypoints = tuple(load_skeleton('human14').keypoints)
    out = tmp_path / 'labels.csv'
    with label_server(synth, out) as url:
        first = browser.current_window_handle
        tab_b = label_page(browser, url)
        tab_b.open(T)                                  # tab B loads the instant ...
        browser.switch_to.new_window('tab')
        second = browser.current_window_handle
        tab_a = label_page(browser, url)
        tab_a.open(T)                                  # ... tab A too
        tab_a.click(names[0], 40.0, 30.0)              # A: cam0/head
        tab_a.wait_idle()
        a_head = tuple(tab_a.state(f'labels["{names[0]}"].head'))
        assert saved(out, synth, names, keypoints) == {(names[0], 'head'): a_head}

        browser.switch_to.window(first)                # the stale tab B: cam1/neck
        tab_b.select('neck')
        tab_b.click(names[1], 80.0, 60.0)
        tab_b.wait_idle()
        b_neck = tuple(tab_b.state(f'labels["{names[1]}"].neck'))
        assert saved(out, synth, names, keypoints) == {(names[0], 'head'): a_head,
                                                       (names[1], 'neck'): b_neck}
        notice = browser.find_element('id', 'notice').text
        assert re.search(r'saved by another tab .* merged, 1 of its points taken in', notice)
        # B now shows A's point too, and its undo keeps it
        assert tuple(tab_b.state(f'labels["{names[0]}"].head')) == a_head
        tab_b.click(names[2], 100.0, 50.0)             # autosave goes on, no conflict now
        tab_b.wait_idle()
        b_neck2 = tuple(tab_b.state(f'labels["{names[2]}"].neck'))
        tab_b.key('z', ctrl=True)                      # undo B's last click only
        tab_b.wait_idle()
        assert saved(out, synth, names, keypoints) == {(names[0], 'head'): a_head,
                                                       (names[1], 'neck'): b_neck}
        tab_b.click(names[2], 100.0, 50.0)
        tab_b.wait_idle()

        browser.switch_to.window(second)               # A is the stale one now
        tab_a.drag(names[0], a_head, (a_head[0] + 5.0, a_head[1] - 3.0))
        tab_a.wait_idle()
        a_moved = tuple(tab_a.state(f'labels["{names[0]}"].head'))
        assert np.hypot(a_moved[0] - a_head[0] - 5.0, a_moved[1] - a_head[1] + 3.0) < 1.0
        assert saved(out, synth, names, keypoints) == {(names[0], 'head'): a_moved,
                                                       (names[1], 'neck'): b_neck,
                                                       (names[2], 'neck'): b_neck2}
        assert 'merged, 2 of its points' in browser.find_element('id', 'notice').text
        # a reload of either tab shows exactly the saved labels
        tab_a.open(T)
        shown = tab_a.state('labels')
        assert {(c, k): tuple(uv) for c, p in shown.items() for k, uv in p.items()} == \
            saved(out, synth, names, keypoints)
        browser.close()
        browser.switch_to.window(first)
