"""Figures to judge a calibration by (no ROS): per camera, per pair, and the board's own
geometry triangulated back with the new calibration.

- Per camera: board views and corners used, reprojection error (px) mean / p95 after the
  bundle adjustment (the error of each detected corner against the projection of the
  fitted board pose).
- Per pair: shared views / corners, and the stereo reprojection error (px) of the corners
  both cameras saw, triangulated from those two cameras only (independent of the fitted
  board poses).
- Board geometry: every corner seen by >= 2 cameras triangulated from all of them
  (monet_ros.geometry.triangulate), then the distances between corners one square apart:
  their median against square_length, in the board's unit.
"""
import numpy as np

from monet_ros.geometry import reprojection_error, triangulate


def camera_table(result):
    """list of dicts per calibrated camera: name, views, corners, mean_px, p95_px, fx, fy,
    cx, cy, dist (5,), single_rms_px (OpenCV's single-camera RMS; NaN when intrinsics were
    kept)."""
    obs = result.observations
    rows = []
    for cam in result.cameras:
        c = result.names.index(cam.name)
        mine = obs.camera == c
        errors = result.errors[mine]
        rows.append({
            'name': cam.name, 'views': int(np.unique(obs.frame[mine]).size),
            'corners': int(mine.sum()),
            'mean_px': float(errors.mean()) if errors.size else float('nan'),
            'p95_px': float(np.percentile(errors, 95)) if errors.size else float('nan'),
            'fx': float(cam.K[0, 0]), 'fy': float(cam.K[1, 1]), 'cx': float(cam.K[0, 2]),
            'cy': float(cam.K[1, 2]), 'dist': np.pad(cam.dist, (0, 5))[:5],
            'single_rms_px': result.intrinsics_rms.get(cam.name, float('nan'))})
    return rows


def corners_of(result, corners):
    """(V, F, N, 2) corners of the calibrated cameras (in result.cameras order)."""
    return np.stack([corners[result.names.index(c.name)] for c in result.cameras])


def pair_table(result, corners):
    """list of dicts per camera pair sharing views: a, b, views, corners, stereo_px (mean
    reprojection error of the two-camera triangulation of their shared corners)."""
    sub = corners_of(result, corners)
    rows = []
    for i in range(len(result.cameras)):
        for j in range(i + 1, len(result.cameras)):
            pair = sub[[i, j]].reshape(2, -1, 2)
            both = np.isfinite(pair[..., 0]).all(axis=0)
            if not both.any():
                continue
            views = int(np.isfinite(sub[[i, j], ..., 0]).all(axis=0).any(axis=1).sum())
            cams = [result.cameras[i], result.cameras[j]]
            X = triangulate(pair[:, both], cams)
            err = reprojection_error(X, pair[:, both], cams)
            rows.append({'a': cams[0].name, 'b': cams[1].name, 'views': views,
                         'corners': int(both.sum()), 'stereo_px': float(np.nanmean(err))})
    return rows


def board_geometry(result, corners, board):
    """Adjacent-corner distances of the board triangulated with the calibration: dict
    median, p5, p95, mean (board units), count (pairs measured), square_length,
    error_pct ((median - square) / square * 100). NaN figures when nothing is measurable."""
    sub = corners_of(result, corners)                 # (V, F, N, 2)
    V, F, N = sub.shape[:3]
    X = triangulate(sub.reshape(V, F * N, 2), result.cameras).reshape(F, N, 3)
    pairs = board.adjacent_pairs()
    distances = np.linalg.norm(X[:, pairs[:, 0]] - X[:, pairs[:, 1]], axis=-1).ravel()
    distances = distances[np.isfinite(distances)]
    square = board.square_length
    if not distances.size:
        nan = float('nan')
        return {'median': nan, 'p5': nan, 'p95': nan, 'mean': nan, 'count': 0,
                'square_length': square, 'error_pct': nan}
    median = float(np.median(distances))
    return {'median': median, 'p5': float(np.percentile(distances, 5)),
            'p95': float(np.percentile(distances, 95)), 'mean': float(distances.mean()),
            'count': int(distances.size), 'square_length': square,
            'error_pct': (median - square) / square * 100.0}


def summary_lines(result, corners, board, detections):
    """The printed summary (list of lines)."""
    lines = [f'board: {board.describe()}',
             f'root (world frame): {result.root}; tree: '
             + (', '.join(f'{a}-{b} ({n} shared views)' for a, b, n in result.tree) or '-')]
    frames = {d.name: (len(d.corners), len(d.no_board)) for d in detections}
    lines.append(f'{"camera":<14}{"frames":>7}{"no board":>9}{"views":>6}{"corners":>8}'
                 f'{"mean px":>9}{"p95 px":>8}{"fx":>9}{"fy":>9}{"cx":>8}{"cy":>8}'
                 f'{"k1":>8}{"k2":>8}')
    for row in camera_table(result):
        n, none = frames[row['name']]
        lines.append(f'{row["name"]:<14}{n:>7}{none:>9}{row["views"]:>6}{row["corners"]:>8}'
                     f'{row["mean_px"]:>9.3f}{row["p95_px"]:>8.3f}{row["fx"]:>9.1f}'
                     f'{row["fy"]:>9.1f}{row["cx"]:>8.1f}{row["cy"]:>8.1f}'
                     f'{row["dist"][0]:>8.4f}{row["dist"][1]:>8.4f}')
    for name, reason in result.left_out.items():
        n, none = frames[name]
        lines.append(f'{name:<14}{n:>7}{none:>9}  NOT CALIBRATED: {reason}')
    pairs = pair_table(result, corners)
    if pairs:
        lines.append(f'{"pair":<24}{"views":>6}{"corners":>8}{"stereo px":>10}')
        lines += [f'{p["a"] + " - " + p["b"]:<24}{p["views"]:>6}{p["corners"]:>8}'
                  f'{p["stereo_px"]:>10.3f}' for p in pairs]
    geometry = board_geometry(result, corners, board)
    if geometry['count']:
        lines.append(
            f'board geometry: adjacent corners triangulated {geometry["median"]:.3f} median '
            f'(p5 {geometry["p5"]:.3f}, p95 {geometry["p95"]:.3f}, {geometry["count"]} '
            f'pairs) vs square_length {geometry["square_length"]:g} (board units): '
            f'{geometry["error_pct"]:+.2f}%')
    else:
        lines.append('board geometry: no corner seen by 2 calibrated cameras (not measured)')
    lines.append(f'reprojection error (all corners): {result.errors.mean():.3f} px mean, '
                 f'{np.percentile(result.errors, 95):.3f} px p95 (before the bundle '
                 f'adjustment: {result.initial_errors.mean():.3f} px mean)')
    return lines
