"""The web app of `monet label` (Flask): the page in static/ and a JSON API.

    GET  /                         the page (static/index.html with the run's token in a
                                   <meta name="monet-token">; every asset ships here)
    GET  /api/summary              cameras (name, width, height, K, dist, R, t), instants
                                   (index, stamp_ns as a string, complete, views),
                                   keypoints, bones, labels path, flag_px, subjects
                                   [{id, name}] (name: an import's track / individual, '')
    GET  /api/image/<t>/<camera>   the view's image (JPEG / PNG)
    GET  /api/labels/<t>?subject=s {labels: {camera: {keypoint: [u, v]}} of subject s
                                   (default 0), prefill: bool (subject 0 only), version: the
                                   (instant, subject)'s version (opaque string), subject,
                                   others: {subject: labels} of the instant's other subjects}
    PUT  /api/labels/<t>           body {labels: ..., version, subject (default 0)}: replaces
                                   that subject's labels of the instant and saves the table
                                   (atomic; every subject's rows) when `version` is still
                                   theirs -> {rows, labelled, version}; else 409
                                   {error, version, labels: the saved labels}, nothing
                                   changed (a stale tab never overwrites another's save)
    POST /api/triangulate          body {labels: ...}: -> {keypoint: {X, robust, views:
                                   {camera: {ghost [u, v], error px, flagged}}}}
    POST /api/epipolar             body {camera, keypoint, labels}: -> {camera: [polyline,
                                   ...]} the epipolar curves, in `camera`, of the
                                   keypoint's clicks in the other views
    GET  /api/suggest              {method: 'detector' | 'images', instants: [t, ...],
                                   disagreement: {t: px} (detector only)}

Every request passes guard.refusal first: a Host that is not this server's gets 421, a
foreign Origin 403, a PUT / POST without the run's X-Monet-Token header 403. Bodies are
JSON (Content-Type application/json) of at most guard.request_limit bytes (else 413; the
rest of a refused body is read and dropped, never kept).
Every response carries guard.CSP. Errors are JSON {error: message} with status 400 (bad
request), 404 (no such instant, camera or keypoint), 409 (version conflict), 413, 421, 403.
"""
from importlib import resources
import json
import re
import secrets
import threading

from flask import Flask, Response, jsonify, request, send_from_directory
import numpy as np
from werkzeug.exceptions import HTTPException, RequestEntityTooLarge

from monet_ros.label_app import guard
from monet_ros.label_app.assist import assist_instant, assist_to_json, epipolar_polyline
from monet_ros.label_app.session import (
    MAX_SUBJECT,
    NAME_CHARS,
    VersionConflict,
    check_subject,
    short,
)

# The page's placeholder for the run's token (static/index.html).
TOKEN_MARK = '__MONET_TOKEN__'
# Most bytes of a refused (413) body read and dropped; a client sending more sees a reset.
DISCARD_BYTES = 1 << 30
# Deepest nesting of arrays / objects a JSON body may have (the API's bodies have 4:
# {labels: {camera: {keypoint: [u, v]}}}); deeper ones are refused before parsing, so that
# neither the parser nor an error message recurses without bound.
JSON_DEPTH = 32
_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')


def json_depth(data):
    """Deepest nesting of arrays and objects in JSON bytes (brackets inside strings are
    not counted; unbalanced input gives a depth the parser then refuses)."""
    text = np.frombuffer(_JSON_STRING.sub(b'""', data), np.uint8)
    if not text.size:
        return 0
    step = np.isin(text, (ord('['), ord('{'))).astype(np.int64) \
        - np.isin(text, (ord(']'), ord('}')))
    return int(np.cumsum(step).max(initial=0))


def parse_json_body(data):
    """A request body's JSON; ValueError (400) naming the body when it is nested deeper
    than JSON_DEPTH or is not JSON."""
    depth = json_depth(data)
    if depth > JSON_DEPTH:
        raise ValueError(f'body: JSON nested {depth} levels deep (at most {JSON_DEPTH})')
    try:
        return json.loads(data)
    except (ValueError, RecursionError) as error:
        raise ValueError(f'body: not valid JSON ({error})') from None


