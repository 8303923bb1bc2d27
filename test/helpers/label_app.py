"""`monet label` as a real process for tests: a free port, the server started and stopped
(SIGINT, exit 0), and JSON requests that carry the page's token like the page does."""
from contextlib import contextmanager
import http.client
import json
import os
from pathlib import Path
import re
import socket
import subprocess
import sys
import time
import urllib.parse
import urllib.request

REPO_ROOT = Path(__file__).resolve().parents[2]
TOKEN_HEADER = 'X-Monet-Token'


def free_port():
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


@contextmanager
def label_server(rec, labels, *args, timeout=90.0):
    """`monet label REC --labels LABELS ARGS` in a subprocess on a free port; yields its URL
    once /api/summary answers; stops it with SIGINT (and checks it exits 0)."""
    port = free_port()
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(REPO_ROOT), env.get('PYTHONPATH')]))
    log = open(Path(labels).with_suffix('.server.log'), 'w+')
    proc = subprocess.Popen([sys.executable, '-m', 'monet_ros.cli', 'label', str(rec),
                             '--labels', str(labels), '--port', str(port), *map(str, args)],
                            stdout=log, stderr=subprocess.STDOUT, env=env, cwd=REPO_ROOT)
    url = f'http://127.0.0.1:{port}'
    try:
        deadline = time.monotonic() + timeout
        while True:
            if proc.poll() is not None:
                log.seek(0)
                raise AssertionError(f'monet label exited {proc.returncode}: {log.read()}')
            try:
                with urllib.request.urlopen(url + '/api/summary', timeout=5):
                    break
            except OSError:
                if time.monotonic() > deadline:
                    raise AssertionError('monet label did not answer in time') from None
                time.sleep(0.2)
        yield url
    finally:
        if proc.poll() is None:
            proc.send_signal(2)
            try:
                code = proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                code = proc.wait()
            assert code == 0, f'monet label exited {code} on SIGINT'
        log.close()


def page_token(url):
    """The token of the page served at `url` (its <meta name="monet-token">)."""
    with urllib.request.urlopen(url + '/', timeout=60) as response:
        page = response.read().decode()
    found = re.search(r'<meta name="monet-token" content="([^"]+)">', page)
    assert found, 'the page carries no token'
    return found.group(1)


def request(url, method='GET', body=None, headers=None, raw=None):
    """One HTTP request to `url` (http.client: Host / Origin headers as given). body: JSON
    value, raw: bytes as they are. Returns (status, headers, parsed JSON or bytes)."""
    parts = urllib.parse.urlsplit(url)
    conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=120)
    headers = dict(headers or {})
    data = raw
    if body is not None:
        data = json.dumps(body).encode()
    if data is not None:
        headers.setdefault('Content-Type', 'application/json')
    try:
        conn.request(method, parts.path + (f'?{parts.query}' if parts.query else ''),
                     body=data, headers=headers)
        response = conn.getresponse()
        payload = response.read()
        kind = response.headers.get('Content-Type', '')
        if kind.startswith('application/json'):
            payload = json.loads(payload)
        return response.status, response.headers, payload
    finally:
        conn.close()
