"""Accuracy against a reference: 2D labels (any importer format or the labels CSV) and/or
3D points (TRC, anipose CSV), scored in pixels and millimetres (no ROS).

load_reference(path, index, keypoints, ...) -> Reference on the recording's instants:
- 2D sources (labels CSV stamp/frame keyed, dlc, lightning-pose, sleap, anipose, dannce)
  go through the one label validator (monet_ros.labels.resolve_labels); the 3D reference
  is then their triangulation (DLT over the labelled views, >= 2 views);
- TRC: Frame# N (1-based) is instant N-1 of the recording (the recording imported from
  the same videos from their first frame); Units mm / cm / m converted to metres;
  axes='yzx' undoes a Y-up file (Pose2Sim);
- anipose CSV: rows matched by stamp_ns when present (nearest instant within half a
  frame period), else fnum = instant index.
Reference keypoints are matched to the model's by name (keypoint_map renames); names the
model lacks are listed in `Reference.unused` and not scored.

score(...) -> dict of figures: 2D pixel error of detections (median, mean, PCK@px) on
labelled views, 3D error (median, mean, p90 in mm, PCK@mm) and coverage (fraction of
reference joints that were triangulated).
"""
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from monet_ros.labels import LabelError

PX_THRESHOLDS = (5.0, 10.0, 20.0)
MM_THRESHOLDS = (25.0, 50.0, 100.0)
UNITS = {'m': 1.0, 'mm': 1e-3, 'cm': 1e-2}
LABEL_FORMATS = ('labels', 'dlc', 'lightning-pose', 'sleap', 'anipose', 'dannce')


@dataclass
class Reference:
    """source; keypoints (C, the model's order); stamps (T,) recording instants;
    points2d (T, V, C, 2) px or None; X (T, C, 3) metres (NaN = none); unused: reference
    keypoint names the model lacks; kind '2d' (labels, X triangulated) or '3d'."""
    source: str
    keypoints: tuple
    stamps: np.ndarray
    points2d: np.ndarray | None
    X: np.ndarray
    kind: str
    unused: tuple = field(default_factory=tuple)


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


def _instants_3d(path, frames, stamps_ref, stamps):
    """Instant index per reference row (frames 0-based, or stamps matched nearest)."""
    from monet_ros.labels import frame_period_ns
    T = len(stamps)
    if stamps_ref is not None:
        tol = frame_period_ns(stamps) // 2
        j = np.clip(np.searchsorted(stamps, stamps_ref), 1, max(T - 1, 1))
        cand = np.stack([j - 1, np.minimum(j, T - 1)])
        d = np.abs(stamps[cand] - stamps_ref[None])
        best = cand[np.argmin(d, axis=0), np.arange(len(stamps_ref))]
        bad = np.flatnonzero(np.min(d, axis=0) > tol)
        if len(bad):
            raise LabelError(f'{path}:{bad[0] + 2}: field stamp_ns: {stamps_ref[bad[0]]} '
                             f'matches no instant of the recording ({len(bad)} rows)')
        return best
    bad = np.flatnonzero((frames < 0) | (frames >= T))
    if len(bad):
        raise LabelError(f'{path}: frame {frames[bad[0]]} (row {bad[0] + 1}) is not an instant '
                         f'of the recording (0 .. {T - 1}; {len(bad)} rows)')
    return frames


