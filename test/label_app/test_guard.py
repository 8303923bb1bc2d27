"""`monet label`'s server refuses what a page of another site, a stale tab or a bad client
sends (a real server process, raw HTTP requests): foreign Host names (DNS rebinding) 421,
changes without the page's token or from a foreign Origin 403, bodies over the limit 413,
coordinates that are not JSON numbers 400 naming the field, a save on an old version 409.
Every refusal leaves the labels table byte for byte as it was."""
import json
import re

import cv2
from helpers.label_app import TOKEN_HEADER, label_server, page_token, request
from helpers.recordings import noise_recording
import numpy as np
import pytest
import yaml

from monet_ros.label_app.guard import allowed_hosts, request_limit
from monet_ros.skeleton import load_skeleton

W, H = 64, 48


@pytest.fixture(scope='module')
def server(tmp_path_factory):
    """(url, labels path, rig, stamps): 2 cameras x 3 instants, instant 1 labelled."""
    root = tmp_path_factory.mktemp('guard')
    rig, stamps = noise_recording(root / 'bag', cameras=2, frames=3, width=W, height=H)
    labels = root / 'labels.csv'
    labels.write_text('stamp_ns,camera,keypoint,u,v\n'
                      f'{stamps[1]},{rig[0].name},head,10.0,20.0\n'
                      f'{stamps[1]},{rig[1].name},neck,30.0,5.0\n')
    with label_server(root / 'bag', labels, '--allow-host', 'Studio.lan') as url:
        yield url, labels, rig, stamps


def port_of(url):
    return int(url.rsplit(':', 1)[1])


def change(url, t, labels, version=None, headers=None):
    """PUT /api/labels/t as the page does (its token, the version it loaded)."""
    if version is None:
        version = request(f'{url}/api/labels/{t}')[2].get('version', '')
    sent = {TOKEN_HEADER: page_token(url), **(headers or {})}
    return request(f'{url}/api/labels/{t}', 'PUT', {'labels': labels, 'version': version},
                   headers=sent)


def test_allowed_hosts_are_the_loopback_names_the_bound_one_and_the_given_ones():
    assert allowed_hosts('127.0.0.1', 8080) == {
        'localhost:8080', '127.0.0.1:8080', '[::1]:8080'}
    # a wildcard bind names no host; IPv6 in brackets; port 80 also bare (browsers omit it)
    assert allowed_hosts('0.0.0.0', 80, ['Studio.LAN', 'fe80::1', '[fe80::2]']) == {
        'localhost:80', '127.0.0.1:80', '[::1]:80', 'studio.lan:80', '[fe80::1]:80',
        '[fe80::2]:80', 'localhost', '127.0.0.1', '[::1]', 'studio.lan', '[fe80::1]',
        '[fe80::2]'}
    assert allowed_hosts('192.168.1.5', 9000) == {
        'localhost:9000', '127.0.0.1:9000', '[::1]:9000', '192.168.1.5:9000'}


def test_only_the_bound_host_names_are_served(server):
    url, labels, rig, stamps = server
    port = port_of(url)
    before = labels.read_bytes()
    # the request: a rebound name, its own Origin, even with the real token
    status, _, body = request(f'{url}/api/labels/1', 'PUT', {'labels': {}, 'version': 'x'},
                              headers={'Host': f'attacker.example.com:{port}',
                                       'Origin': f'http://attacker.example.com:{port}',
                                       TOKEN_HEADER: page_token(url)})
    assert status == 421 and 'attacker.example.com' in body['error']
    # the page itself (and so its token) is not served under a foreign name either
    status, _, body = request(f'{url}/', headers={'Host': f'attacker.example.com:{port}'})
    assert status == 421 and 'monet-token' not in json.dumps(body)
    for host in (f'localhost:{port + 1}', 'localhost', f'127.0.0.2:{port}',
                 f'studio.lan.evil:{port}', f'::1:{port}', ''):
        assert request(f'{url}/api/summary', headers={'Host': host})[0] == 421, host
    for host in (f'localhost:{port}', f'LOCALHOST:{port}', f'127.0.0.1:{port}',
                 f'[::1]:{port}', f'studio.lan:{port}'):            # --allow-host Studio.lan
        assert request(f'{url}/api/summary', headers={'Host': host})[0] == 200, host
    assert labels.read_bytes() == before


