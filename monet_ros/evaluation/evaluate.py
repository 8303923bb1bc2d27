"""Evaluate a detector on held-out instants of a recording against ground truth 3D.

Per instant, every view is cropped by the crop rule (monet_ros.crop_rule): by default the
live detector's tracked rule (around the previous instant's fused 3D keypoints, fused with
monet_ros.fusion exactly as `monet process` does; given boxes as the fallback and the
start), or, explicitly, given boxes (e.g. ground-truth boxes, a labelled benchmark option).
The detector runs once over all views (models.Detector), peaks are decoded in heatmap pixels,
mapped back to original pixels and compared with the projected ground truth (2D error, PCK
normalised by the ground-truth subject box, see evaluate_detector), then triangulated from
all views without RANSAC and reprojected (evaluation.reprojection).
"""
import numpy as np

from monet_ros.crop_rule import TrackedCrops
from monet_ros.evaluation.pck import pck
from monet_ros.evaluation.report import EvalSummary
from monet_ros.evaluation.reprojection import multiview_reprojection
from monet_ros.fusion import FusionConfig, fuse_heatmaps
from monet_ros.geometry import crop_transform
from monet_ros.geometry.units import rig_units
from monet_ros.learning.dataset import boxes_from_points
from monet_ros.learning.pseudo_labels import project_to_views
from monet_ros.models import decode_heatmaps

CROPS = ('tracked', 'boxes')


def detect_instants(detector, recording, instants, boxes, crop='tracked', rule=None,
                    fusion_config=None):
    """Run the detector on every view of `instants` (in order).

    boxes: (T, V, 4) boxes of the whole recording: with crop='boxes' the crops, with
    crop='tracked' the fallback of the tracked rule (crop_rule.TrackedCrops with `rule`; the
    3D it follows is fused with `fusion_config`, as in `monet process`). Returns dict of
    peaks_heat (N, V, C, 2), confidence (N, V, C), points (N, V, C, 2) original pixels,
    heat_K (N, V, 3, 3), used boxes (N, V, 4), fused (N, C, 3) m: the 3D keypoints fused from
    the heatmaps as `monet process` fuses them (fusion.fuse_heatmaps with `fusion_config`: the
    product's 3D; NaN where not triangulated). Raises ValueError for an unknown crop."""
    if crop not in CROPS:
        raise ValueError(f'crop must be one of {CROPS}, got {crop!r}')
    instants = np.asarray(instants, dtype=np.int64)
    cams = recording.cameras
    V, C = len(cams), recording.num_keypoints
    h, w = detector.heatmap_size
    tracker = TrackedCrops(rule, rig_units(cams))
    fusion_config = fusion_config or FusionConfig()
    out = {k: np.empty((len(instants), V) + s) for k, s in (
        ('peaks_heat', (C, 2)), ('confidence', (C,)), ('points', (C, 2)), ('heat_K', (3, 3)),
        ('boxes', (4,)))}
    out['fused'] = np.empty((len(instants), C, 3))
    for n, t in enumerate(instants):
        stamp = int(recording.stamps[t])
        chosen = tracker.boxes(cams, stamp, boxes[t]) if crop == 'tracked' else boxes[t]
        used = detector.boxes_for(cams, chosen)
        heat, heat_cams = detector.predict(recording.images(int(t)), cams, used,
                                           keep_aspect=False)
        K_heat = np.stack([c.K for c in heat_cams])
        fused = fuse_heatmaps(heat, K_heat, cams, fusion_config).X
        if crop == 'tracked':
            tracker.update(fused, stamp)
        out['fused'][n] = fused
        peaks, conf = decode_heatmaps(heat)
        S_inv = np.linalg.inv(np.stack([crop_transform(b, (w, h)) for b in used]))
        out['peaks_heat'][n] = peaks
        out['confidence'][n] = conf
        out['points'][n] = np.einsum('vij,vcj->vci', S_inv[:, :2, :2], peaks) + \
            S_inv[:, None, :2, 2]
        out['heat_K'][n] = K_heat
        out['boxes'][n] = used
    return out


