"""Distillation from filtered 3D (issue 36 item 2): a teacher detector's whole-recording 3D,
smoothed by the offline filter (`monet process --filter optim`: bones, smoothness, robust
reprojection), reprojected into every view as weighted, gated pseudo-labels (L_D).

The route of Lightning Pose 3D (Biderman et al., 2024: multi-view ensemble Kalman smoothing,
then distillation into a student from the smoothed pseudo-labels), with this package's
tools: the product's own detector, crop rule, fusion and filter make the teacher's 3D, so
a distillation round sees what a user's `monet process` run would give. No ROS here; the
round itself (running `monet process`) is commands.train_distill.
"""
from dataclasses import dataclass
import warnings

import numpy as np

from monet_ros.geometry.camera import project_views
from monet_ros.geometry.units import convert, rig_units


@dataclass(frozen=True)
class Distilled:
    """Pseudo-labels of a distillation round.

    points (T, V, C, 2) source image px, NaN where there is none; weight (T, V, C) in (0, 1]
    (0 where there is none): 1 / (1 + (error / residual_px)^2) of the filtered point's mean
    reprojection error over its inlier views; counts: dict of the (instant, view, keypoint)
    cells considered (`cells`) and where they went: `kept`, `no_3d` (the teacher's filter
    left no point), `few_views` (fewer than min_views inlier views), `high_error` (mean
    reprojection error above gate_px), `outside` (behind the camera or outside its image),
    and `frames_unmatched` (instants with no frame of the teacher's run)."""
    points: np.ndarray
    weight: np.ndarray
    counts: dict

    @property
    def count(self):
        return int(self.counts['kept'])

    def summary(self):
        """One line: kept / considered and why the rest were left out."""
        c = self.counts
        return (f"{c['kept']} of {c['cells']} unlabelled view x keypoint cells "
                f"({100 * c['kept'] / max(c['cells'], 1):.0f}%): left out {c['no_3d']} with "
                f"no filtered point, {c['few_views']} with fewer inlier views than required, "
                f"{c['high_error']} with a reprojection error above the gate, "
                f"{c['outside']} outside the view; {c['frames_unmatched']} instants without "
                "a frame of the teacher's run")


def align_to_instants(stamps, frame_stamps, values, fill=np.nan):
    """Rows of `values` (F, ...) at frame_stamps (F,) ns placed at the instants whose stamp
    (stamps (T,) ns) equals theirs: (T, ...) filled with `fill` elsewhere, and the (T,) bool
    of instants that got a row. Stamps are exact (the teacher's run groups the recording's
    images by the same rule, io.multiview, as the training recording)."""
    stamps = np.asarray(stamps, np.int64)
    frame_stamps = np.asarray(frame_stamps, np.int64)
    values = np.asarray(values)
    out = np.full((len(stamps),) + values.shape[1:], fill, dtype=np.result_type(values, fill))
    found = np.zeros(len(stamps), bool)
    if len(frame_stamps) and len(stamps):
        order = np.argsort(frame_stamps)
        pos = np.clip(np.searchsorted(frame_stamps[order], stamps), 0, len(order) - 1)
        found = frame_stamps[order][pos] == stamps
        out[found] = values[order][pos[found]]
    return out, found


