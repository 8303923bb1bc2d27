"""`monet label` as a process, through its JSON API (no browser): a raw-image recording
and a detector checkpoint (suggestions from its 3D output, pre-filled peaks,
disagreement), request errors, and bad command lines (exit 2, one line)."""
import json
import subprocess
import sys
import urllib.error
import urllib.request

import cv2
from helpers.label_app import TOKEN_HEADER, page_token
from helpers.recordings import noise_recording, small_checkpoint
import numpy as np
import pytest

from .conftest import label_server


def call(url, method='GET', body=None):
    """A request as the page sends it (a change carries the page's token)."""
    data = None if body is None else json.dumps(body).encode()
    headers = {'Content-Type': 'application/json'}
    if method != 'GET':
        headers[TOKEN_HEADER] = page_token(url.split('/api/')[0])
    request = urllib.request.Request(url, data=data, method=method, headers=headers)
    try:
        with urllib.request.urlopen(request, timeout=120) as response:
            return response.status, response.headers['Content-Type'], response.read()
    except urllib.error.HTTPError as error:
        return error.code, error.headers['Content-Type'], error.read()


@pytest.fixture(scope='module')
def raw_rec(tmp_path_factory):
    root = tmp_path_factory.mktemp('raw')
    rig, stamps = noise_recording(root / 'bag', cameras=3, frames=5, width=96, height=64)
    model = small_checkpoint(root / 'model.pt')
    return root / 'bag', model, rig, stamps


def test_model_suggestions_prefill_and_raw_images(raw_rec, tmp_path):
    bag, model, rig, stamps = raw_rec
    labels = tmp_path / 'labels.csv'
    with label_server(bag, labels, '--model', model, '--suggestions', '3') as url:
        status, kind, body = call(url + '/api/summary')
        summary = json.loads(body)
        assert summary['model'] is True
        assert [c['name'] for c in summary['cameras']] == [c.name for c in rig]
        assert [int(i['stamp_ns']) for i in summary['instants']] == stamps

        # raw views come back as lossless PNG: exactly the recorded pixels
        rng = np.random.default_rng(0)                     # noise_recording's images
        expected = [[rng.integers(0, 255, (64, 96, 3), dtype=np.uint8) for _ in rig]
                    for _ in stamps]
        status, kind, body = call(url + f'/api/image/3/{rig[1].name}')
        assert status == 200 and kind == 'image/png'
        image = cv2.cvtColor(cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR),
                             cv2.COLOR_BGR2RGB)
        np.testing.assert_array_equal(image, expected[3][1])

        status, _, body = call(url + '/api/suggest')
        suggest = json.loads(body)
        assert suggest['method'] == 'detector'
        assert 1 <= len(suggest['instants']) <= 3
        assert set(suggest['instants']) <= set(range(5))
        assert sorted(int(t) for t in suggest['disagreement']) == list(range(5))

        status, _, body = call(url + '/api/labels/2')
        data = json.loads(body)
        assert status == 200 and data['prefill'] is True
        for points in data['labels'].values():
            for u, v in points.values():
                assert -0.5 <= u <= 95.5 and -0.5 <= v <= 63.5
        assert not labels.exists()                 # a pre-fill is saved only once edited

        # request errors: JSON with the reason
        status, _, body = call(url + '/api/labels/2', 'PUT',
                               {'labels': {'nocam': {'head': [1, 2]}}})
        assert status == 404 and 'nocam' in json.loads(body)['error']
        status, _, body = call(url + '/api/labels/2', 'PUT',
                               {'labels': {rig[0].name: {'head': [500, 2]}}})
        assert status == 400 and 'outside' in json.loads(body)['error']
        status, _, body = call(url + '/api/labels/99')
        assert status == 404 and 'out of range' in json.loads(body)['error']
        version = json.loads(call(url + '/api/labels/2')[2])['version']
        status, _, _ = call(url + '/api/labels/2', 'PUT',
                            {'labels': {rig[0].name: {'head': [10.25, 20.5]}},
                             'version': version})
        assert status == 200
    assert labels.read_text().splitlines() == [
        'stamp_ns,camera,keypoint,u,v', f'{stamps[2]},{rig[0].name},head,10.25,20.5']


