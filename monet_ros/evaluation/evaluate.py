"""Evaluate a detector on held-out instants of a recording against ground truth 3D.

Per instant, every view is cropped around the subject (the same boxes as training), the
detector runs once over all views (models.Detector), peaks are decoded in heatmap pixels
and compared with the ground truth projected into the heatmap's virtual camera (PCK, see
evaluation.pck); then the peaks are mapped back to original pixels, triangulated from all
views without RANSAC and reprojected (evaluation.reprojection).
"""
import numpy as np

from monet_ros.evaluation.pck import normalised_distances, pck
from monet_ros.evaluation.report import EvalSummary
from monet_ros.evaluation.reprojection import multiview_reprojection
from monet_ros.geometry import crop_transform, project_views
from monet_ros.learning.pseudo_labels import project_to_views
from monet_ros.models import decode_heatmaps


def detect_instants(detector, recording, instants, boxes):
    """Run the detector on every view of `instants`.

    boxes: (T, V, 4) crop boxes of the whole recording. Returns dict of
    peaks_heat (N, V, C, 2), confidence (N, V, C), points (N, V, C, 2) original pixels,
    heat_K (N, V, 3, 3), used boxes (N, V, 4)."""
    instants = np.asarray(instants, dtype=np.int64)
    cams = recording.cameras
    V, C = len(cams), recording.num_keypoints
    h, w = detector.heatmap_size
    out = {k: np.empty((len(instants), V) + s) for k, s in (
        ('peaks_heat', (C, 2)), ('confidence', (C,)), ('points', (C, 2)), ('heat_K', (3, 3)),
        ('boxes', (4,)))}
    for n, t in enumerate(instants):
        used = detector.boxes_for(cams, boxes[t])
        heat, heat_cams = detector.predict(recording.images(int(t)), cams, used)
        peaks, conf = decode_heatmaps(heat)
        S_inv = np.linalg.inv(np.stack([crop_transform(b, (w, h)) for b in used]))
        out['peaks_heat'][n] = peaks
        out['confidence'][n] = conf
        out['points'][n] = np.einsum('vij,vcj->vci', S_inv[:, :2, :2], peaks) + \
            S_inv[:, None, :2, 2]
        out['heat_K'][n] = np.stack([c.K for c in heat_cams])
        out['boxes'][n] = used
    return out


def evaluate_detector(detector, recording, instants, boxes, mode='model', dataset=None):
    """EvalSummary of a detector on `instants` (requires recording.gt3d).

    PCK is over (instant, view, keypoint) where the ground truth projects inside the
    original image; the heatmap window is the heatmap width. Reprojection: consistency of the
    all-view triangulation with the detections, and of its reprojection with the ground
    truth, in original pixels."""
    if recording.gt3d is None:
        raise ValueError(f'{recording.name}: evaluation needs ground-truth 3D keypoints')
    instants = np.asarray(instants, dtype=np.int64)
    det = detect_instants(detector, recording, instants, boxes)
    gt3d = recording.gt3d[instants]                                          # (N, C, 3)
    visible = np.isfinite(project_to_views(gt3d.reshape(-1, 3), recording.cameras)[..., 0])
    visible = visible.reshape(len(recording.cameras), len(instants), -1).transpose(1, 0, 2)
    h, w = detector.heatmap_size
    heat_cams_gt = np.empty_like(det['peaks_heat'])
    for n in range(len(instants)):
        cams = [c.replace(K=K, width=w, height=h)
                for c, K in zip(recording.cameras, det['heat_K'][n])]
        heat_cams_gt[n] = project_views(cams, gt3d[n])                        # (V, C, 2)
    heat_cams_gt[~visible] = np.nan
    distances = normalised_distances(det['peaks_heat'], heat_cams_gt, float(w))
    result = pck(distances.reshape(-1, recording.num_keypoints), keypoints=recording.keypoints)
    reproj = multiview_reprojection(det['points'], recording.cameras, gt3d)
    cons, gt_err = reproj.consistency_stats, reproj.gt_stats
    extra = {'error3d_mean': reproj.error3d_stats.mean, 'error3d_std': reproj.error3d_stats.std,
             'mean_confidence': float(np.mean(det['confidence'])),
             'heatmap_size': [h, w]}
    return EvalSummary(mode, dataset or recording.name, cons.mean, cons.std, gt_err.mean,
                       gt_err.std, result, len(instants), extra)
