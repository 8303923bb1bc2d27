"""`monet demo`: triangulate the Pose2Sim demo trial and compare with Pose2Sim's result.

Temporary main job of `make demo` until the live pipeline exists: it loads the Qualisys
calibration (Pose2Sim TOML), the pose-associated OpenPose BODY_25B detections of the 4
cameras, triangulates every marker of every frame with Pose2Sim's rule (likelihood >= 0.3
as weights, worst-camera exclusion at 15 px, >= 2 cameras) and reports the agreement with
Pose2Sim's own .trc and the reprojection error per camera.
"""
import os
from pathlib import Path
import sys
import time

import numpy as np

HELP = 'triangulate the Pose2Sim demo (../shared/data) and compare with its .trc'
TRIAL = Path('pose2sim_demo_balancing/S00_P00_SingleParticipant/S00_P00_T01_BalancingTrial')
CALIBRATION = Path('pose2sim_demo_balancing/S00_Calibration/Calib_qualisys.toml')


def default_data_root():
    """$MONET_SHARED_DATA, else shared/data beside the repository (../shared/data)."""
    if os.environ.get('MONET_SHARED_DATA'):
        return Path(os.environ['MONET_SHARED_DATA'])
    repo = Path(__file__).resolve().parents[2]
    for root in (repo.parent, Path.cwd().parent):
        if (root / 'shared' / 'data').is_dir():
            return root / 'shared' / 'data'
    return repo.parent / 'shared' / 'data'


def add_arguments(parser):
    parser.add_argument('--data', type=Path, default=None,
                        help='shared data folder (default: ../shared/data beside the repo)')
    parser.add_argument('--threshold-px', type=float, default=15.0,
                        help='exclusion threshold on the mean reprojection error (px)')
    parser.add_argument('--likelihood', type=float, default=0.3,
                        help='minimum OpenPose likelihood of a detection')
    parser.add_argument('--undistort', action='store_true',
                        help='use the lens distortion (Pose2Sim ran without: pinhole)')


def _log(message):
    print(message, file=sys.stderr, flush=True)


def run(args):
    from monet_ros.geometry import load_rig, reprojection_error, triangulate_robust
    from monet_ros.geometry.pose2sim import (
        BODY_25B_IDS,
        read_openpose_folder,
        read_trc,
        trc_to_world,
    )

    root = args.data or default_data_root()
    trial = root / TRIAL
    if not trial.is_dir():
        print(f'monet demo: Pose2Sim demo data not found at {trial} (use --data DIR)',
              file=sys.stderr)
        return 2
    cameras = load_rig(root / CALIBRATION)
    _log(f'calibration: {len(cameras)} cameras ({", ".join(c.name for c in cameras)})')
    folders = sorted((trial / 'pose-associated').glob('cam*_json'))
    if len(folders) != len(cameras):
        print(f'monet demo: {len(folders)} detection folders for {len(cameras)} cameras',
              file=sys.stderr)
        return 2
    detections = []
    for folder in folders:
        detections.append(read_openpose_folder(folder))
        _log(f'  read {folder.name}: {len(detections[-1])} frames')
    detections = np.stack(detections)  # (V, F, 25, 3)
    trc_path = next((trial / 'pose-3d').glob('*.trc'))
    names, _, trc = read_trc(trc_path)
    ids = [BODY_25B_IDS[name] for name in names]
    V, F = detections.shape[:2]
    points = detections[:, :, ids, :2].reshape(V, F * len(ids), 2)
    likelihood = detections[:, :, ids, 2].reshape(V, F * len(ids))
    weights = np.where(likelihood >= args.likelihood, likelihood, 0.0)
    rig = cameras if args.undistort else [c.without_distortion() for c in cameras]

    start = time.perf_counter()
    X, inliers = triangulate_robust(points, rig, weights, threshold_px=args.threshold_px,
                                    min_views=2, method='exclusion')
    elapsed = time.perf_counter() - start
    expected = trc_to_world(trc).reshape(-1, 3)
    diff_mm = np.linalg.norm(X - expected, axis=1) * 1000.0
    ok = np.isfinite(X[:, 0])
    err = reprojection_error(X, points, rig)

    print(f'Pose2Sim demo: {F} frames x {len(ids)} markers = {F * len(ids)} points, '
          f'{V} cameras; triangulated {ok.sum()} in {elapsed * 1e3:.1f} ms '
          f'({elapsed / F * 1e3:.2f} ms/frame)')
    print(f'agreement with Pose2Sim .trc: {(diff_mm < 0.1).sum()} of {F * len(ids)} points '
          f'within 0.1 mm (max {np.nanmax(diff_mm):.2g} mm); {(~ok).sum()} not triangulated '
          '(Pose2Sim interpolated those)')
    print(f'{"camera":<8} {"used":>6} {"excluded":>9} {"mean reproj. error (px)":>24}')
    for v, cam in enumerate(rig):
        used = inliers[v]
        excluded = (weights[v] > 0) & ok & ~used
        print(f'{cam.name:<8} {used.sum():>6} {excluded.sum():>9} '
              f'{np.nanmean(err[v][used]):>24.2f}')
    return 0
