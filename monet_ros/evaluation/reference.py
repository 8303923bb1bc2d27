"""Accuracy against a reference: 2D labels (any importer format or the labels CSV) and/or
3D points (TRC, anipose CSV), scored in pixels and millimetres (no ROS).

load_reference(path, index, keypoints, ...) -> Reference on the recording's instants:
- 2D sources (labels CSV stamp/frame keyed, dlc, lightning-pose, sleap, anipose, dannce)
  go through the one label validator (monet_ros.labels.resolve_labels); the 3D reference
  is then their triangulation (DLT over the labelled views, >= 2 views);
- TRC: row Frame# N is at (N - 1) / DataRate s after the recording's first instant
  (the recording imported from the same videos from their first frame; the Time column
  is not used: Pose2Sim writes Frame# / DataRate, OpenSim (Frame# - 1) / DataRate); Units
  mm / cm / m converted to the rig's unit; axes='yzx' undoes a Y-up file (Pose2Sim);
- anipose CSV: rows at their stamp_ns when present, else at fnum / reference_fps s after
  the first instant (default: the recording's median frame period); in the rig's unit (as
  anipose writes them), or in the unit of monet's sidecar (export_tables.read_csv_units);
- rows are put on the recording's instants by time (align_rows): at the same rate the
  nearest row within half a frame period; at another rate resampled by linear
  interpolation in time (or refused); rows outside the recording are counted
  (`Reference.alignment`), never paired by index.
Reference keypoints are matched to the model's by name (keypoint_map renames); names the
model lacks are listed in `Reference.unused` and not scored.
Labels of several subjects (the labels CSV's `subject` column, an importer's tracks /
individuals): load_references gives one Reference per subject (its `subject` id, its
labels (T, V, C, 2) px and their triangulation (T, C, 3)); load_reference, one subject,
refuses them (LabelError naming the file, the field subject and --subjects).

score(...) -> dict of figures on the chosen instants: 2D pixel error of detections
(median, mean, PCK@px) on labelled views - for a 3D reference on its projection into
every camera (project_reference) -, 3D error (median, mean, p90 in mm, PCK@mm) and
coverage (fraction of reference joints that were triangulated).
score_subjects(...) -> the same of a several-subject prediction (rows of instant, track
identity, 3D, 2D) against several references: pooled, plus one dict per reference subject
scored against the track matched to it (subjects.metrics.assign_subjects: one-to-one,
least mean 3D distance over the scored instants both have; the track ids are not the
labels' subject numbers).
"""
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from monet_ros.geometry.units import check_units, convert, rig_units, to_mm
from monet_ros.labels import LabelError

PX_THRESHOLDS = (5.0, 10.0, 20.0)
MM_THRESHOLDS = (25.0, 50.0, 100.0)
LABEL_FORMATS = ('labels', 'dlc', 'lightning-pose', 'sleap', 'anipose', 'dannce')


@dataclass
class Reference:
    """source; keypoints (C, the model's order); stamps (T,) recording instants;
    points2d (T, V, C, 2) px: the labels, or for a 3D reference its projection into the
    cameras (project_reference); X (T, C, 3) in `units` (the rig's length unit, NaN =
    none); unused: reference keypoint names the model lacks; kind '2d' (labels, X
    triangulated) or '3d'; alignment: how 3D rows were put on the instants (align_rows'
    info), None for labels; subject: the labels' subject id (0 for a 3D reference and
    labels without a subject column)."""
    source: str
    keypoints: tuple
    stamps: np.ndarray
    points2d: np.ndarray | None
    X: np.ndarray
    kind: str
    unused: tuple = field(default_factory=tuple)
    alignment: dict = None
    units: str = 'm'
    subject: int = 0


