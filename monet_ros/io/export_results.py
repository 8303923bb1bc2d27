"""Collect the per-frame results of offline processing and write them as analysis files
beside the recording output (no ROS): anipose CSV and TRC (export_tables), NWB with
ndx-pose (export_nwb) and the 2D detections with their crop cameras (detections2d.npz).

detections2d.npz: stamps_ns (T,), fnum (T,) frame numbers (the CSV's), cameras (V,),
keypoints (C,), points2d (T, V, C, 2) decoded peaks in SOURCE image pixels (NaN = view
missing or below the confidence threshold), confidence (T, V, C) heatmap peak values,
inliers (T, V, C) bool (views used by the triangulation), K_heat (T, V, 3, 3) the
heatmap's virtual camera (crop + scale of the source camera: K_heat = S K, NaN where the
view is missing), heat_size (2,) (w, h).
With the rig, points2d and K_heat let 2D accuracy be scored against labels.

write_results(...) writes the same files from arrays (`monet triangulate`); with a
temporal.Smoothed (`--filter`) csv / trc / nwb hold the filtered points.
"""
import os
from pathlib import Path

import numpy as np

FORMATS = ('csv', 'trc', 'nwb', 'npz')
FILE_NAMES = {'csv': 'keypoints3d.csv', 'trc': 'keypoints3d.trc', 'nwb': 'keypoints.nwb',
              'npz': 'detections2d.npz'}


def parse_formats(text):
    """'csv,trc' -> ('csv', 'trc'); '' or 'none' -> (); ValueError naming a bad one."""
    items = tuple(t.strip() for t in str(text).split(',') if t.strip())
    if items in ((), ('none',)):
        return ()
    bad = [t for t in items if t not in FORMATS]
    if bad:
        raise ValueError(f'--export: unknown format {bad[0]!r}; one of {", ".join(FORMATS)}')
    return items


class ResultsCollector:
    """Per-frame FusionResults of V cameras (names fixed at construction) and C keypoints."""

    def __init__(self, cameras, keypoints):
        self.cameras = list(cameras)
        self.names = [c.name for c in self.cameras]
        self.keypoints = tuple(keypoints)
        self.stamps, self.X, self.error, self.ncams, self.score = [], [], [], [], []
        self.points2d, self.conf2d, self.inliers, self.K_heat = [], [], [], []
        self.heat_size = None

    def add(self, stamp_ns, present, result, heat_cameras):
        """present: the Cameras of this frame's views (order of result's V axis);
        heat_cameras: their heatmap cameras."""
        V, C = len(self.names), len(self.keypoints)
        p2 = np.full((V, C, 2), np.nan)
        cf = np.full((V, C), np.nan)
        inl = np.zeros((V, C), bool)
        K = np.full((V, 3, 3), np.nan)
        for i, (cam, hc) in enumerate(zip(present, heat_cameras)):
            v = self.names.index(cam.name)
            p2[v], cf[v], inl[v], K[v] = (result.points2d[i], result.peak_confidence[i],
                                          result.inliers[i], hc.K)
            self.heat_size = (hc.width, hc.height)
        self.stamps.append(int(stamp_ns))
        self.X.append(result.X)
        self.error.append(result.reprojection_error)
        self.ncams.append(result.num_views)
        self.score.append(result.confidence)
        self.points2d.append(p2)
        self.conf2d.append(cf)
        self.inliers.append(inl)
        self.K_heat.append(K)

    def arrays(self):
        """dict of stacked arrays (T leading)."""
        C, V = len(self.keypoints), len(self.names)
        shape = {'X': (0, C, 3), 'error': (0, C), 'ncams': (0, C), 'score': (0, C),
                 'points2d': (0, V, C, 2), 'conf2d': (0, V, C), 'inliers': (0, V, C),
                 'K_heat': (0, V, 3, 3)}
        out = {k: (np.stack(getattr(self, k)) if getattr(self, k) else np.zeros(s))
               for k, s in shape.items()}
        out['stamps'] = np.array(self.stamps, np.int64)
        return out

    def summary(self):
        """dict: frames, per-joint dropout (fraction of frames not triangulated), mean
        inlier views per joint, mean inlier views overall."""
        a = self.arrays()
        if not len(a['stamps']):
            return dict(frames=0, dropout={}, inlier_views={}, mean_inlier_views=float('nan'))
        missing = ~np.isfinite(a['X']).all(-1)
        views = np.where(missing, np.nan, a['ncams'].astype(float))
        counts = np.isfinite(views).sum(axis=0)
        per_joint = np.where(counts > 0, np.nansum(views, axis=0) / np.maximum(counts, 1),
                             np.nan)
        return dict(frames=len(a['stamps']),
                    dropout=dict(zip(self.keypoints, missing.mean(axis=0).tolist())),
                    inlier_views=dict(zip(self.keypoints, np.asarray(per_joint).tolist())),
                    mean_inlier_views=float(np.nanmean(views)) if np.isfinite(views).any()
                    else float('nan'))

    def write(self, folder, formats=FORMATS, edges=None, trc_axes='xyz', smoothed=None):
        """Write the chosen formats into `folder` -> {format: path} (write_results)."""
        return write_results(folder, formats, self.cameras, self.keypoints, self.arrays(),
                             edges=edges, trc_axes=trc_axes, smoothed=smoothed,
                             heat_size=self.heat_size)


