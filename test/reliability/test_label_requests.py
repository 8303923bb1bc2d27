"""Generated requests to a running `monet label` (a real server process): Host and Origin
headers, body sizes and coordinate values of every JSON type. Each is served right
(checked against what was sent) or refused with a JSON error naming the header / limit /
field (421, 403, 413, 400) - never a 500, a hang or a label changed by a refused request."""
import json

from helpers.label_app import TOKEN_HEADER, label_server, page_token, request
from helpers.recordings import noise_recording
from helpers.reliability import RELIABILITY, record
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from monet_ros.label_app.guard import request_limit
from monet_ros.skeleton import load_skeleton

ENTRY = 'monet label (HTTP)'
W, H = 64, 48
ASCII = st.characters(min_codepoint=33, max_codepoint=126)      # visible, no space


@pytest.fixture(scope='module')
def server(tmp_path_factory):
    """(url, port, token, labels path, camera names): 2 cameras x 2 instants, no labels."""
    root = tmp_path_factory.mktemp('label_requests')
    rig, _ = noise_recording(root / 'bag', cameras=2, frames=2, width=W, height=H)
    labels = root / 'labels.csv'
    with label_server(root / 'bag', labels) as url:
        yield url, int(url.rsplit(':', 1)[1]), page_token(url), labels, [c.name for c in rig]


def served_hosts(port):
    return {f'localhost:{port}', f'127.0.0.1:{port}', f'[::1]:{port}'}


def hosts(port):
    return st.one_of(
        st.sampled_from(sorted(served_hosts(port)) + [f'LocalHost:{port}', 'localhost',
                                                      f'localhost:{port + 1}', '[::1]',
                                                      f'127.0.0.1.:{port}', '']),
        st.from_regex(r'[a-z0-9.\-]{1,24}(:[0-9]{1,5})?', fullmatch=True),
        st.text(ASCII, max_size=30))


@settings(RELIABILITY, max_examples=30)
@given(data=st.data())
def test_host_headers(server, data):
    url, port, token, labels, names = server
    host = data.draw(hosts(port))
    status, _, body = request(url + '/api/summary', headers={'Host': host})
    if host.lower() in served_hosts(port):
        assert status == 200 and [c['name'] for c in body['cameras']] == names
        record(ENTRY, 'right result')
    else:
        assert status == 421 and 'is not served here' in body['error'], (host, body)
        record(ENTRY, 'clear error')


@settings(RELIABILITY, max_examples=30)
@given(data=st.data())
def test_origin_headers(server, data):
    url, port, token, labels, names = server
    origin = data.draw(st.one_of(
        st.sampled_from([f'http://{h}' for h in sorted(served_hosts(port))] +
                        ['null', f'https://localhost:{port}', f'http://localhost:{port}/',
                         f'http://localhost:{port + 1}']),
        st.from_regex(r'(https?|ftp|file)://[a-z0-9.\-]{1,20}(:[0-9]{1,5})?', fullmatch=True),
        st.text(ASCII, max_size=30)))
    status, _, body = request(url + '/api/triangulate', 'POST', {'labels': {}},
                              headers={'Origin': origin, TOKEN_HEADER: token})
    if origin.lower() in {f'http://{h}' for h in served_hosts(port)}:
        assert status == 200 and body == {}
        record(ENTRY, 'right result')
    else:
        assert status == 403 and 'origin' in body['error'], (origin, body)
        record(ENTRY, 'clear error')


@settings(RELIABILITY, max_examples=20)
@given(data=st.data())
def test_body_sizes(server, data):
    url, port, token, labels, names = server
    limit = request_limit(names, load_skeleton('human14').keypoints)
    size = data.draw(st.one_of(st.integers(40, 4096), st.integers(limit - 64, limit + 64),
                               st.integers(limit, 3 * limit)))
    head = b'{"labels": {}, "pad": "'
    raw = head + b'x' * (size - len(head) - 2) + b'"}'
    assert len(raw) == size
    status, _, body = request(url + '/api/triangulate', 'POST', raw=raw,
                              headers={TOKEN_HEADER: token})
    if size <= limit:
        assert status == 200 and body == {}
        record(ENTRY, 'right result')
    else:
        assert status == 413, (size, status)
        assert f'{size} bytes' in body['error'] and f'limit is {limit} bytes' in body['error']
        record(ENTRY, 'clear error')


JSON_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10, 100), st.integers(-10**30, 10**30),
    st.floats(allow_nan=True, allow_infinity=True), st.floats(-1.0, 70.0),
    st.text(max_size=6), st.sampled_from(['1', '2.5', 'NaN', 'true', '']),
    st.lists(st.integers(0, 5), max_size=2), st.dictionaries(st.text(max_size=2),
                                                             st.integers(), max_size=2))


@settings(RELIABILITY, max_examples=40)
@given(u=JSON_VALUES, v=JSON_VALUES, shape=st.sampled_from(['pair', 'triple', 'bare']))
def test_coordinate_types(server, u, v, shape):
    url, port, token, labels, names = server
    uv = {'pair': [u, v], 'triple': [u, v, v], 'bare': u}[shape]
    t_url = f'{url}/api/labels/1'
    before = labels.read_bytes() if labels.exists() else None
    version = request(t_url)[2]['version']
    status, _, body = request(t_url, 'PUT', {'labels': {names[0]: {'head': uv}},
                                             'version': version},
                              headers={TOKEN_HEADER: token})

    def number(x, size):
        return (isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)
                and -0.5 <= x <= size - 0.5)

    if shape == 'bare' and u is None:                  # null: no point (allowed)
        assert status == 200 and request(t_url)[2]['labels'] == {}
        record(ENTRY, 'right result')
    elif shape == 'pair' and number(u, W) and number(v, H):
        assert status == 200, body
        assert request(t_url)[2]['labels'] == {names[0]: {'head': [float(u), float(v)]}}
        version = request(t_url)[2]['version']
        assert request(t_url, 'PUT', {'labels': {}, 'version': version},
                       headers={TOKEN_HEADER: token})[0] == 200
        record(ENTRY, 'right result')
    else:
        assert status == 400, (uv, status, body)
        assert f'{names[0]}/head' in body['error'], body
        assert (labels.read_bytes() if labels.exists() else None) == before
        record(ENTRY, 'clear error')
    json.dumps(body)                                     # every answer is JSON