def load_reference(path, index, keypoints, fmt='auto', options=None, axes='xyz',
                   camera=None):
    """Reference of `path` on the recording `index` (commands.info.RecordingIndex) for the
    model's `keypoints` (module docstring). options: LabelOptions (name maps, skip_bad).
    Raises LabelError (or ExportError) naming the file and what does not fit."""
    from monet_ros.geometry.triangulation import triangulate
    from monet_ros.io.export_tables import read_anipose_csv, read_trc
    from monet_ros.labels import LabelOptions, read_label_rows, resolve_labels

    options = options or LabelOptions()
    keypoints = tuple(keypoints)
    kmap = dict(options.keypoint_map)
    fmt = guess_format(path) if fmt == 'auto' else fmt
    stamps = np.asarray(index.stamps, np.int64)
    T, V, C = len(stamps), len(index.cameras), len(keypoints)
    if fmt in ('trc', 'anipose3d'):
        if fmt == 'trc':
            trc = read_trc(path, axes=axes)
            scale = UNITS.get(trc['units'].lower())
            if scale is None:
                raise LabelError(f'{path}:3: field Units: {trc["units"]!r}, expected m, cm '
                                 'or mm')
            names, values, rows = trc['keypoints'], trc['X'] * scale, trc['frames'] - 1
            at = _instants_3d(path, rows, None, stamps)
        else:
            table = read_anipose_csv(path)
            names, values = table['keypoints'], table['X']
            at = _instants_3d(path, table['fnum'], table['stamps_ns'], stamps)
        pick, unused = _names(names, keypoints, kmap)
        X = np.full((T, C, 3), np.nan)
        X[at] = _take(values, pick, (3,))
        return Reference(str(path), keypoints, stamps, None, X, '3d', unused)
    if fmt not in LABEL_FORMATS:
        raise LabelError(f'unknown reference format {fmt!r}; one of trc, anipose3d, '
                         f'{", ".join(LABEL_FORMATS)}')
    if fmt == 'labels':
        rows = read_label_rows(path)
    else:
        from monet_ros.labels_import import import_labels
        rows = import_labels(fmt, path, cameras=[c.name for c in index.cameras],
                             camera=camera, camera_map=dict(options.camera_map)).rows
    names = tuple(dict.fromkeys(kmap.get(r.keypoint, r.keypoint) for r in rows))
    unused = tuple(n for n in names if n not in keypoints)
    rows = [r for r in rows if kmap.get(r.keypoint, r.keypoint) in keypoints]
    if not rows:
        raise LabelError(f'{path}: no reference keypoint ({", ".join(names)}) is a model '
                         f'keypoint ({", ".join(keypoints)}); map names with --keypoint-map')
    labels, _ = resolve_labels(rows, stamps, index.cameras, keypoints, options)
    cam_names = [c.name for c in index.cameras]
    points2d = np.full((T, V, C, 2), np.nan)
    where = {int(s): i for i, s in enumerate(stamps)}
    for s in labels.stamps:
        points2d[where[int(s)]] = labels.points(s, cam_names)
    X = np.full((T, C, 3), np.nan)
    labelled = np.flatnonzero(np.isfinite(points2d[..., 0]).any(axis=(1, 2)))
    for t in labelled:
        X[t] = triangulate(points2d[t], index.cameras)
    return Reference(str(path), keypoints, stamps, points2d, X, '2d', unused)


def _pct(values, thresholds):
    values = values[np.isfinite(values)]
    return {t: (float((values <= t).mean()) if values.size else float('nan'))
            for t in thresholds}


def score(reference, stamps, X, points2d=None, px_thresholds=PX_THRESHOLDS,
          mm_thresholds=MM_THRESHOLDS):
    """Figures of a prediction against a Reference. stamps (N,) of the predicted instants
    (a subset of the reference's); X (N, C, 3) metres; points2d (N, V, C, 2) source px.
    An instant / joint the prediction lacks (not processed, or not triangulated) counts
    against coverage, not in the error statistics."""
    where = {int(s): i for i, s in enumerate(reference.stamps)}
    rows = np.array([where.get(int(s), -1) for s in stamps])
    keep = rows >= 0
    ref_X = np.full((len(reference.stamps),) + reference.X.shape[1:], np.nan)
    pred_X = ref_X.copy()
    pred_X[rows[keep]] = np.asarray(X, float)[keep]
    ref_X[:] = reference.X
    has_ref = np.isfinite(ref_X).all(-1)
    has_pred = np.isfinite(pred_X).all(-1)
    mm = np.linalg.norm(pred_X - ref_X, axis=-1)[has_ref & has_pred] * 1000.0
    out = dict(reference=reference.source, kind=reference.kind,
               joints_3d=int(has_ref.sum()),
               coverage=float((has_ref & has_pred).sum() / has_ref.sum()) if has_ref.any()
               else float('nan'),
               mm_median=float(np.median(mm)) if mm.size else float('nan'),
               mm_mean=float(mm.mean()) if mm.size else float('nan'),
               mm_p90=float(np.percentile(mm, 90)) if mm.size else float('nan'))
    for t, v in _pct(mm, mm_thresholds).items():
        out[f'pck3d@{t:g}mm'] = v
    if reference.points2d is not None and points2d is not None:
        pred2 = np.full(reference.points2d.shape, np.nan)
        pred2[rows[keep]] = np.asarray(points2d, float)[keep]
        ref2 = reference.points2d
        labelled = np.isfinite(ref2).all(-1)
        px_all = np.linalg.norm(pred2 - ref2, axis=-1)[labelled]
        # a labelled view without a detection is a miss: infinitely far
        px = np.where(np.isfinite(px_all), px_all, np.inf)
        out.update(views_2d=int(labelled.sum()),
                   px_median=float(np.median(px)) if px.size else float('nan'),
                   px_mean=float(px[np.isfinite(px)].mean()) if np.isfinite(px).any()
                   else float('nan'))
        for t in px_thresholds:
            out[f'pck2d@{t:g}px'] = float((px <= t).mean()) if px.size else float('nan')
    return out