def test_changes_need_the_pages_token_and_no_foreign_origin(server):
    url, labels, rig, stamps = server
    port = port_of(url)
    before = labels.read_bytes()
    version = request(f'{url}/api/labels/2')[2].get('version', '')
    body = {'labels': {rig[0].name: {'head': [1.0, 2.0]}}, 'version': version}
    for headers in ({}, {TOKEN_HEADER: 'guessed'}, {TOKEN_HEADER: page_token(url) + 'x'},
                    {TOKEN_HEADER: page_token(url), 'Origin': 'http://evil.example'},
                    {TOKEN_HEADER: page_token(url), 'Origin': 'null'},
                    {TOKEN_HEADER: page_token(url), 'Origin': f'https://localhost:{port}'}):
        status, _, answer = request(f'{url}/api/labels/2', 'PUT', body, headers=headers)
        assert status == 403, headers
        assert (TOKEN_HEADER in answer['error'] or 'origin' in answer['error']), answer
    status, _, _ = request(f'{url}/api/triangulate', 'POST', {'labels': {}})
    assert status == 403
    assert labels.read_bytes() == before
    # the page's own request: token, same origin
    status, _, answer = request(f'{url}/api/labels/2', 'PUT', body, headers={
        TOKEN_HEADER: page_token(url), 'Origin': f'http://localhost:{port}'})
    assert status == 200 and answer['rows'] == 3
    assert labels.read_text().splitlines()[-1] == f'{stamps[2]},{rig[0].name},head,1.0,2.0'
    assert change(url, 2, {})[0] == 200                          # back as it was
    assert labels.read_bytes() == before


def test_every_response_has_a_csp_without_inline_script(server):
    url = server[0]
    for path in ('/', '/api/summary', '/static/app.js', '/api/labels/99', '/nope'):
        _, headers, _ = request(url + path)
        csp = dict(part.strip().split(' ', 1) for part in
                   headers['Content-Security-Policy'].split(';'))
        assert csp['script-src'] == "'self'" and csp['default-src'] == "'none'", path
        assert 'unsafe' not in headers['Content-Security-Policy']
        assert headers['X-Content-Type-Options'] == 'nosniff'
    page = request(url + '/')[2].decode()
    scripts = re.findall(r'<script\b([^>]*)>(.*?)</script>', page, re.S)
    assert scripts and all('src=' in attrs and not text.strip() for attrs, text in scripts)
    assert not re.search(r'\son[a-z]+\s*=', page)                # no inline handlers
    app = request(url + '/static/app.js')[2].decode()
    assert 'innerHTML' not in app and 'insertAdjacentHTML' not in app


def test_bodies_over_the_limit_get_413_and_are_never_parsed(server):
    url, labels, rig, stamps = server
    names = [c.name for c in rig]
    keypoints = load_skeleton('human14').keypoints
    limit = request_limit(names, keypoints)
    assert limit == 1 << 20                     # this rig and skeleton: the 1 MiB floor
    token = {TOKEN_HEADER: page_token(url)}

    def padded(size):
        head = b'{"labels": {}, "pad": "'
        return head + b'x' * (size - len(head) - 2) + b'"}'

    status, _, body = request(f'{url}/api/triangulate', 'POST', raw=padded(limit + 1),
                              headers=token)
    assert status == 413
    assert f'{limit + 1} bytes' in body['error'] and f'limit is {limit} bytes' in body['error']
    status, _, body = request(f'{url}/api/triangulate', 'POST', raw=padded(200 << 20),
                              headers=token)
    assert status == 413
    # without a Content-Length (chunked): cut at the limit all the same
    chunks = (padded(4 << 20)[i:i + 65536] for i in range(0, 4 << 20, 65536))
    status, _, body = request(f'{url}/api/triangulate', 'POST', raw=chunks,
                              headers=token)
    assert status == 413 and 'limit' in body['error']
    assert request(f'{url}/api/triangulate', 'POST', raw=padded(limit), headers=token)[0] == 200
    # the largest request the page sends: every view x keypoint, 17-digit coordinates
    full = {c: {k: [1.2345678901234567, 2.3456789012345678] for k in keypoints}
            for c in names}
    body = {'labels': full, 'camera': names[0], 'keypoint': keypoints[0]}
    assert 2 * len(json.dumps(body)) < limit
    status, _, answer = request(f'{url}/api/epipolar', 'POST', body, headers=token)
    assert status == 200 and set(answer) == {names[1]}


