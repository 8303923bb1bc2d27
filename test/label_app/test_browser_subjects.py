"""`monet label` with several subjects (issue 39 item 6) in a real headless Chromium on a small
`monet synth` recording, with a SLEAP analysis file of two tracks per camera imported
(--import sleap=DIR): the tracks are subjects 0 and 1, their names shown as text (a name
that is HTML stays text: no element is made of it); a click labels the selected subject
only; choosing 'new' labels a third subject; the autosaved table carries the subject
column and round-trips through the labels loader with every subject's points (the
imported ones kept); a reload shows them again, `s` steps to the next subject, and the API
refuses a bad subject."""
from helpers.label_app import TOKEN_HEADER, page_token, request
import numpy as np

from monet_ros.geometry import load_rig
from monet_ros.labels import read_label_rows, resolve_labels
from monet_ros.learning.recording_index import recording_index

from .conftest import label_server
from .test_browser_synth import synth  # noqa: F401 (the module's recording fixture)

T = 1
KP = 'head'
EVIL = '<img src=x id=evil onerror=alert(1)>'


def write_sleap(path, uv, track_names, video):
    """SLEAP analysis HDF5 (documented shapes, stored transposed): uv (frames, tracks,
    nodes, 2)."""
    import h5py
    with h5py.File(path, 'w') as f:
        f['tracks'] = uv.transpose(0, 2, 3, 1).T            # frames*nodes*2*tracks
        f['track_occupancy'] = np.isfinite(uv[..., 0]).any(-1).astype(np.uint8)
        f['node_names'] = np.array([b'head'], dtype='S')
        f['track_names'] = np.array([n.encode() for n in track_names], dtype='S')
        f['video_path'] = video


def saved(path, synth_dir, cameras, keypoints):
    index = recording_index(synth_dir)
    labels, report = resolve_labels(read_label_rows(path), index.stamps, cameras, keypoints)
    assert report.total_skipped == 0 and report.kept == report.rows
    return labels, index.stamps


def test_clicks_label_the_selected_subject(synth, tmp_path, browser, label_page):  # noqa: F811
    cams = load_rig(synth / 'rig.yaml')
    names = [c.name for c in cams]
    from monet_ros.skeleton import load_skeleton
    keypoints = tuple(load_skeleton('human14').keypoints)
    c = keypoints.index(KP)
    frames = len(recording_index(synth).stamps)
    # imported: track 'mouse' at (40, 50) + 10 v, the evil-named one at (200, 150) + 10 v,
    # at instant T only (the other frames: no instance)
    sleap = tmp_path / 'sleap'
    sleap.mkdir()
    for v, cam in enumerate(cams):
        uv = np.full((frames, 2, 1, 2), np.nan)
        uv[T, 0, 0] = (40.0, 50.0 + 10 * v)
        uv[T, 1, 0] = (200.0, 150.0 + 10 * v)
        write_sleap(sleap / f'{cam.name}.analysis.h5', uv, ['mouse', EVIL], f'{cam.name}.mp4')
    out = tmp_path / 'labels.csv'
    with label_server(synth, out, '--import', f'sleap={sleap}') as url:
        page = label_page(browser, url)
        page.open(T)
        assert page.state('subject') == 0
        buttons = browser.find_elements('css selector', '#subjects button')
        assert [b.text for b in buttons] == ['0 (mouse) *', f'1 ({EVIL}) *', 'new']
        assert browser.find_elements('id', 'evil') == []          # the name is text only
        assert page.state('labels')[names[0]][KP] == [40.0, 50.0]
        assert page.state('others')['1'][names[0]][KP] == [200.0, 150.0]

        # subject 1: a click moves its head in cam0; subject 0 is untouched
        browser.find_element('css selector', '#subjects button[data-subject="1"]').click()
        page.wait_idle()
        assert page.state('subject') == 1
        assert page.state('labels')[names[0]][KP] == [200.0, 150.0]
        page.select(KP)
        page.click(names[0], 220.0, 160.0)
        page.wait_idle()
        # a new subject (id 2): clicks in two views
        browser.find_element('css selector', '#subjects button[data-subject="new"]').click()
        page.wait_idle()
        assert page.state('subject') == 2 and page.state('labels') == {}
        page.select(KP)
        page.click(names[0], 100.0, 100.0)
        page.wait_idle()
        page.click(names[1], 120.0, 90.0)
        page.wait_idle()

        assert out.read_text().splitlines()[0] == 'stamp_ns,camera,keypoint,u,v,subject'
        labels, stamps = saved(out, synth, cams, keypoints)
        assert labels.subjects == [0, 1, 2]
        s0 = labels.points(stamps[T], names, 0)[:, c]
        s1 = labels.points(stamps[T], names, 1)[:, c]
        s2 = labels.points(stamps[T], names, 2)[:, c]
        np.testing.assert_array_equal(s0, [(40.0, 50.0 + 10 * v) for v in range(4)])
        assert np.hypot(*(s1[0] - (220.0, 160.0))) < 1.0           # the click
        np.testing.assert_array_equal(s1[1:], [(200.0, 150.0 + 10 * v) for v in (1, 2, 3)])
        assert np.hypot(*(s2[0] - (100.0, 100.0))) < 1.0
        assert np.hypot(*(s2[1] - (120.0, 90.0))) < 1.0 and np.isnan(s2[2:]).all()

        # reload: the page starts on subject 0 and lists every subject labelled here
        page.open(T)
        texts = [b.text for b in browser.find_elements('css selector', '#subjects button')]
        assert texts == ['0 (mouse) *', f'1 ({EVIL}) *', '2 *', 'new']
        assert sorted(page.state('others')) == ['1', '2']
        page.key('s')                                   # the next subject: 1
        page.wait_idle()
        assert page.state('subject') == 1
        assert np.hypot(*(np.array(page.state('labels')[names[0]][KP]) - s1[0])) < 1e-9
        assert sorted(page.state('others')) == ['0', '2']

        # the API: a bad subject is a 400 naming the field; nothing changes
        status, _, body = request(f'{url}/api/labels/{T}?subject=x')
        assert status == 400 and 'subject' in body['error']
        token = page_token(url)
        status, _, body = request(f'{url}/api/labels/{T}', 'PUT',
                                  {'labels': {}, 'version': 'x', 'subject': -1},
                                  headers={TOKEN_HEADER: token})
        assert status == 400 and 'subject: expected an integer 0..99' in body['error']
    assert saved(out, synth, cams, keypoints)[0].subjects == [0, 1, 2]