def write_results(folder, formats, cameras, keypoints, a, edges=None, trc_axes='xyz',
                  smoothed=None, heat_size=None, fnum=None, origin_ns=None, rate_hz=None):
    """Write the chosen formats into `folder` -> {format: path}.

    fnum (T,) int, origin_ns, rate_hz: the source's frame numbers, time origin (ns) and
    frame rate (Hz) when the source has them (2D tables: `monet triangulate`), kept in every
    export (CSV fnum, TRC Frame# / Time / DataRate, NWB timestamps and 'source_frame', npz
    fnum); None = counted from the stamps (export_tables TIME_BASE, SOURCE_FRAMES).

    cameras: V Camera; keypoints (C,); a: dict of arrays as ResultsCollector.arrays gives
    (stamps (T,), X (T, C, 3), error, ncams, score (T, C), points2d (T, V, C, 2), conf2d,
    inliers (T, V, C), K_heat (T, V, 3, 3)); smoothed: a temporal.Smoothed of the same
    frames: csv, trc and nwb then hold the filtered points (with their confidence, change
    and bridged flags); npz always holds the 2D detections. Every file states the length
    unit of the cameras (Camera.units), that of X: TRC Units, NWB unit, the CSV's sidecar
    keypoints3d.units.json."""
    from monet_ros.geometry.units import rig_units
    from monet_ros.io.export_tables import source_frames, write_anipose_csv, write_trc
    folder = Path(folder)
    units = rig_units(cameras)
    names = [c.name for c in cameras]
    X, error, ncams, score = a['X'], a['error'], a['ncams'], a['score']
    extra = filtered = None
    if smoothed is not None:
        X, error, ncams, score = smoothed.X, smoothed.error, smoothed.ncams, smoothed.score
        extra = {'change_mm': smoothed.change_mm, 'bridged': smoothed.bridged.astype(float)}
        filtered = dict(method=smoothed.method, change_mm=smoothed.change_mm,
                        bridged=smoothed.bridged)
    out = {}
    if 'csv' in formats:
        out['csv'] = write_anipose_csv(folder / FILE_NAMES['csv'], keypoints, a['stamps'], X,
                                       error, ncams, score, extra=extra, units=units,
                                       fnum=fnum)
    if 'trc' in formats:
        out['trc'] = write_trc(folder / FILE_NAMES['trc'], keypoints, a['stamps'], X,
                               axes=trc_axes, units=units, fnum=fnum, origin_ns=origin_ns,
                               rate_hz=rate_hz)
    if 'npz' in formats:
        path = folder / FILE_NAMES['npz']
        tmp = folder / ('.tmp_' + FILE_NAMES['npz'])
        with open(tmp, 'wb') as f:
            np.savez_compressed(f, stamps_ns=a['stamps'], cameras=np.array(names),
                                fnum=source_frames(a['stamps'], fnum),
                                keypoints=np.array(keypoints),
                                points2d=a['points2d'], confidence=a['conf2d'],
                                inliers=a['inliers'], K_heat=a['K_heat'],
                                heat_size=np.array(heat_size or (0, 0)))
        os.replace(tmp, path)
        out['npz'] = path
    if 'nwb' in formats and len(a['stamps']):
        from monet_ros.io.export_nwb import write_nwb
        out['nwb'] = write_nwb(folder / FILE_NAMES['nwb'], keypoints, a['stamps'], X, score,
                               cameras, a['points2d'], a['conf2d'], edges=edges,
                               filtered=filtered, fnum=fnum, origin_ns=origin_ns)
    return out