@pytest.mark.parametrize('field, value, status, says', [
    ('labels', {f'cam{i}': {} for i in range(3)}, 400, '3 cameras, the rig has 2'),
    ('labels', {'c' * 100_000: {}}, 404, 'is not one of'),
    ('version', 'v' * 1000, 400, 'version: expected'),
    ('version', 7, 400, 'version: expected'),
    ('camera', 3, 400, 'camera: expected a name'),
    ('keypoint', ['head'], 400, 'keypoint: expected a name'),
])
def test_fields_are_bounded(server, field, value, status, says):
    url, labels, rig, stamps = server
    before = labels.read_bytes()
    body = {'labels': {}, 'version': 'x', 'camera': rig[0].name, 'keypoint': 'head',
            field: value}
    path = '/api/epipolar' if field in ('camera', 'keypoint') else '/api/labels/1'
    method = 'POST' if path == '/api/epipolar' else 'PUT'
    got, _, answer = request(url + path, method, body, headers={TOKEN_HEADER: page_token(url)})
    assert got == status and says in answer['error'], answer
    assert len(answer['error']) < 400                    # a huge name is cut in the message
    assert labels.read_bytes() == before


@pytest.mark.parametrize('u, v, field', [
    ('1', 2.0, 'u'), (1.0, '2', 'v'), (True, 2.0, 'u'), (1.0, False, 'v'), (None, 2.0, 'u'),
    ([1], 2.0, 'u'), ({'u': 1}, 2.0, 'u'), ('NaN', 2.0, 'u')])
def test_coordinates_must_be_json_numbers(server, u, v, field):
    url, labels, rig, stamps = server
    before = labels.read_bytes()
    cam = rig[0].name
    for path, method in (('/api/labels/0', 'PUT'), ('/api/triangulate', 'POST')):
        version = request(f'{url}/api/labels/0')[2].get('version', '')
        status, _, answer = request(url + path, method, {
            'labels': {cam: {'head': [u, v]}}, 'version': version},
            headers={TOKEN_HEADER: page_token(url)})
        assert status == 400, (path, answer)
        assert f'{cam}/head: {field} must be a number' in answer['error'], answer
    assert labels.read_bytes() == before
    # integers are numbers
    assert change(url, 0, {cam: {'head': [3, 4]}})[0] == 200
    assert request(f'{url}/api/labels/0')[2]['labels'] == {cam: {'head': [3.0, 4.0]}}
    assert change(url, 0, {})[0] == 200
    assert labels.read_bytes() == before


def test_a_save_on_an_old_version_is_refused_and_changes_nothing(server):
    url, labels, rig, stamps = server
    a, b = rig[0].name, rig[1].name
    loaded = request(f'{url}/api/labels/1')[2]           # two tabs load instant 1
    assert loaded['labels'] == {a: {'head': [10.0, 20.0]}, b: {'neck': [30.0, 5.0]}}
    first = {**loaded['labels'], b: {'neck': [30.0, 5.0], 'head': [40.0, 6.0]}}
    status, _, saved = change(url, 1, first, loaded['version'])       # tab A adds b/head
    assert status == 200 and saved['version'] != loaded['version']
    after_a = labels.read_bytes()
    status, _, answer = change(url, 1, {a: {'head': [10.0, 20.0]}}, loaded['version'])
    assert status == 409                                    # stale tab B: refused
    assert 'another tab' in answer['error'] and answer['version'] == saved['version']
    assert answer['labels'] == first                        # what B needs to merge
    assert labels.read_bytes() == after_a
    assert request(f'{url}/api/labels/1')[2]['version'] == saved['version']
    status, _, _ = change(url, 1, loaded['labels'], saved['version'])  # B, merged: accepted
    assert status == 200


