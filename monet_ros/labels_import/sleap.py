"""SLEAP analysis HDF5 (File > Export Analysis HDF5, `sleap-convert --format analysis`) and
SLEAP project / prediction files (.slp; read_slp below).

Published layout (datasets stored column-major for MATLAB, so h5py reads the transpose
of the documented shapes):
- tracks: documented (frames, nodes, 2, tracks) -> read (tracks, 2, nodes, frames), pixels,
  NaN where a node is missing;
- track_occupancy: documented (tracks, frames) -> read (frames, tracks), nonzero where a
  track has an instance;
- node_names (nodes,), track_names (tracks,): byte strings;
- point_scores: documented (frames, nodes, tracks) -> read (tracks, nodes, frames);
  optional, used by --min-score and as the detection score of `monet triangulate`; a NaN
  score of a present point (e.g. a user-placed point) is no score: the point is kept;
- video_path: the video the file belongs to (its name gives the camera).
The frame axis is the video's frame index; its length is the file's frame count (the
video's), even when the animal is missing from the last frames. With several tracks each
track is a subject (labels_import: ids by track name, in order of first appearance over
the files) and the keypoint is the node; `monet triangulate` names it '<track>/<node>'.
"""
import json
from pathlib import Path

import numpy as np

from monet_ros.labels import LabelError, LabelRow
from monet_ros.labels_import import ImportResult, camera_for, join_notes, subject_note


def open_hdf5(path):
    """h5py.File(path, 'r'), or LabelError naming the file when it is not HDF5."""
    import h5py
    try:
        return h5py.File(path, 'r')
    except (OSError, ValueError) as error:
        raise LabelError(f'{path}: cannot open as HDF5 ({error})') from None

def _text(value):
    if isinstance(value, np.ndarray):
        value = value.item() if value.size == 1 else value.ravel()[0]
    return value.decode('utf-8', 'replace') if isinstance(value, bytes) else str(value)


def _numbers(f, key, path):
    """Field `key` of an open analysis file as float64; LabelError naming the file and
    field when it holds no numbers (strings, objects)."""
    try:
        return np.asarray(f[key][()], dtype=np.float64)
    except (ValueError, TypeError) as error:
        raise LabelError(f'{path}: field {key}: not numbers ({error})') from None


def read_sleap(path, cameras=(), camera=None, min_score=0.0, camera_map=None, ids=None):
    """(rows, keypoints, dropped, frames) of one SLEAP analysis HDF5 file: LabelRow list,
    keypoint names ('<track>/<node>' with several tracks), points below min_score left out,
    the file's frame count. An entry without a position (NaN / inf, or its track not
    occupied in the frame) is a row with u = v = NaN (labels_import's missing points).
    With several tracks a row's keypoint is the node, its instance the track name and its
    subject the name's id in `ids` ({name: id}, filled in order of first appearance).
    Raises LabelError naming the file and field."""
    ids = {} if ids is None else ids
    with open_hdf5(path) as f:
        for key in ('tracks', 'node_names'):
            if key not in f:
                raise LabelError(f'{path}: field {key}: missing; not a SLEAP analysis file '
                                 f'(has {", ".join(sorted(f.keys()))})')
        tracks = _numbers(f, 'tracks', path)
        nodes = [_text(n) for n in f['node_names'][()]]
        if tracks.ndim != 4 or tracks.shape[1] != 2 or tracks.shape[2] != len(nodes):
            raise LabelError(f'{path}: field tracks: shape {tracks.shape}, expected (tracks, 2,'
                             f' {len(nodes)} nodes, frames) as SLEAP writes it')
        n_tracks, _, _, n_frames = tracks.shape
        occupancy = np.ones((n_frames, n_tracks), bool)
        if 'track_occupancy' in f:
            occupancy = _numbers(f, 'track_occupancy', path).astype(bool)
            if occupancy.shape != (n_frames, n_tracks):
                raise LabelError(f'{path}: field track_occupancy: shape {occupancy.shape}, '
                                 f'expected ({n_frames}, {n_tracks})')
        scores = None
        if 'point_scores' in f:
            scores = _numbers(f, 'point_scores', path)
            if scores.shape != (n_tracks, len(nodes), n_frames):
                raise LabelError(f'{path}: field point_scores: shape {scores.shape}, '
                                 f'expected ({n_tracks}, {len(nodes)}, {n_frames})')
        names = [_text(n) for n in f['track_names'][()]] if 'track_names' in f else []
        video = _text(f['video_path'][()]) if 'video_path' in f else ''
    if names and len(names) != n_tracks:    # ids follow names: never a silent renaming
        raise LabelError(f'{path}: field track_names: {len(names)} names for the {n_tracks} '
                         'tracks of field tracks')
    names = names or [f'track_{i}' for i in range(n_tracks)]
    cam = camera_for(Path(video).stem if video else Path(path).stem, cameras, camera,
                     camera_map)
    if cam not in cameras and video:
        by_file = camera_for(Path(path).stem, cameras, camera, camera_map)
        cam = by_file if by_file in cameras else cam
    keypoints = [n if n_tracks == 1 else f'{t}/{n}' for t in names for n in nodes]
    # (tracks, 2, nodes, frames) -> (frames, tracks, nodes, 2)
    points = tracks.transpose(3, 0, 2, 1)
    ok = np.isfinite(points).all(-1) & occupancy[:, :, None]
    dropped = 0
    score = scores.transpose(2, 0, 1) if scores is not None else None   # (frames, tracks, nodes)
    if score is not None and min_score > 0:
        low = ok & ~(score >= min_score) & ~np.isnan(score)     # NaN: no score, kept
        dropped = int(low.sum())
        ok &= ~low
    several = n_tracks > 1
    subject = [ids.setdefault(n, len(ids)) if several else 0 for n in names]
    rows = []
    missing = ~(np.isfinite(points).all(-1) & occupancy[:, :, None])
    for frame, track, node in zip(*np.nonzero(ok | missing)):
        if missing[frame, track, node]:     # a row without a position (labels_import)
            u = v = s = np.nan
        else:
            u, v = points[frame, track, node]
            s = None if score is None else float(score[frame, track, node])
        rows.append(LabelRow(str(path), int(frame) + 1, None, int(frame), cam,
                             nodes[node], float(u), float(v),
                             f'frame {frame} track {names[track]} node {nodes[node]}',
                             None if s is None or np.isnan(s) else s,
                             subject=subject[track], instance=names[track] if several else ''))
    return rows, tuple(keypoints), dropped, n_frames