def write_subject_results(folder, formats, cameras, keypoints, rows, stamps_ns, fnum,
                          edges=None, trc_axes='xyz', origin_ns=None, rate_hz=None,
                          smoothed=None):
    """Write several subjects' points (`monet triangulate --subjects`) -> {format: path}.

    rows: subjects.offline.SubjectRows (frame indices into stamps_ns (T,) / fnum (T,));
    csv: keypoints3d.csv in anipose's layout with a `subject` column, one row per frame and
    subject (frame order, then identity); trc: keypoints3d_subject<identity>.trc per
    subject, every frame from the first to the last (empty cells where the subject is
    absent); nwb: keypoints.nwb with one 3D series per subject (export_nwb, NaN where
    absent; the 2D instances are not written). Formats and units as write_results; npz is
    not written for several subjects (ValueError). smoothed: a subjects.offline.
    SmoothedSubjects of these rows (`--filter`): every file then holds its filtered rows
    instead (the subject column as without it), the CSV also `<kp>_change_mm` and
    `<kp>_bridged`, the NWB `filter_change_mm_subject<id>` / `filter_bridged_subject<id>`
    per subject."""
    from monet_ros.geometry.units import rig_units
    from monet_ros.io.export_tables import write_anipose_csv, write_trc
    if 'npz' in formats:
        raise ValueError('--export npz: not written with --subjects (its 2D arrays are per '
                         'subject-less instance); use csv, trc, nwb')
    folder = Path(folder)
    units = rig_units(cameras)
    stamps_ns = np.asarray(stamps_ns, np.int64)
    fnum = np.asarray(fnum, np.int64)
    extra = filtered = None
    if smoothed is not None:
        rows = smoothed.rows
    order = np.lexsort((rows.subject, rows.frame))
    frame = rows.frame[order].astype(np.int64)
    if smoothed is not None:
        extra = {'change_mm': smoothed.change_mm[order],
                 'bridged': smoothed.bridged[order].astype(float)}
    out = {}
    if 'csv' in formats:
        out['csv'] = write_anipose_csv(folder / FILE_NAMES['csv'], keypoints, stamps_ns[frame],
                                       rows.X[order], rows.error[order], rows.ncams[order],
                                       rows.score[order], extra=extra, units=units,
                                       fnum=fnum[frame], subject=rows.subject[order])
    T, C = len(stamps_ns), len(keypoints)
    per_subject = []
    if smoothed is not None:
        filtered = dict(method=smoothed.method, subjects={})
    for ident in np.unique(rows.subject):
        mine = rows.subject == ident
        X = np.full((T, C, 3), np.nan)
        score = np.full((T, C), np.nan)
        X[rows.frame[mine]] = rows.X[mine]
        score[rows.frame[mine]] = rows.score[mine]
        per_subject.append((int(ident), X, score))
        if smoothed is not None:
            change = np.full((T, C), np.nan)
            bridged = np.zeros((T, C), bool)
            change[rows.frame[mine]] = smoothed.change_mm[mine]
            bridged[rows.frame[mine]] = smoothed.bridged[mine]
            filtered['subjects'][int(ident)] = (change, bridged)
    if 'trc' in formats:
        for ident, X, _ in per_subject:
            out[f'trc subject {ident}'] = write_trc(
                folder / f'keypoints3d_subject{ident}.trc', keypoints, stamps_ns, X,
                axes=trc_axes, units=units, fnum=fnum, origin_ns=origin_ns, rate_hz=rate_hz)
    if 'nwb' in formats and T:
        from monet_ros.io.export_nwb import write_nwb
        out['nwb'] = write_nwb(folder / FILE_NAMES['nwb'], keypoints, stamps_ns, None, None,
                               cameras, None, None, edges=edges, fnum=fnum,
                               origin_ns=origin_ns, subjects=per_subject, filtered=filtered)
    return out
