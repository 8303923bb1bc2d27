"""evaluate_detector against an independent recomputation (OpenCV projection, per-point DLT)
from the same detector outputs."""
import cv2
from helpers.blobs import blob_recording
import numpy as np
import torch

from monet_ros.crop_rule import recording_boxes
from monet_ros.evaluation.evaluate import evaluate_detector
from monet_ros.models import build_model, decode_heatmaps
from monet_ros.models.detector import Detector


def dlt(points, cameras):
    """Plain per-point DLT with numpy SVD (independent of geometry.triangulate)."""
    rows = []
    for (u, v), cam in zip(points, cameras):
        P = cam.K @ np.hstack([cam.R, cam.t[:, None]])
        rows += [u * P[2] - P[0], v * P[2] - P[1]]
    X = np.linalg.svd(np.array(rows))[2][-1]
    return X[:3] / X[3]


def test_evaluate_detector_matches_independent_computation():
    torch.manual_seed(0)
    rec = blob_recording(num_views=4, T=6, C=3, labelled=(0,))
    model = build_model('small', 3, input_size=[48, 48], width=8)
    detector = Detector(model, {'keypoints': list(rec.keypoints)}, device='cpu')
    boxes = recording_boxes(rec, 'ground_truth', 1.0, 0.25)     # explicit benchmark option
    instants = np.array([3, 4, 5])
    summary = evaluate_detector(detector, rec, instants, boxes, 'supervised', 'blobs',
                                crop='boxes')

    distances, errors, gt_errors, errors2d = [], [], [], []
    for t in instants:
        heat, heat_cams = detector.predict(rec.images(t), rec.cameras, boxes[t])
        peaks, _ = decode_heatmaps(heat)
        image_pts = []
        for v, hc in enumerate(heat_cams):
            gt_heat, _ = cv2.projectPoints(rec.gt3d[t], cv2.Rodrigues(hc.R)[0], hc.t, hc.K,
                                           hc.dist)
            distances.append(np.linalg.norm(peaks[v] - gt_heat[:, 0], axis=1) / 12.0)
            x0, y0, x1, y1 = boxes[t, v]
            image_pts.append(np.stack([(peaks[v, :, 0] + 0.5) * (x1 - x0) / 12 + x0 - 0.5,
                                       (peaks[v, :, 1] + 0.5) * (y1 - y0) / 12 + y0 - 0.5], 1))
        image_pts = np.stack(image_pts)                                        # (V, C, 2)
        for c in range(3):
            X = dlt(image_pts[:, c], rec.cameras)
            for v, cam in enumerate(rec.cameras):
                proj, _ = cv2.projectPoints(X[None], cv2.Rodrigues(cam.R)[0], cam.t, cam.K,
                                            cam.dist)
                gt, _ = cv2.projectPoints(rec.gt3d[t, c][None], cv2.Rodrigues(cam.R)[0], cam.t,
                                          cam.K, cam.dist)
                errors.append(np.linalg.norm(proj[0, 0] - image_pts[v, c]))
                errors2d.append(np.linalg.norm(image_pts[v, c] - gt[0, 0]))
                gt_errors.append(np.linalg.norm(proj[0, 0] - gt[0, 0]))
    d = np.concatenate(distances)
    for alpha in (0.05, 0.1, 0.2):
        assert summary.pck.at(alpha) == np.mean(d <= alpha)
    assert abs(summary.reprojection_mean - np.mean(errors)) < 1e-6
    assert abs(summary.reprojection_std - np.std(errors)) < 1e-6
    assert abs(summary.gt_reprojection_mean - np.mean(gt_errors)) < 1e-6
    assert abs(summary.extra['error2d_mean'] - np.mean(errors2d)) < 1e-6
    assert abs(summary.extra['error2d_median'] - np.median(errors2d)) < 1e-6
    assert summary.instants == 3 and summary.pck.counts.tolist() == [12, 12, 12]


def test_tracked_crops_follow_the_previous_instants_fused_3d():
    """Evaluation crops with the live rule: instant n is cropped around the 3D fused from
    instant n - 1 (crop_rule.crop_boxes, the detector node's function; fusion as in `monet
    process`), the given boxes being the start and the fallback."""
    from monet_ros.crop_rule import crop_boxes
    from monet_ros.evaluation.evaluate import detect_instants
    from monet_ros.fusion import FusionConfig, fuse_heatmaps

    torch.manual_seed(1)
    rec = blob_recording(num_views=4, T=6, C=3, labelled=(0,))
    model = build_model('small', 3, input_size=[48, 48], width=8)
    detector = Detector(model, {'keypoints': list(rec.keypoints)}, device='cpu')
    start = recording_boxes(rec, 'labels', 1.0, 0.25)
    instants = np.array([2, 3, 4])
    det = detect_instants(detector, rec, instants, start, crop='tracked',
                          fusion_config=FusionConfig(confidence_threshold=0.0))
    cams = rec.cameras
    np.testing.assert_array_equal(det['boxes'][0], detector.boxes_for(cams, start[2]))
    for n in (1, 2):
        t = instants[n]
        heat, heat_cams = detector.predict(rec.images(t - 1), cams, det['boxes'][n - 1],
                                           keep_aspect=False)
        X = fuse_heatmaps(heat, np.stack([c.K for c in heat_cams]), cams,
                          FusionConfig(confidence_threshold=0.0)).X
        assert np.isfinite(X).all(axis=1).sum() >= 3           # the tracked branch is taken
        want = detector.boxes_for(cams, crop_boxes(cams, X.astype(np.float32), start[t]))
        np.testing.assert_allclose(det['boxes'][n], want, atol=1e-9)


def test_fused_3d_is_what_monet_process_fuses():
    """The product's 3D figures: the heatmaps of every instant fused as `monet process` fuses
    them (fusion.fuse_heatmaps, default FusionConfig), against the ground-truth 3D; keypoints
    left untriangulated are counted as missing, not averaged."""
    from monet_ros.fusion import FusionConfig, fuse_heatmaps

    torch.manual_seed(0)
    rec = blob_recording(num_views=4, T=6, C=3, labelled=(0,))
    model = build_model('small', 3, input_size=[48, 48], width=8)
    detector = Detector(model, {'keypoints': list(rec.keypoints)}, device='cpu')
    boxes = recording_boxes(rec, 'ground_truth', 1.0, 0.25)
    instants = np.array([3, 4, 5])
    summary = evaluate_detector(detector, rec, instants, boxes, 'supervised', 'blobs',
                                crop='boxes')
    errors, missing = [], 0
    for t in instants:
        heat, heat_cams = detector.predict(rec.images(t), rec.cameras,
                                           detector.boxes_for(rec.cameras, boxes[t]),
                                           keep_aspect=False)
        X = fuse_heatmaps(heat, np.stack([c.K for c in heat_cams]), rec.cameras,
                          FusionConfig()).X
        for c in range(3):
            if np.isfinite(X[c]).all():
                errors.append(np.sqrt(((X[c] - rec.gt3d[t, c]) ** 2).sum()))
            else:
                missing += 1
    assert errors, 'the random net should still triangulate some keypoints'
    e = summary.extra
    assert abs(e['fused3d_mean'] - np.mean(errors)) < 1e-9
    assert abs(e['fused3d_median'] - np.median(errors)) < 1e-9
    assert abs(e['fused3d_p90'] - np.percentile(errors, 90)) < 1e-9
    assert abs(e['fused3d_missing'] - missing / 9) < 1e-12