SLP_INSTANCE_USER = 0          # instances.instance_type: 0 user-labelled, 1 predicted


def _slp_json(value):
    return json.loads(value.decode('utf-8') if isinstance(value, bytes) else str(value))


def read_slp(path, cameras=(), camera=None, min_score=0.0, camera_map=None, ids=None):
    """(rows, keypoints, dropped, None) of one SLEAP .slp file (HDF5; SLEAP's layout, format
    1.x):
    - metadata attribute json: nodes [{name}], skeletons [{nodes: [{id: index into
      nodes}]}]: an instance's points are in its skeleton's node order;
    - videos_json: one JSON per video, backend.filename (its name gives the camera);
      tracks_json: one JSON [spawned_on, name] per track;
    - frames (frame_id, video, frame_idx, instance_id_start, instance_id_end);
    - instances (instance_id, instance_type 0 user / 1 predicted, frame_id, skeleton, track
      (-1: none), from_predicted, score, point_id_start, point_id_end);
    - points (user: x, y, visible, complete) and pred_points (+ score): pixels, NaN or
      visible False where a node is not placed (a row with u = v = NaN: labels_import's
      missing points).
    A predicted instance that a user instance of the frame was made from (from_predicted) is
    left out: the user's correction wins. Tracks are subjects as in the analysis file (ids by
    track name); two instances without a track in one frame of a camera are an error (their
    identity across cameras is unknown: assign tracks in SLEAP). The frame count is not in
    the file (None). Raises LabelError naming the file and field."""
    ids = {} if ids is None else ids
    with open_hdf5(path) as f:
        for key in ('frames', 'instances', 'metadata'):
            if key not in f:
                raise LabelError(f'{path}: field {key}: missing; not a SLEAP .slp file (has '
                                 f'{", ".join(sorted(f.keys()))})')
        try:
            meta = _slp_json(f['metadata'].attrs['json'])
            names = [str(n['name']) for n in meta['nodes']]
            skeletons = [[names[int(n['id'])] for n in sk['nodes']] for sk in meta['skeletons']]
            videos = [_slp_json(v).get('backend', {}).get('filename', '')
                      for v in f['videos_json'][()]] if 'videos_json' in f else []
            tracks = [str(_slp_json(t)[1]) for t in f['tracks_json'][()]] \
                if 'tracks_json' in f else []
        except (KeyError, IndexError, TypeError, ValueError) as error:
            raise LabelError(f"{path}: field metadata: not SLEAP's skeleton / video / track "
                             f'JSON ({type(error).__name__}: {error})') from None
        frames = f['frames'][()]
        instances = f['instances'][()]
        user = f['points'][()] if 'points' in f else None
        pred = f['pred_points'][()] if 'pred_points' in f else None
    several = len(tracks) > 1
    subject = [ids.setdefault(t, len(ids)) if several else 0 for t in tracks]
    cams = [camera_for(Path(str(v).replace('\\', '/')).stem if v else Path(path).stem,
                       cameras, camera, camera_map) for v in videos]
    replaced = {int(i['from_predicted']) for i in instances
                if i['instance_type'] == SLP_INSTANCE_USER and i['from_predicted'] >= 0}
    rows, dropped, seen = [], 0, {}
    for i in instances:
        if int(i['instance_id']) in replaced:
            continue
        frame = frames[int(i['frame_id'])]
        t, video, track = int(frame['frame_idx']), int(frame['video']), int(i['track'])
        cam = cams[video] if video < len(cams) else camera_for(Path(path).stem, cameras,
                                                                camera, camera_map)
        is_user = i['instance_type'] == SLP_INSTANCE_USER
        table = user if is_user else pred
        where = f'frame {t} video {video} instance {int(i["instance_id"])}'
        if table is None or not 0 <= int(i['skeleton']) < len(skeletons) or \
                track >= len(tracks):
            raise LabelError(f'{path}: {where}: field instances: refers to a missing '
                             'points table, skeleton or track')
        if track < 0:
            key = (cam, t)
            if key in seen:
                raise LabelError(f'{path}: {where}: field track: two instances without a '
                                 f'track in frame {t} of camera {cam} (also instance '
                                 f'{seen[key]}): assign tracks in SLEAP so that each animal '
                                 'is one subject')
            seen[key] = int(i['instance_id'])
        nodes = skeletons[int(i['skeleton'])]
        pts = table[int(i['point_id_start']):int(i['point_id_end'])]
        track_name = tracks[track] if track >= 0 and several else ''
        for node, point in zip(nodes, pts):
            u, v = float(point['x']), float(point['y'])
            score = None if is_user or 'score' not in pts.dtype.names \
                else float(point['score'])
            if not (point['visible'] and np.isfinite(u) and np.isfinite(v)):
                u = v = score = np.nan      # a row without a position (labels_import)
            if score is not None and np.isnan(score):
                score = None
            if score is not None and min_score > 0 and not score >= min_score:
                dropped += 1
                continue
            rows.append(LabelRow(str(path), t + 1, None, t, cam, node, u, v,
                                 f'{where} node {node}', score,
                                 subject=subject[track] if track_name else 0,
                                 instance=track_name))
    nodes = list(dict.fromkeys(n for sk in skeletons for n in sk))
    keypoints = [f'{t}/{n}' for t in tracks for n in nodes] if several else nodes
    return rows, tuple(keypoints), dropped, None


