"""The web app of `monet label` (Flask): the page in static/ and a JSON API.

    GET  /                         the page (static/index.html; every asset ships here)
    GET  /api/summary              cameras (name, width, height, K, dist, R, t), instants
                                   (index, stamp_ns as a string, complete, views),
                                   keypoints, bones, labels path, flag_px
    GET  /api/image/<t>/<camera>   the view's image (JPEG / PNG)
    GET  /api/labels/<t>           {labels: {camera: {keypoint: [u, v]}}, prefill: bool}
    PUT  /api/labels/<t>           body {labels: ...}: replaces the instant's labels and
                                   saves the table (atomic); -> {rows, labelled}
    POST /api/triangulate          body {labels: ...}: -> {keypoint: {X, robust, views:
                                   {camera: {ghost [u, v], error px, flagged}}}}
    POST /api/epipolar             body {camera, keypoint, labels}: -> {camera: [polyline,
                                   ...]} the epipolar curves, in `camera`, of the
                                   keypoint's clicks in the other views
    GET  /api/suggest              {method: 'detector' | 'images', instants: [t, ...],
                                   disagreement: {t: px} (detector only)}

Errors are JSON {error: message} with status 400 (bad request) or 404 (no such instant,
camera or keypoint).
"""
from importlib import resources
import threading

from flask import Flask, Response, jsonify, request, send_from_directory
import numpy as np

from monet_ros.label_app.assist import assist_instant, assist_to_json, epipolar_polyline


def static_folder():
    """Folder of the page's assets inside the installed package."""
    return str(resources.files('monet_ros.label_app') / 'static')


def create_app(session, predictor=None):
    """Flask app serving `session` (a LabelSession). predictor: a suggest.Predictor (the
    detector of --model) for suggestions, pre-fill and disagreement: an unlabelled
    instant's peaks are computed when it is opened, the subsample of suggestions on the
    first /api/suggest."""
    app = Flask('monet_label', static_folder=None)
    folder = static_folder()
    state = {'suggest': None}
    lock = threading.Lock()

    def body_points():
        body = request.get_json(silent=True)
        if not isinstance(body, dict) or 'labels' not in body:
            raise ValueError('expected a JSON body {"labels": {camera: {keypoint: [u, v]}}}')
        return body, session.points_from_json(body['labels'])

    @app.errorhandler(ValueError)
    def bad_request(error):
        return jsonify(error=str(error)), 400

    @app.errorhandler(KeyError)
    @app.errorhandler(IndexError)
    def not_found(error):
        return jsonify(error=str(error.args[0] if error.args else error)), 404

    @app.get('/')
    def index():
        return send_from_directory(folder, 'index.html')

    @app.get('/static/<path:name>')
    def assets(name):
        return send_from_directory(folder, name)

    @app.get('/api/summary')
    def summary():
        out = session.summary()
        out['labelled'] = session.labelled_instants()
        out['model'] = predictor is not None
        return jsonify(out)

    @app.get('/api/image/<int:t>/<camera>')
    def image(t, camera):
        data, mimetype = session.image_bytes(t, camera)
        return Response(data, mimetype=mimetype, headers={'Cache-Control': 'max-age=3600'})

    @app.get('/api/labels/<int:t>')
    def get_labels(t):
        points = session.instant_labels(t)
        prefill = False
        if not np.isfinite(points).any():
            session.instant(t)                             # IndexError: 404
            pred = {} if predictor is None else predictor.instants([t])
            if t in pred:
                points, prefill = pred[t]['points2d'], True
        return jsonify(labels=session.points_to_json(points), prefill=prefill)

    @app.put('/api/labels/<int:t>')
    def put_labels(t):
        _, points = body_points()
        rows = session.set_instant(t, points)
        return jsonify(rows=rows, labelled=session.labelled_instants())

    @app.post('/api/triangulate')
    def triangulate():
        _, points = body_points()
        result = assist_instant(points, session.cameras, session.config.threshold_px,
                                session.config.flag_px)
        return jsonify(assist_to_json(result, session.names, session.keypoints))

    @app.post('/api/epipolar')
    def epipolar():
        body, points = body_points()
        target = session.cameras[session.camera_index(str(body.get('camera')))]
        keypoint = body.get('keypoint')
        if keypoint not in session.keypoints:
            raise KeyError(f'keypoint {keypoint!r} is not in the skeleton')
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