def run_label(*args):
    return subprocess.run([sys.executable, '-m', 'monet_ros.cli', 'label', *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def test_imported_labels_are_shown_and_saved_in_the_canonical_table(raw_rec, tmp_path):
    bag, model, rig, stamps = raw_rec
    frames = tmp_path / 'frames.csv'
    frames.write_text('frame,camera,keypoint,u,v\n'
                      f'1,{rig[0].name},neck,12.5,30.25\n4,{rig[2].name},head,80.0,5.5\n')
    own = tmp_path / 'labels.csv'        # the table's own row for the same point wins
    own.write_text(f'stamp_ns,camera,keypoint,u,v\n{stamps[1]},{rig[0].name},neck,13.0,31.0\n')
    with label_server(bag, own, '--import', f'frames={frames}') as url:
        status, _, body = call(url + '/api/labels/4')
        assert json.loads(body)['labels'] == {rig[2].name: {'head': [80.0, 5.5]}}
        status, _, body = call(url + '/api/labels/1')
        assert json.loads(body)['labels'] == {rig[0].name: {'neck': [13.0, 31.0]}}
        status, _, body = call(url + '/api/summary')
        assert json.loads(body)['labelled'] == [1, 4]
        version = json.loads(call(url + '/api/labels/4')[2])['version']
        status, _, body = call(url + '/api/labels/4', 'PUT',
                               {'labels': {rig[2].name: {'head': [81.0, 6.0]}},
                                'version': version})
        assert status == 200
    assert own.read_text().splitlines() == [
        'stamp_ns,camera,keypoint,u,v', f'{stamps[1]},{rig[0].name},neck,13.0,31.0',
        f'{stamps[4]},{rig[2].name},head,81.0,6.0']


def test_a_port_in_use_is_one_line(raw_rec, tmp_path):
    import socket
    bag = raw_rec[0]
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        sock.listen(1)
        port = sock.getsockname()[1]
        result = run_label(bag, '--labels', tmp_path / 'l.csv', '--port', port)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [result.stderr.strip()]
    assert f'127.0.0.1:{port}' in result.stderr and 'port' in result.stderr


@pytest.mark.parametrize('host', ['8.8.8.8', 'no-such-host.invalid'])
def test_a_host_not_of_this_machine_names_host_not_port(raw_rec, tmp_path, host):
    """An address this machine does not have (or a name that does not resolve) is the
    --host's fault: the one line names host, not port."""
    result = run_label(raw_rec[0], '--labels', tmp_path / 'l.csv', '--host', host,
                       '--port', 0)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "parameter 'host'" in lines[0] and host in lines[0], lines
    assert "'port'" not in lines[0]


@pytest.mark.parametrize('case', ['no_recording', 'bad_import', 'labels_folder', 'bad_port',
                                  'bad_labels', 'bad_model', 'model_skeleton',
                                  'bad_allow_host', 'labels_unsavable', 'subject_beyond_page'])
def test_bad_input_exits_2_with_one_line(raw_rec, tmp_path, case):
    bag, model, rig, stamps = raw_rec
    labels = tmp_path / 'labels.csv'
    args, names = {
        'no_recording': ([tmp_path / 'nope', '--labels', labels], ['nope']),
        'bad_import': ([bag, '--labels', labels, '--import', 'xyz=a.csv'], ['import']),
        'labels_folder': ([bag, '--labels', tmp_path], ['labels']),
        'bad_port': ([bag, '--labels', labels, '--port', '70000'], ['port']),
        'bad_labels': ([bag, '--labels', labels], ['labels.csv', 'cam_9']),
        'bad_model': ([bag, '--labels', labels, '--model', tmp_path / 'm.pt'], ['m.pt']),
        'model_skeleton': ([bag, '--labels', labels, '--model', model, '--skeleton',
                            tmp_path / 'sk.yaml'], ['skeleton']),
        'bad_allow_host': ([bag, '--labels', labels, '--allow-host', 'http://studio:80/'],
                           ['allow_host']),
        # a labels file that cannot be saved (its folder would be under a file): the
        # server started and every click's autosave failed
        'labels_unsavable': ([bag, '--labels', tmp_path / 'blocker' / 'labels.csv'],
                             [f"'labels': {tmp_path / 'blocker' / 'labels.csv'}: cannot be "
                              'saved']),
        # a valid labels file (ids up to 2**31 - 1) with an id the page cannot address
        # (0..99): listed in the subject buttons and never shown before
        'subject_beyond_page': ([bag, '--labels', labels], ['labels.csv', 'subject 150']),
    }[case]
    (tmp_path / 'blocker').write_text('a file, not a folder')
    (tmp_path / 'sk.yaml').write_text('keypoints: [a, b]\n')
    if case == 'bad_labels':
        labels.write_text(f'stamp_ns,camera,keypoint,u,v\n{stamps[0]},cam_9,head,1,2\n')
    if case == 'subject_beyond_page':
        labels.write_text(f'stamp_ns,camera,keypoint,u,v,subject\n'
                          f'{stamps[0]},{rig[0].name},head,1,2,150\n')
    if case == 'bad_model':
        (tmp_path / 'm.pt').write_bytes(b'not a checkpoint')
    result = run_label(*args)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('monet label'), result.stderr
    assert any(n in lines[0] for n in names), lines[0]


def test_sigterm_stops_cleanly(raw_rec, tmp_path):
    import os
    import signal
    import time

    from .conftest import free_port
    bag = raw_rec[0]
    port = free_port()
    proc = subprocess.Popen([sys.executable, '-m', 'monet_ros.cli', 'label', str(bag),
                             '--labels', str(tmp_path / 'l.csv'), '--port', str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED='1'))
    deadline = time.monotonic() + 90
    while True:
        try:
            call(f'http://127.0.0.1:{port}/api/suggest')       # a long job in flight too
            break
        except OSError:
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert 'Traceback' not in err and err.count('stopped') == 1
