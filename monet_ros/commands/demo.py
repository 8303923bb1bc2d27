"""`monet demo`: triangulate the Pose2Sim demo trial and compare with Pose2Sim's result.

Temporary main job of `make demo` until the live pipeline exists: it loads the Qualisys
calibration (Pose2Sim TOML), the pose-associated OpenPose BODY_25B detections of the 4
cameras, triangulates every marker of every frame with Pose2Sim's rule (likelihood >= 0.3
as weights, worst-camera exclusion at 15 px, >= 2 cameras) and reports the agreement with
Pose2Sim's own .trc and the reprojection error per camera. Without the data (or with
--synthetic) it triangulates a synthetic subject seen by a generated 8-camera rig instead.
"""
from dataclasses import dataclass
import os
from pathlib import Path
import sys
import time

import numpy as np

from monet_ros.config import setting, validate_config

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


@dataclass(frozen=True)
class DemoOptions:
    """The numeric options of `monet demo` (validated; errors name the option)."""
    threshold_px: float = setting(15.0, 'exclusion threshold (px)', minimum=0.0,
                                  exclusive_minimum=True)
    likelihood: float = setting(0.3, 'minimum OpenPose likelihood', minimum=0.0, maximum=1.0)

    def __post_init__(self):
        validate_config(self)


def add_arguments(parser):
    parser.add_argument('--data', type=Path, default=None,
                        help='shared data folder (default: ../shared/data beside the repo)')
    parser.add_argument('--threshold-px', type=float, default=15.0,
                        help='exclusion threshold on the mean reprojection error (px)')
    parser.add_argument('--likelihood', type=float, default=0.3,
                        help='minimum OpenPose likelihood of a detection')
    parser.add_argument('--undistort', action='store_true',
                        help='use the lens distortion (Pose2Sim ran without: pinhole)')
    parser.add_argument('--synthetic', action='store_true',
                        help='generated rig + subject instead of the Pose2Sim data')


def run_synthetic(frames=100, num_cameras=8, noise_px=0.5, outlier_rate=0.1, seed=0):
    """Triangulate a synthetic human14 subject seen by a generated ring rig, with noise and
    gross outliers; report the 3D error and the reprojection error per camera."""
    from monet_ros.geometry import project_views, reprojection_error, triangulate_robust
    from monet_ros.skeleton import load_skeleton
    from monet_ros.synth import RigConfig, Subject, make_rig

    rng = np.random.default_rng(seed)
    cameras = make_rig(RigConfig(num_cameras=num_cameras), seed=seed)
    truth = Subject(load_skeleton('human14'), seed=seed).keypoints3d(np.arange(frames) / 30.0)
    T, C = truth.shape[:2]
    points = project_views(cameras, truth.reshape(-1, 3))  # (V, T*C, 2)
    points += rng.normal(scale=noise_px, size=points.shape)
    bad = rng.random(points.shape[:2]) < outlier_rate
    points[bad] += 50.0
    start = time.perf_counter()
    X, inliers = triangulate_robust(points, cameras, threshold_px=3.0, method='ransac')
    elapsed = time.perf_counter() - start
    err3d = np.linalg.norm(X - truth.reshape(-1, 3), axis=1) * 1000.0
    print(f'synthetic demo: {T} frames x {C} keypoints, {len(cameras)} cameras, '
          f'{noise_px} px noise, {bad.mean():.0%} outliers (+50 px); triangulated '
          f'{np.isfinite(X[:, 0]).sum()} in {elapsed * 1e3:.1f} ms; 3D error mean '
          f'{np.nanmean(err3d):.2f} mm, outliers flagged {(~inliers & bad).sum()}/{bad.sum()}')
    err = reprojection_error(X, points, cameras)
    print(f'{"camera":<8} {"used":>6} {"excluded":>9} {"mean reproj. error (px)":>24}')
    for v, cam in enumerate(cameras):
        print(f'{cam.name:<8} {inliers[v].sum():>6} {(~inliers[v]).sum():>9} '
              f'{np.nanmean(err[v][inliers[v]]):>24.2f}')
    return 0


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
    from monet_ros.geometry.units import from_m, rig_units, to_mm

    DemoOptions(threshold_px=args.threshold_px, likelihood=args.likelihood)
    if args.synthetic:
        return run_synthetic()
    root = args.data or default_data_root()
    trial = root / TRIAL
    if not trial.is_dir():
        if args.data is not None:
            raise FileNotFoundError(2, 'Pose2Sim demo data not found', str(trial))
        _log(f'Pose2Sim demo data not found at {trial} (use --data DIR): synthetic demo')
        return run_synthetic()
    cameras = load_rig(root / CALIBRATION)
    # inputs are all read before anything is logged: a bad file is the one line printed
    notes = [f'calibration: {len(cameras)} cameras ({", ".join(c.name for c in cameras)})']
    folders = sorted((trial / 'pose-associated').glob('cam*_json'))
    if len(folders) != len(cameras):
        raise ValueError(f'{trial / "pose-associated"}: {len(folders)} detection folders '
                         f'(cam*_json) for the {len(cameras)} cameras of {CALIBRATION.name}')
    detections = []
    for folder in folders:
        detections.append(read_openpose_folder(folder))
        notes.append(f'  read {folder.name}: {len(detections[-1])} frames')
    counts = {folder.name: len(d) for folder, d in zip(folders, detections)}
    if len(set(counts.values())) != 1:
        raise ValueError(f'{trial / "pose-associated"}: the cameras have different numbers '
                         f'of frames {counts}')
    detections = np.stack(detections)  # (V, F, 25, 3)
    trc_path = next(iter(sorted((trial / 'pose-3d').glob('*.trc'))), None)
    if trc_path is None:
        raise FileNotFoundError(2, "no Pose2Sim .trc file (Pose2Sim's 3D result)",
                                str(trial / 'pose-3d'))
    names, _, trc = read_trc(trc_path)
    unknown = [name for name in names if name not in BODY_25B_IDS]
    if unknown:
        raise ValueError(f'{trc_path}: marker {unknown[0]!r} is not a BODY_25B keypoint')
    ids = [BODY_25B_IDS[name] for name in names]
    V, F = detections.shape[:2]
    if len(trc) != F:
        raise ValueError(f'{trc_path}: {len(trc)} rows, the detections have {F} frames')
    points = detections[:, :, ids, :2].reshape(V, F * len(ids), 2)
    likelihood = detections[:, :, ids, 2].reshape(V, F * len(ids))
    weights = np.where(likelihood >= args.likelihood, likelihood, 0.0)
    rig = cameras if args.undistort else [c.without_distortion() for c in cameras]
    for note in notes:
        _log(note)

    start = time.perf_counter()
    X, inliers = triangulate_robust(points, rig, weights, threshold_px=args.threshold_px,
                                    min_views=2, method='exclusion')
    elapsed = time.perf_counter() - start
    units = rig_units(cameras)               # Pose2Sim's .trc is in metres
    expected = from_m(trc_to_world(trc).reshape(-1, 3), units)
    diff_mm = to_mm(np.linalg.norm(X - expected, axis=1), units)
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