# Issue 37: a 400-digit JSON integer and a body nested 100,000 arrays deep were 500 with a
# traceback; they are 400 naming the field / the body, and change nothing.
def test_a_huge_integer_or_a_deep_body_is_400_naming_it(server):
    url, labels, rig, stamps = server
    before = labels.read_bytes()
    cam = rig[0].name
    token = {TOKEN_HEADER: page_token(url)}
    version = request(f'{url}/api/labels/0')[2].get('version', '')
    huge = '9' * 400
    for path, method in (('/api/labels/0', 'PUT'), ('/api/triangulate', 'POST')):
        raw = (f'{{"labels": {{"{cam}": {{"head": [{huge}, 2.0]}}}}, "version": "{version}"}}'
               .encode())
        status, _, answer = request(url + path, method, raw=raw, headers=token)
        assert status == 400, (path, answer)
        assert answer['error'] == (f'labels {cam}/head: u must be a finite number, got a '
                                   '400-digit integer'), answer
    deep = 100_000
    for raw in (b'[' * deep + b']' * deep,
                b'{"labels": ' + b'[' * deep + b']' * deep + b', "version": "x"}',
                b'{"labels": ' + b'[' * 40 + b']' * 40 + b', "version": "x"}'):
        assert len(raw) < request_limit([c.name for c in rig], load_skeleton('human14')
                                        .keypoints)
        status, _, answer = request(f'{url}/api/labels/0', 'PUT', raw=raw, headers=token)
        depth = raw.count(b'[') + raw.startswith(b'{')
        assert status == 400, answer
        assert answer['error'] == f'body: JSON nested {depth} levels deep (at most 32)'
    # brackets inside strings are text, not nesting
    status, _, answer = request(f'{url}/api/labels/0', 'PUT', {
        'labels': {}, 'version': '[' * 100}, headers=token)
    assert status == 409 and 'another tab' in answer['error'], answer
    assert labels.read_bytes() == before


# Issue 37: keypoint names longer than 256 characters (a lab's own naming) get their
# epipolar curves like any other.
@pytest.fixture(scope='module')
def long_names(tmp_path_factory):
    root = tmp_path_factory.mktemp('long_names')
    rig, stamps = noise_recording(root / 'bag', cameras=2, frames=2, width=W, height=H)
    names = ['left_' + 'forepaw_' * 40, 'right_' + 'hindpaw_' * 45, 'tail']
    assert min(map(len, names[:2])) > 256
    skeleton = root / 'skeleton.yaml'
    skeleton.write_text(yaml.safe_dump({'name': 'lab', 'keypoints': names,
                                        'bones': [names[:2]]}))
    labels = root / 'labels.csv'
    with label_server(root / 'bag', labels, '--skeleton', str(skeleton)) as url:
        yield url, rig, names


def test_long_keypoint_names_get_epipolar_curves(long_names):
    url, rig, names = long_names
    a, b = rig
    uv = [30.0, 20.0]
    status, _, answer = request(f'{url}/api/epipolar', 'POST', {
        'camera': b.name, 'keypoint': names[1], 'labels': {a.name: {names[1]: uv}}},
        headers={TOKEN_HEADER: page_token(url)})
    assert status == 200, answer
    curve = np.array([p for line in answer[a.name] for p in line])
    assert len(curve) > 10
    # independently: undistorted by OpenCV, every point lies on the epipolar line F x of
    # the undistorted click, F from the two cameras' K, R, t
    R = b.R @ a.R.T
    t = b.t - R @ a.t
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    F = np.linalg.inv(b.K).T @ tx @ R @ np.linalg.inv(a.K)
    click = cv2.undistortPoints(np.array([[uv]]), a.K, a.dist, P=a.K).reshape(2)
    points = cv2.undistortPoints(curve[:, None], b.K, b.dist, P=b.K).reshape(-1, 2)
    line = F @ np.array([*click, 1.0])
    distance = np.abs(np.c_[points, np.ones(len(points))] @ line) / np.hypot(*line[:2])
    assert distance.max() < 1e-3, distance.max()