def import_sleap(paths, cameras=(), camera=None, min_score=0.0, camera_map=None):
    """ImportResult of SLEAP analysis .h5 and .slp files or folders (a folder: its .h5 /
    .hdf5 files, or its .slp files when it has none)."""
    files = []
    for p in paths:
        if p.is_dir():
            found = sorted(p.rglob('*.h5')) + sorted(p.rglob('*.hdf5'))
            files += found or sorted(p.rglob('*.slp'))
        else:
            files.append(p)
    if not files:
        raise LabelError(f'{", ".join(map(str, paths))}: no SLEAP analysis .h5 or .slp file '
                         'found')
    rows, keypoints, dropped, counts, ids = [], {}, 0, {}, {}
    for f in files:
        read = read_slp if f.suffix.lower() == '.slp' else read_sleap
        r, k, d, n = read(f, cameras, camera, min_score, camera_map, ids)
        rows += r
        keypoints.update(dict.fromkeys(k))
        dropped += d
        if n is not None:
            counts[str(f)] = n
    note = join_notes(f'{dropped} points below --min-score {min_score} left out'
                      if dropped else '', subject_note(ids, 'SLEAP tracks'))
    plain = tuple(dict.fromkeys(k.split('/', 1)[-1] for k in keypoints)) if ids \
        else tuple(keypoints)
    return ImportResult(rows, plain, note, counts, ids, tuple(keypoints) if ids else ())