def guess_format(path):
    """Reference format from the file: .trc -> trc; .mat -> dannce; .csv -> labels,
    anipose3d or dlc by its header; .h5 -> dlc (SLEAP / anipose 2D need the format)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == '.trc':
        return 'trc'
    if suffix == '.mat':
        return 'dannce'
    if suffix in ('.h5', '.hdf5'):
        return 'dlc'
    if suffix == '.csv':
        try:
            head = path.read_text(encoding='utf-8-sig', errors='replace').split('\n', 1)[0]
        except OSError as error:
            raise LabelError(f'{path}: cannot read ({error.strerror})') from None
        cells = [c.strip() for c in head.split(',')]
        if cells[:2] in (['stamp_ns', 'camera'], ['frame', 'camera']):
            return 'labels'
        if cells and cells[0] == 'scorer':
            return 'dlc'
        if any(c.endswith('_x') for c in cells):
            return 'anipose3d'
    raise LabelError(f'{path}: cannot tell the reference format; give --reference-format')


def _names(ref_names, keypoints, keypoint_map):
    """index map model c -> reference column, and the unused reference names."""
    mapped = [keypoint_map.get(n, n) for n in ref_names]
    columns = {m: i for i, m in enumerate(mapped)}
    pick = [columns.get(k) for k in keypoints]
    unused = tuple(n for n, m in zip(ref_names, mapped) if m not in keypoints)
    if all(p is None for p in pick):
        raise LabelError(f'no reference keypoint ({", ".join(ref_names)}) is a model keypoint '
                         f'({", ".join(keypoints)}); map names with --keypoint-map')
    return pick, unused


def _take(values, pick, shape_tail):
    out = np.full(values.shape[:1] + (len(pick),) + shape_tail, np.nan)
    for c, i in enumerate(pick):
        if i is not None:
            out[:, c] = values[:, i]
    return out


RATE_POLICIES = ('resample', 'refuse')
SAME_RATE = 0.02            # relative period difference within which two rates are one
# (29.97 and 30 Hz are one rate: nearest rows in time follow the drift; 25 and 30 are not)


def _rate_text(period_ns):
    return f'{1e9 / period_ns:.4g} Hz' if period_ns > 0 else 'an unknown rate'


def align_rows(path, ref_stamps, values, stamps, ref_period_ns=None, policy='resample'):
    """Reference rows (3D points at their own times) on the recording's instants.

    ref_stamps (R,) int ns (increasing), values (R, C, 3), stamps (T,) the recording's
    instants. ref_period_ns: the reference's frame period (default: the median of its
    stamp differences). Same rate (periods within 0.1 %): each instant takes the row
    nearest in time within half a recording period ('nearest'). Another rate: policy
    'resample' interpolates linearly in time between the two rows around each instant
    (only rows at most 1.5 reference periods apart; an instant on a row takes it as is;
    a NaN end gives NaN) ('linear'); 'refuse' raises LabelError naming both rates.
    Returns (X (T, C, 3) NaN where no reference, info dict: rule, reference_hz,
    recording_hz, rows, rows_unmatched (rows no instant took for 'nearest'; rows more
    than half a recording period outside the recording's span for 'linear'), instants
    (with a reference value)). Raises LabelError when no row falls on the recording."""
    from monet_ros.labels import frame_period_ns
    ref = np.asarray(ref_stamps, np.int64)
    stamps = np.asarray(stamps, np.int64)
    values = np.asarray(values, float)
    R, T = len(ref), len(stamps)
    rec_period = frame_period_ns(stamps)
    period = int(ref_period_ns) if ref_period_ns else (
        int((ref[-1] - ref[0]) / (R - 1)) if R > 1 else 0)
    if R and np.any(np.diff(ref) <= 0):
        bad = int(np.flatnonzero(np.diff(ref) <= 0)[0]) + 1
        raise LabelError(f'{path}: row {bad + 1}: time {ref[bad]} ns does not follow '
                         f'{ref[bad - 1]} ns (rows must be in time order)')
    if R == 0:
        raise LabelError(f'{path}: no reference row')
    if policy not in RATE_POLICIES:
        raise LabelError(f'reference rate policy must be one of {", ".join(RATE_POLICIES)}, '
                         f'got {policy!r}')
    same = rec_period <= 0 or period <= 0 or abs(period - rec_period) <= SAME_RATE * rec_period
    X = np.full((T,) + values.shape[1:], np.nan)
    half = max(rec_period // 2, 1) if rec_period > 0 else max(period // 2, 1)
    info = dict(reference_hz=1e9 / period if period > 0 else float('nan'),
                recording_hz=1e9 / rec_period if rec_period > 0 else float('nan'), rows=R)
    outside = (ref < stamps[0] - half) | (ref > stamps[-1] + half)
    if outside.all():
        raise LabelError(f'{path}: no reference row falls on the recording (rows '
                         f'{ref[0]} .. {ref[-1]} ns, instants {stamps[0]} .. {stamps[-1]} '
                         'ns)')
    j = np.clip(np.searchsorted(ref, stamps), 1, max(R - 1, 1))
    cand = np.stack([j - 1, np.minimum(j, R - 1)])                  # (2, T) rows around
    dist = np.abs(ref[cand] - stamps[None])
    nearest = cand[np.argmin(dist, axis=0), np.arange(T)]
    near = np.min(dist, axis=0) <= half
    if same:
        X[near] = values[nearest[near]]
        used = np.zeros(R, bool)
        used[nearest[near]] = True
        info.update(rule='nearest', rows_unmatched=int((~used).sum()))
    elif policy == 'refuse':
        raise LabelError(f'{path}: the reference is at {_rate_text(period)}, the recording '
                         f'at {_rate_text(rec_period)}: rows cannot be paired one to one; '
                         'resample it (--reference-rate-mismatch resample) or give a '
                         "reference at the recording's rate")
    else:
        hi = np.searchsorted(ref, stamps, side='right')
        lo = hi - 1
        inside = (lo >= 0) & (hi < R)
        lo_c, hi_c = np.clip(lo, 0, R - 1), np.clip(hi, 0, R - 1)
        gap = ref[hi_c] - ref[lo_c]
        ok = inside & (gap > 0) & (gap <= 1.5 * period)
        w = np.where(ok, (stamps - ref[lo_c]) / np.where(gap > 0, gap, 1), 0.0)
        X[ok] = (1 - w[ok, None, None]) * values[lo_c[ok]] + w[ok, None, None] * values[
            hi_c[ok]]
        on_row = np.min(dist, axis=0) == 0                          # exactly on a row
        X[on_row] = values[nearest[on_row]]
        info.update(rule='linear', rows_unmatched=int(outside.sum()))
    info['instants'] = int(np.isfinite(X).all(-1).any(-1).sum())
    return X, info


def alignment_text(info):
    """One line: how reference rows were put on the recording's instants."""
    if info.get('rule') == 'linear':
        how = (f'{info["reference_hz"]:.4g} Hz resampled to the recording\'s '
               f'{info["recording_hz"]:.4g} Hz by linear interpolation in time between '
               'neighbouring rows')
        unmatched = f'{info["rows_unmatched"]} outside the recording'
    else:
        how = 'rows matched to the nearest instant in time'
        unmatched = f'{info["rows_unmatched"]} on no instant'
    return (f'{how}; {info["rows"]} rows, {unmatched}; {info["instants"]} instants with a '
            'reference')


def project_reference(X, cameras):
    """(T, C, 3) world points (the cameras' unit) -> (T, V, C, 2) pixels: each camera's projection
    (Camera.project, with lens distortion) of the reference, NaN for NaN points, points
    behind the camera and points outside the image (pixel-edge box -0.5 .. size - 0.5).
    Occlusion is not known: every point inside an image counts as seen there."""
    X = np.asarray(X, float)
    T, C = X.shape[:2]
    flat = X.reshape(-1, 3)
    out = np.full((T, len(cameras), C, 2), np.nan)
    for v, cam in enumerate(cameras):            # one batched projection per camera
        with np.errstate(invalid='ignore', divide='ignore'):
            depth = cam.to_camera(flat)[:, 2]
            uv = cam.project(flat)
            inside = (depth > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= cam.width - 0.5) & \
                (uv[:, 1] >= -0.5) & (uv[:, 1] <= cam.height - 0.5)
        out[:, v] = np.where(inside[:, None], uv, np.nan).reshape(T, C, 2)
    return out


def labelled_instants(path, stamps):
    """(T,) bool: instants of the recording (stamps (T,) ns) that a labels CSV (stamp- or
    frame-keyed, monet_ros.labels) labels: a stamp within half a frame period of an
    instant, a frame = an instant index. Rows matching no instant are ignored here (the
    label validator reports them where the labels are used)."""
    from monet_ros.labels import frame_period_ns, read_label_rows
    stamps = np.asarray(stamps, np.int64)
    T = len(stamps)
    out = np.zeros(T, bool)
    rows = read_label_rows(path)
    frames = np.array([r.frame for r in rows if r.frame is not None], np.int64)
    out[frames[(frames >= 0) & (frames < T)]] = True
    keyed = np.array([r.stamp_ns for r in rows if r.stamp_ns is not None], np.int64)
    if len(keyed) and T:
        j = np.clip(np.searchsorted(stamps, keyed), 1, max(T - 1, 1))
        cand = np.stack([j - 1, np.minimum(j, T - 1)])
        dist = np.abs(stamps[cand] - keyed[None])
        best = cand[np.argmin(dist, axis=0), np.arange(len(keyed))]
        half = max(frame_period_ns(stamps) // 2, 1)
        out[best[np.min(dist, axis=0) <= half]] = True
    return out


def load_reference(path, index, keypoints, fmt='auto', options=None, axes='xyz',
                   camera=None, reference_fps=None, rate_policy='resample'):
    """Reference of `path` on the recording `index` (learning.recording_index.RecordingIndex)
    for the model's `keypoints` (module docstring): one subject. options: LabelOptions (name
    maps, skip_bad); reference_fps: rate of an anipose CSV's fnum (default the recording's);
    rate_policy: 'resample' or 'refuse' a 3D reference at another rate (align_rows).
    Raises LabelError (or ExportError) naming the file and what does not fit; labels of
    several subjects (field subject) are refused here: load_references reads them, for a
    model run with several subjects (--subjects N)."""
    references = load_references(path, index, keypoints, fmt, options, axes, camera,
                                 reference_fps, rate_policy)
    if len(references) > 1:
        raise LabelError(f'{path}: field subject: the reference labels hold subjects '
                         f'{", ".join(str(r.subject) for r in references)}; score them '
                         'against a model run with several subjects (--subjects N), or keep '
                         'the rows of one subject (subject 0, no subject column)')
    return references[0]


def load_references(path, index, keypoints, fmt='auto', options=None, axes='xyz',
                    camera=None, reference_fps=None, rate_policy='resample'):
    """[Reference, ...] of `path`, one per subject, in subject order (load_reference's
    arguments and errors): labels with a `subject` column (the labels CSV; an importer's
    tracks / individuals) give one Reference per labelled subject (its `subject` id, its
    labels and their triangulation; T instants each, NaN where it is unlabelled); every
    other reference is one subject (subject 0)."""
    from monet_ros.geometry.triangulation import triangulate
    from monet_ros.io.export_tables import read_anipose_csv, read_csv_units, read_trc
    from monet_ros.labels import LabelOptions, read_label_rows, resolve_labels

    options = options or LabelOptions()
    keypoints = tuple(keypoints)
    kmap = dict(options.keypoint_map)
    fmt = guess_format(path) if fmt == 'auto' else fmt
    stamps = np.asarray(index.stamps, np.int64)
    T, V, C = len(stamps), len(index.cameras), len(keypoints)
    units = rig_units(index.cameras)
    if fmt in ('trc', 'anipose3d'):
        if fmt == 'trc':
            trc = read_trc(path, axes=axes)
            try:
                scale = convert(1.0, check_units(trc['units'].lower()), units)
            except ValueError:
                raise LabelError(f'{path}:3: field Units: {trc["units"]!r}, expected m, cm '
                                 'or mm') from None
            if not (np.isfinite(trc['rate']) and trc['rate'] > 0):
                raise LabelError(f'{path}:3: field DataRate: {trc["rate"]!r}, needed to '
                                 "put the rows on the recording's time")
            names, values = trc['keypoints'], trc['X'] * scale
            period = 1e9 / trc['rate']
            # Frame# 1 is the recording's first instant (Pose2Sim writes Time = Frame# /
            # DataRate, OpenSim (Frame# - 1) / DataRate: the frame number is the one rule)
            ref_stamps = stamps[0] + np.round((trc['frames'] - 1) * period).astype(np.int64)
        else:
            table = read_anipose_csv(path)
            names, values = table['keypoints'], table['X']
            stated = read_csv_units(path)            # monet's sidecar, else the rig's unit
            if stated is not None:
                values = convert(values, stated, units)
            period = 1e9 / reference_fps if reference_fps else None
            if table['stamps_ns'] is not None:
                ref_stamps = table['stamps_ns']
            else:           # fnum at --reference-fps, else at the recording's own rate
                from monet_ros.labels import frame_period_ns
                step = period or frame_period_ns(stamps)
                ref_stamps = stamps[0] + np.round(table['fnum'] * step).astype(np.int64)
        pick, unused = _names(names, keypoints, kmap)
        X, info = align_rows(path, ref_stamps, _take(values, pick, (3,)), stamps,
                             ref_period_ns=period, policy=rate_policy)
        return [Reference(str(path), keypoints, stamps, project_reference(X, index.cameras),
                          X, '3d', unused, info, units)]
    if fmt not in LABEL_FORMATS:
        raise LabelError(f'unknown reference format {fmt!r}; one of trc, anipose3d, '
                         f'{", ".join(LABEL_FORMATS)}')
    if fmt == 'labels':
        rows = read_label_rows(path)
    else:
        from monet_ros.labels_import import import_labels, to_recording_pixels
        rows = import_labels(fmt, path, cameras=[c.name for c in index.cameras],
                             camera=camera, camera_map=dict(options.camera_map)).rows
        # labels of the videos of a resized import: in the recording's pixels
        rows = to_recording_pixels(rows, fmt, index.bag,
                                   camera_map=dict(options.camera_map))[0]
    names = tuple(dict.fromkeys(kmap.get(r.keypoint, r.keypoint) for r in rows))
    unused = tuple(n for n in names if n not in keypoints)
    rows = [r for r in rows if kmap.get(r.keypoint, r.keypoint) in keypoints]
    if not rows:
        raise LabelError(f'{path}: no reference keypoint ({", ".join(names)}) is a model '
                         f'keypoint ({", ".join(keypoints)}); map names with --keypoint-map')
    labels, _ = resolve_labels(rows, stamps, index.cameras, keypoints, options)
    cam_names = [c.name for c in index.cameras]
    where = {int(s): i for i, s in enumerate(stamps)}
    out = []
    for subject in labels.subjects or [0]:
        points2d = np.full((T, V, C, 2), np.nan)
        for s in labels.stamps:
            points2d[where[int(s)]] = labels.points(s, cam_names, subject)
        X = np.full((T, C, 3), np.nan)
        labelled = np.flatnonzero(np.isfinite(points2d[..., 0]).any(axis=(1, 2)))
        for t in labelled:
            X[t] = triangulate(points2d[t], index.cameras)
        out.append(Reference(str(path), keypoints, stamps, points2d, X, '2d', unused,
                             units=units, subject=int(subject)))
    return out


def _pct(values, thresholds):
    values = values[np.isfinite(values)]
    return {t: (float((values <= t).mean()) if values.size else float('nan'))
            for t in thresholds}


def _on_instants(reference, stamps, X, points2d, instants):
    """(ref_X, pred_X (T, C, 3), ref2, pred2 (T, V, C, 2) or None) on the reference's T
    instants: the prediction at its stamps (others NaN), the reference outside `instants`
    NaN (score's arguments)."""
    keep_t = np.ones(len(reference.stamps), bool) if instants is None else \
        np.asarray(instants, bool)
    where = {int(s): i for i, s in enumerate(reference.stamps)}
    rows = np.array([where.get(int(s), -1) for s in stamps], np.int64)
    keep = rows >= 0
    pred_X = np.full(reference.X.shape, np.nan)
    pred_X[rows[keep]] = np.asarray(X, float)[keep]
    ref_X = np.where(keep_t[:, None, None], reference.X, np.nan)
    if reference.points2d is None or points2d is None:
        return ref_X, pred_X, None, None
    pred2 = np.full(reference.points2d.shape, np.nan)
    pred2[rows[keep]] = np.asarray(points2d, float)[keep]
    ref2 = np.where(keep_t[:, None, None, None], reference.points2d, np.nan)
    return ref_X, pred_X, ref2, pred2


def _figures(reference, ref_X, pred_X, ref2, pred2, px_thresholds, mm_thresholds):
    """score's dict of arrays with a leading subject axis: ref_X, pred_X (S, T, C, 3),
    ref2, pred2 (S, T, V, C, 2) or None. instants_scored counts instants with a reference
    of any subject; joints_3d and views_2d count every subject's."""
    has_ref = np.isfinite(ref_X).all(-1)
    has_pred = np.isfinite(pred_X).all(-1)
    mm = to_mm(np.linalg.norm(pred_X - ref_X, axis=-1)[has_ref & has_pred], reference.units)
    out = dict(reference=reference.source, kind=reference.kind,
               instants_scored=int(has_ref.any(-1).any(0).sum()), joints_3d=int(has_ref.sum()),
               coverage=float((has_ref & has_pred).sum() / has_ref.sum()) if has_ref.any()
               else float('nan'),
               mm_median=float(np.median(mm)) if mm.size else float('nan'),
               mm_mean=float(mm.mean()) if mm.size else float('nan'),
               mm_p90=float(np.percentile(mm, 90)) if mm.size else float('nan'))
    for t, v in _pct(mm, mm_thresholds).items():
        out[f'pck3d@{t:g}mm'] = v
    if ref2 is not None:
        labelled = np.isfinite(ref2).all(-1)
        px_all = np.linalg.norm(pred2 - ref2, axis=-1)[labelled]
        # a labelled view without a detection is a miss: infinitely far
        px = np.where(np.isfinite(px_all), px_all, np.inf)
        out.update(points2d_from='projection' if reference.kind == '3d' else 'labels',
                   views_2d=int(labelled.sum()),
                   px_median=float(np.median(px)) if px.size else float('nan'),
                   px_mean=float(px[np.isfinite(px)].mean()) if np.isfinite(px).any()
                   else float('nan'))
        for t in px_thresholds:
            out[f'pck2d@{t:g}px'] = float((px <= t).mean()) if px.size else float('nan')
    return out


def score(reference, stamps, X, points2d=None, px_thresholds=PX_THRESHOLDS,
          mm_thresholds=MM_THRESHOLDS, instants=None):
    """Figures of a prediction against a Reference. stamps (N,) of the predicted instants
    (a subset of the reference's); X (N, C, 3) in reference.units (the rig's; the 3D
    errors are reported in mm whatever the unit); points2d (N, V, C, 2) source px;
    instants: (T,) bool of the reference's instants to score (default all). An instant /
    joint the prediction lacks (not processed, or not triangulated) counts against
    coverage, not in the error statistics. 2D figures are on the labelled views, or for a
    3D reference on its projection into every camera (points2d_from says which)."""
    arrays = _on_instants(reference, stamps, X, points2d, instants)
    return _figures(reference, *(None if a is None else a[None] for a in arrays),
                    px_thresholds, mm_thresholds)


def score_subjects(references, stamps, ids, X, points2d=None, px_thresholds=PX_THRESHOLDS,
                   mm_thresholds=MM_THRESHOLDS, instants=None):
    """Figures of a several-subject prediction (rows: one per instant and track) against
    references of several subjects (load_references; on the same T instants). stamps (R,)
    ns, ids (R,) int track identities, X (R, C, 3) in the references' unit, points2d
    (R, V, C, 2) px or None; instants: (T,) bool, as score's.

    Track identities are not the references' subject numbers: each reference subject is
    matched to one track by subjects.metrics.assign_subjects over the scored instants (the
    one-to-one assignment minimising the sum of the pairs' mean 3D distance over the
    instants both have, the mean over their common keypoints). Returns score's dict of
    the pooled figures (every subject's joints and views; an unmatched subject's are
    misses: coverage, and 2D at infinite distance) with `subjects`: one dict per reference
    subject, in order: subject (its id), track (the matched identity, -1 = none),
    match_mm (the pair's mean 3D distance, mm; NaN for none) and score's figures of that
    subject against that track alone."""
    from monet_ros.subjects.metrics import assign_subjects
    references = list(references)
    ref = references[0]
    T = len(ref.stamps)
    stamps, ids = np.asarray(stamps, np.int64), np.asarray(ids, np.int64)
    X = np.asarray(X, float).reshape(len(stamps), len(ref.keypoints), 3)
    uids = np.unique(ids)
    where = {int(s): i for i, s in enumerate(ref.stamps)}
    rows = np.array([where.get(int(s), -1) for s in stamps], np.int64)
    on = rows >= 0
    tracks = np.full((T, len(uids)) + X.shape[1:], np.nan)          # (T, H, C, 3)
    col = np.searchsorted(uids, ids)
    tracks[rows[on], col[on]] = X[on]
    track_ids = np.where(np.isfinite(tracks).all(-1).any(-1), uids[None], -1)
    keep_t = np.ones(T, bool) if instants is None else np.asarray(instants, bool)
    gt = np.stack([np.where(keep_t[:, None, None], r.X, np.nan) for r in references], 1)
    matched, distance = assign_subjects(gt, tracks, track_ids)
    per, arrays = [], []
    for r, track, d in zip(references, matched, distance):
        mine = ids == track
        a = _on_instants(r, stamps[mine], X[mine],
                         None if points2d is None else np.asarray(points2d, float)[mine],
                         instants)
        arrays.append(a)
        figures = _figures(r, *(None if x is None else x[None] for x in a), px_thresholds,
                           mm_thresholds)
        per.append(dict(subject=r.subject, track=int(track),
                        match_mm=float(to_mm(d, r.units)), **figures))
    pooled = _figures(ref, *(None if arrays[0][k] is None else np.stack([a[k] for a in arrays])
                             for k in range(4)), px_thresholds, mm_thresholds)
    pooled['subjects'] = per
    return pooled