def distilled_labels(X, error, ncams, cameras, cells, units=None, gate_px=8.0, min_views=3,
                     residual_px=2.0, matched=None):
    """Distilled pseudo-labels from filtered 3D.

    X (T, C, 3) filtered points (T: instants, or the crop rows of several subjects:
    commands.train_distill) in `units` (default: the cameras', Camera.units), NaN where
    the filter kept none; error (T, C) px mean reprojection error of each point over its
    inlier views and ncams (T, C) those views (temporal.Smoothed's); cameras: the V Camera
    the labels are for; cells (T, V, C) bool: the cells that may get a pseudo-label (e.g.
    unlabelled views of training instants); gate_px, min_views: a point is used where
    error <= gate_px and ncams >= min_views; residual_px: the weight's scale; matched (T,)
    bool: instants the teacher's run had a frame for (None: all). A perfect teacher (X the
    ground truth, error 0, every view an inlier) gives the projected ground truth, weight 1.
    Returns Distilled. Raises ValueError on shapes."""
    X = np.asarray(X, np.float64)
    T, C = X.shape[:2]
    V = len(cameras)
    error = np.asarray(error, np.float64)
    ncams = np.asarray(ncams)
    cells = np.asarray(cells, bool)
    if X.shape != (T, C, 3) or error.shape != (T, C) or ncams.shape != (T, C) or \
            cells.shape != (T, V, C):
        raise ValueError(f'distilled_labels: X must be (T, C, 3), error and ncams (T, C), cells '
                         f'(T, V={V}, C); got {X.shape}, {error.shape}, {ncams.shape}, '
                         f'{cells.shape}')
    own = rig_units(cameras)
    if units is not None and units != own:
        X = convert(X, units, own)
    matched = np.ones(T, bool) if matched is None else np.asarray(matched, bool)
    has = np.isfinite(X).all(-1)                                             # (T, C)
    with np.errstate(invalid='ignore'):
        enough = has & (ncams >= min_views)
        good = enough & (error <= gate_px)
    points = project_views(cameras, np.where(has[..., None], X, 0.0))        # (T, V, C, 2)
    R = np.stack([c.R for c in cameras])
    t = np.stack([c.t for c in cameras])
    depth = np.einsum('vj,tcj->tvc', R[:, 2], np.where(has[..., None], X, 0.0)) + t[None, :, 2,
                                                                                    None]
    size = np.array([[c.width, c.height] for c in cameras], np.float64)[None, :, None]
    inside = (depth > 0) & np.all((points >= -0.5) & (points <= size - 0.5), axis=-1)
    keep = cells & good[:, None] & inside
    weight = np.where(keep, 1.0 / (1.0 + (np.nan_to_num(error, nan=np.inf)[:, None]
                                          / residual_px) ** 2), 0.0)
    counts = {'cells': int(cells.sum()), 'kept': int(keep.sum()),
              'no_3d': int((cells & ~has[:, None]).sum()),
              'few_views': int((cells & (has & ~enough)[:, None]).sum()),
              'high_error': int((cells & (enough & ~good)[:, None]).sum()),
              'outside': int((cells & good[:, None] & ~inside).sum()),
              'frames_unmatched': int((~matched).sum())}
    return Distilled(np.where(keep[..., None], points, np.nan), weight, counts)


def label_errors(points, truth):
    """Pseudo-label precision: distances (px) of points (..., 2) to truth (..., 2) where
    both are finite; dict of count, median, mean, p90 and the share within 2 / 5 px."""
    err = np.linalg.norm(np.asarray(points, np.float64) - np.asarray(truth, np.float64),
                         axis=-1)
    err = err[np.isfinite(err)]
    if not err.size:
        return {'count': 0}
    return {'count': int(err.size), 'median_px': float(np.median(err)),
            'mean_px': float(err.mean()), 'p90_px': float(np.percentile(err, 90)),
            'within_2px': float((err <= 2).mean()), 'within_5px': float((err <= 5).mean())}