def evaluate_detector(detector, recording, instants, boxes, mode='model', dataset=None,
                      crop='tracked', rule=None):
    """EvalSummary of a detector on `instants` (requires recording.gt3d); crop, boxes, rule:
    see detect_instants.

    Ground-truth figures (in extra): error2d_mean / error2d_median, the detections' distance
    to the projected ground truth (original px, views where it is visible); error3d_mean /
    error3d_median (m), the all-view triangulation (no RANSAC) against the ground-truth 3D;
    fused3d_mean / fused3d_median / fused3d_p90 (m), the product's 3D (the keypoints
    `monet process` fuses: outlier views excluded, top-k peaks) against the ground truth, over
    the keypoints it triangulated, and fused3d_missing, the share it left untriangulated
    (counted, never hidden in the mean).
    PCK is over (instant, view, keypoint) where the ground truth projects inside the
    original image, distances normalised by the side of the ground-truth subject box of the
    view (square, 25% margin; = the heatmap window of a ground-truth crop). Reprojection:
    consistency of the all-view triangulation with the detections, and of its reprojection
    with the ground truth, in original pixels; an error beyond the view's image diagonal is a
    failure, left out of the mean and std and counted in extra (reprojection_failures,
    gt_reprojection_failures; reprojection_count, gt_reprojection_count: those scored)."""
    if recording.gt3d is None:
        raise ValueError(f'{recording.name}: evaluation needs ground-truth 3D keypoints')
    instants = np.asarray(instants, dtype=np.int64)
    det = detect_instants(detector, recording, instants, boxes, crop, rule)
    gt3d = recording.gt3d[instants]                                          # (N, C, 3)
    gt2d = project_to_views(gt3d.reshape(-1, 3), recording.cameras)          # (V, N*C, 2)
    V, N, C = len(recording.cameras), len(instants), recording.num_keypoints
    gt2d = gt2d.reshape(V, N, C, 2).transpose(1, 0, 2, 3)                    # (N, V, C, 2)
    visible = np.isfinite(gt2d[..., 0])
    h, w = detector.heatmap_size
    # PCK: the distance in original pixels over the side of the ground-truth subject box of
    # that view (square, 25% margin): one yardstick for every mode, whatever its crops. With
    # ground-truth crops it is the paper's normalisation by the heatmap window.
    side = boxes_from_points(gt2d, aspect=1.0, margin=0.25)                  # (N, V, 4)
    side = side[..., 2] - side[..., 0]
    error = np.linalg.norm(det['points'] - gt2d, axis=-1)                    # (N, V, C)
    distances = np.where(visible, error / side[..., None], np.nan)
    result = pck(distances.reshape(-1, recording.num_keypoints), keypoints=recording.keypoints)
    error2d = error[visible]
    reproj = multiview_reprojection(det['points'], recording.cameras, gt3d)
    # beyond a view's image diagonal a reprojection error is a failure (a triangulation of
    # disagreeing views can land 1e15 px away): counted apart, never in the mean
    cons, gt_err = reproj.capped_stats(reproj.consistency), reproj.capped_stats(reproj.gt_error)
    e3d = reproj.error3d_stats
    fused_err = np.linalg.norm(det['fused'] - gt3d, axis=-1)                 # (N, C)
    has = np.isfinite(gt3d[..., 0])
    scored = fused_err[has & np.isfinite(fused_err)]
    extra = {'error3d_mean': e3d.mean, 'error3d_std': e3d.std, 'error3d_median': e3d.median,
             'reprojection_median': cons.median,
             'error2d_mean': float(error2d.mean()) if error2d.size else float('nan'),
             'error2d_median': float(np.median(error2d)) if error2d.size else float('nan'),
             'mean_confidence': float(np.mean(det['confidence'])),
             'fused3d_mean': float(scored.mean()) if scored.size else float('nan'),
             'fused3d_median': float(np.median(scored)) if scored.size else float('nan'),
             'fused3d_p90': float(np.percentile(scored, 90)) if scored.size else float('nan'),
             'fused3d_missing': float(1 - scored.size / max(1, int(has.sum()))),
             'heatmap_size': [h, w], 'crop': crop,
             'reprojection_count': cons.count, 'reprojection_failures': cons.failures,
             'gt_reprojection_count': gt_err.count, 'gt_reprojection_failures': gt_err.failures}
    return EvalSummary(mode, dataset or recording.name, cons.mean, cons.std, gt_err.mean,
                       gt_err.std, result, len(instants), extra)