def static_folder():
    """Folder of the page's assets inside the installed package."""
    return str(resources.files('monet_ros.label_app') / 'static')


def discard_body(stream, length, most=DISCARD_BYTES, chunk=1 << 20):
    """Read and drop what is left of a refused request body (at most `most` bytes, `chunk`
    at a time: memory stays at one chunk), so that the client, still sending, reads the
    413 instead of a connection reset when the server closes. length: Content-Length, or
    None for a chunked body (read to its end)."""
    left = most if length is None else min(int(length), most)
    while left > 0:
        data = stream.read(min(chunk, left))
        if not data:
            break
        left -= len(data)


def create_app(session, hosts, predictor=None, token=None):
    """Flask app serving `session` (a LabelSession). hosts: the Host header values served
    (guard.allowed_hosts of the bound address and port). predictor: a suggest.Predictor
    (the detector of --model) for suggestions, pre-fill and disagreement: an unlabelled
    instant's peaks are computed when it is opened, the subsample of suggestions on the
    first /api/suggest. token: the run's token of state-changing requests (default: a new
    random one; app.config['MONET_TOKEN'])."""
    app = Flask('monet_label', static_folder=None)
    token = token or secrets.token_urlsafe(32)
    hosts = frozenset(hosts)
    limit = guard.request_limit(session.names, session.keypoints)
    app.config.update(MONET_TOKEN=token, MONET_HOSTS=hosts, MAX_CONTENT_LENGTH=limit)
    folder = static_folder()
    state = {'suggest': None}
    lock = threading.Lock()

    def json_body():
        if not request.is_json:
            raise ValueError('expected a JSON body (Content-Type: application/json)')
        # a chunked body (no Content-Length) is read up to the limit only: one that
        # reaches it is refused rather than parsed cut
        if len(request.get_data(cache=True)) >= limit and request.content_length is None:
            raise RequestEntityTooLarge()
        body = parse_json_body(request.get_data(cache=True))         # 400 if not JSON
        if not isinstance(body, dict):
            raise ValueError(f'expected a JSON object, got {type(body).__name__}')
        return body

    def body_points():
        body = json_body()
        if 'labels' not in body:
            raise ValueError('expected a JSON body {"labels": {camera: {keypoint: [u, v]}}}')
        return body, session.points_from_json(body['labels'])

    # the longest name a request may carry: NAME_CHARS, or the rig's / skeleton's longest
    name_chars = max([NAME_CHARS, *map(len, session.names), *map(len, session.keypoints)])

    def name_field(body, field, what='a name'):
        value = body.get(field)
        if not isinstance(value, str) or len(value) > name_chars:
            raise ValueError(f'{field}: expected {what} (a string of at most {name_chars} '
                             f'characters), got {short(value)}')
        return value

    @app.before_request
    def check_request():
        refused = guard.refusal(request.method, request.headers.get('Host'),
                                request.headers.get('Origin'),
                                request.headers.get(guard.TOKEN_HEADER), hosts, token)
        if refused is not None:
            return jsonify(error=refused[1]), refused[0]
        if request.content_length is not None and request.content_length > limit:
            raise RequestEntityTooLarge()        # refused before a byte of it is read
        return None

    @app.after_request
    def headers(response):
        response.headers['Content-Security-Policy'] = guard.CSP
        response.headers['X-Content-Type-Options'] = 'nosniff'
        response.headers['Referrer-Policy'] = 'no-referrer'
        return response

    @app.errorhandler(RequestEntityTooLarge)
    def too_large(error):
        discard_body(request.environ['wsgi.input'], request.content_length)
        size = request.content_length
        got = f'{size} bytes' if size is not None else f'a chunked body of {limit}+ bytes'
        return jsonify(error=f'request too large: {got}, the limit is {limit} bytes (1 MiB '
                       'or twice a fully labelled instant of this rig and skeleton)'), 413

    @app.errorhandler(HTTPException)
    def http_error(error):
        return jsonify(error=f'{error.name}: {error.description}'), error.code

    @app.errorhandler(VersionConflict)
    def conflict(error):
        return jsonify(error=str(error), version=error.version,
                       labels=session.points_to_json(error.labels)), 409

    @app.errorhandler(ValueError)
    def bad_request(error):
        return jsonify(error=str(error)), 400

    @app.errorhandler(KeyError)
    @app.errorhandler(IndexError)
    def not_found(error):
        return jsonify(error=str(error.args[0] if error.args else error)), 404

    page = (resources.files('monet_ros.label_app') / 'static' / 'index.html').read_text()
    if TOKEN_MARK not in page:                        # pragma: no cover - packaging fault
        raise RuntimeError('monet_ros/label_app/static/index.html has no token placeholder')
    page = page.replace(TOKEN_MARK, token)

    @app.get('/')
    def index():
        return Response(page, mimetype='text/html', headers={'Cache-Control': 'no-store'})

    @app.get('/static/<path:name>')
    def assets(name):
        return send_from_directory(folder, name)

    @app.get('/api/summary')
    def summary():
        out = session.summary()
        out['labelled'] = session.labelled_instants()
        out['model'] = predictor is not None
        out['subjects'] = [{'id': s, 'name': name} for s, name in session.subjects().items()]
        return jsonify(out)

    @app.get('/api/image/<int:t>/<camera>')
    def image(t, camera):
        data, mimetype = session.image_bytes(t, camera)
        return Response(data, mimetype=mimetype, headers={'Cache-Control': 'max-age=3600'})

    def query_subject():
        text = request.args.get('subject', '0')
        if not (text.isascii() and text.isdigit() and len(text) <= 3):
            raise ValueError(f'subject: expected an integer 0..{MAX_SUBJECT}, got '
                             f'{short(text)}')
        return check_subject(int(text))

    @app.get('/api/labels/<int:t>')
    def get_labels(t):
        subject = query_subject()
        points, version = session.instant_state(t, subject)        # IndexError: 404
        prefill = False
        if subject == 0 and not np.isfinite(points).any():   # the detector: one subject
            pred = {} if predictor is None else predictor.instants([t])
            if t in pred:
                points, prefill = pred[t]['points2d'], True
        others = {str(s): session.points_to_json(session.instant_labels(t, s))
                  for s in session.instant_subjects(t) if s != subject}
        return jsonify(labels=session.points_to_json(points), prefill=prefill,
                       version=version, subject=subject, others=others)

    @app.put('/api/labels/<int:t>')
    def put_labels(t):
        body, points = body_points()
        version = name_field(body, 'version', 'the version of GET /api/labels/<t>')
        subject = check_subject(body.get('subject', 0))
        rows, version = session.set_instant(t, points, version, subject)
        return jsonify(rows=rows, labelled=session.labelled_instants(), version=version)

    @app.post('/api/triangulate')
    def triangulate():
        _, points = body_points()
        result = assist_instant(points, session.cameras, session.config.threshold_px,
                                session.config.flag_px)
        return jsonify(assist_to_json(result, session.names, session.keypoints))

    @app.post('/api/epipolar')
    def epipolar():
        body, points = body_points()
        target = session.cameras[session.camera_index(name_field(body, 'camera'))]
        keypoint = name_field(body, 'keypoint')
        if keypoint not in session.keypoints:
            raise KeyError(f'keypoint {short(keypoint)} is not in the skeleton')
        c = session.keypoints.index(keypoint)
        out = {}
        for j, cam in enumerate(session.cameras):
            if cam.name != target.name and np.isfinite(points[j, c]).all():
                out[cam.name] = epipolar_polyline(cam, points[j, c], target)
        return jsonify(out)

    @app.get('/api/suggest')
    def suggest():
        from monet_ros.label_app.suggest import suggest_from_images, suggest_from_predictions
        with lock:
            cached = state['suggest']
        if cached is not None:
            return jsonify(cached)
        k = session.config.suggestions
        if predictor is not None:
            pred = predictor.subsample(session.config.model_instants)
            out = {'method': 'detector', 'instants': suggest_from_predictions(pred, k),
                   'disagreement': {str(t): (p['error'] if np.isfinite(p['error']) else None)
                                    for t, p in pred.items()}}
        else:
            out = {'method': 'images', 'instants': suggest_from_images(session, k),
                   'disagreement': {}}
        with lock:
            state['suggest'] = out
        return jsonify(out)

    return app