def match_identities(X, instants, row_instants, row_boxes, cameras, units=None, gate=1.0,
                     row_points=None):
    """Which of a teacher's identities (`monet process --subjects N`) is the subject of each
    crop row of the training data (TrainingData.row_instants / row_boxes): the teacher's
    identity numbers need not be the labels' subject ids (these are instance labels within
    one labelled instant), so rows and identities are matched by geometry, instant by
    instant.

    The rule: per instant, the cost of (identity i, row r) is the median over the views
    where i's reprojected joints (in front of the camera, inside the image) are seen of
    |centre of their bounding box - r's anchor| / half the crop box's longer side, r's
    anchor in a view being the centre of the bounding box of its labels there (row_points)
    where it has one, else the centre of its crop box; the identities and the rows of that
    instant are paired by a Hungarian assignment of that cost (scipy
    linear_sum_assignment), a pair kept only where the cost is at most `gate` (default 1:
    the identity's centre within half a crop side of the anchor in the median view). A
    row's crop is cut around its subject (its labels, their tracks, or its nearest
    labelled instant's box), so the identity centred in it is the subject the row trains;
    a crop that shows both subjects is given the nearer one, and two rows never share an
    identity. (A crop that follows no subject, box_source fixed / full, has no subject to
    match at an unlabelled view: its row gets the identity nearest the crop's centre.)

    X (R, C, 3) the teacher's rows (points in `units`, default the cameras'; NaN = none);
    instants (R,) the training instant of each teacher row (-1: none); row_instants (N,),
    row_boxes (N, V, 4) px (x0, y0, x1, y1); row_points (N, V, C, 2) px the rows' labels
    (NaN = none; None: none); cameras: the V Camera. Returns (match (N,) int:
    the teacher row of each crop row, -1 none; cost (N,): its cost, inf where none)."""
    from scipy.optimize import linear_sum_assignment

    X = np.asarray(X, np.float64)
    instants = np.asarray(instants, np.int64)
    row_instants = np.asarray(row_instants, np.int64)
    boxes = np.asarray(row_boxes, np.float64)
    own = rig_units(cameras)
    if units is not None and units != own:
        X = convert(X, units, own)
    V = len(cameras)
    if X.ndim != 3 or instants.shape != X.shape[:1] or \
            boxes.shape != row_instants.shape + (V, 4):
        raise ValueError(f'match_identities: X must be (R, C, 3), instants (R,), row_boxes '
                         f'(N, V={V}, 4); got {X.shape}, {instants.shape}, {boxes.shape}')
    match = np.full(len(row_instants), -1, np.int64)
    cost = np.full(len(row_instants), np.inf)
    if not len(X) or not len(row_instants):
        return match, cost
    has = np.isfinite(X).all(-1)                                             # (R, C)
    uv = project_views(cameras, np.where(has[..., None], X, 0.0))           # (R, V, C, 2)
    R_ = np.stack([c.R for c in cameras])
    t_ = np.stack([c.t for c in cameras])
    depth = np.einsum('vj,rcj->rvc', R_[:, 2], np.where(has[..., None], X, 0.0)) + \
        t_[None, :, 2, None]
    size = np.array([[c.width, c.height] for c in cameras], np.float64)[None, :, None]
    seen = has[:, None] & (depth > 0) & np.all((uv >= -0.5) & (uv <= size - 0.5), -1) & \
        np.isfinite(uv).all(-1)                                              # (R, V, C)
    lo = np.where(seen[..., None], uv, np.inf).min(2)
    hi = np.where(seen[..., None], uv, -np.inf).max(2)
    with np.errstate(invalid='ignore'):            # unseen: inf - inf, replaced by NaN
        centre = np.where(seen.any(2)[..., None], (lo + hi) / 2, np.nan)     # (R, V, 2)
    box_centre = (boxes[..., :2] + boxes[..., 2:]) / 2                       # (N, V, 2)
    if row_points is not None:       # a labelled view: its labels' centre
        labels = np.asarray(row_points, np.float64)
        has_label = np.isfinite(labels).all(-1)                              # (N, V, C)
        with np.errstate(invalid='ignore'):
            mid = (np.where(has_label[..., None], labels, np.inf).min(2) +
                   np.where(has_label[..., None], labels, -np.inf).max(2)) / 2
        box_centre = np.where(has_label.any(2)[..., None], mid, box_centre)
    half = (boxes[..., 2:] - boxes[..., :2]).max(-1) / 2                     # (N, V)
    for t in np.intersect1d(instants, row_instants):
        ids = np.flatnonzero(instants == t)
        rows = np.flatnonzero(row_instants == t)
        d = np.linalg.norm(centre[ids][:, None] - box_centre[rows][None], axis=-1) / \
            half[rows][None]                                                 # (k, m, V)
        with warnings.catch_warnings():          # an identity seen in no view: no cost
            warnings.simplefilter('ignore', RuntimeWarning)
            c = np.nanmedian(np.where(np.isfinite(d), d, np.nan), axis=-1)   # (k, m)
        c = np.where(np.isfinite(c), c, np.inf)
        ok = c <= gate
        if not ok.any():
            continue
        i, r = linear_sum_assignment(np.where(ok, c, 1e12))
        keep = ok[i, r]
        match[rows[r[keep]]] = ids[i[keep]]
        cost[rows[r[keep]]] = c[i[keep], r[keep]]
    return match, cost
