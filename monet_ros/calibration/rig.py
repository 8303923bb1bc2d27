"""A rig's calibration from board detections: intrinsics, spanning-tree extrinsics, one
joint bundle adjustment, and the figures to judge it by (no ROS).

calibrate_rig(detections, board, CalibrationConfig(...)) -> CalibrationResult.
"""
from dataclasses import dataclass, field

import numpy as np

from monet_ros.calibration.bundle import LOSSES, Observations, bundle_adjust, to_camera
from monet_ros.calibration.detect import MIN_CORNERS
from monet_ros.calibration.extrinsics import (
    chain_extrinsics,
    components,
    initial_board_poses,
    pose_matrix,
    shared_views,
)
from monet_ros.calibration.intrinsics import (
    DISTORTION_MODELS,
    board_poses,
    calibrate_intrinsics,
)
from monet_ros.config import setting, validate_config


@dataclass(frozen=True)
class CalibrationConfig:
    """Options of `monet calibrate` (validated on construction; ConfigError names a field)."""

    distortion: str = setting('k1k2', 'lens distortion model (OpenCV k1 k2 p1 p2 k3 terms)',
                              choices=DISTORTION_MODELS)
    square_pixels: bool = setting(True, 'fx = fy')
    fix_principal_point: bool = setting(False, 'hold the principal point at the image '
                                        'centre')
    loss: str = setting('soft_l1', 'robust loss of the bundle adjustment', choices=LOSSES)
    f_scale_px: float = setting(1.0, 'robust loss scale (px)', minimum=0.0,
                                exclusive_minimum=True)
    min_views: int = setting(5, 'warn when a camera has fewer board views', minimum=1)
    high_error_px: float = setting(1.0, "warn when a camera's mean reprojection error is "
                                   'higher (px)', minimum=0.0, exclusive_minimum=True)
    max_nfev: int = setting(1000, 'most residual evaluations of the bundle adjustment',
                            minimum=1)

    def __post_init__(self):
        validate_config(self)


@dataclass
class CalibrationResult:
    """cameras: list[Camera] calibrated (world = the root camera's frame, board units);
    names: every input camera; left_out: {name: reason} of cameras not calibrated;
    board_poses: (F, 4, 4) board -> world per instant (NaN = not used); observations:
    Observations of the fit, errors (M,) px after it, initial_errors (M,) px before;
    intrinsics_rms: {name: OpenCV RMS px of the single-camera fit}; warnings: lines;
    tree: [(parent, child, shared views)]; bundle: scipy's figures (cost, nfev, status)."""

    cameras: list
    names: list
    left_out: dict
    board_poses: np.ndarray
    observations: Observations
    errors: np.ndarray
    initial_errors: np.ndarray
    intrinsics_rms: dict
    tree: list
    root: str
    shared: np.ndarray
    bundle: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


def stack_detections(detections):
    """(C, F, N, 2) corners of per-camera detections with equal frame counts; ValueError
    naming the cameras and counts otherwise."""
    counts = {d.name: len(d.corners) for d in detections}
    if len(set(counts.values())) > 1:
        raise ValueError('frame counts do not match across cameras ('
                         + ', '.join(f'{n}: {c}' for n, c in counts.items())
                         + '); pair frames with --timestamps CSV')
    return np.stack([d.corners for d in detections])


def board_notes(detections):
    """'; ...' sentences on a camera's frames whose board was seen mirrored or that hold
    markers not fitting the board (CameraDetections.mirrored / hint), or ''."""
    notes = ''
    if detections.mirrored:
        notes += (f'; the board is seen mirrored (left-right) in {len(detections.mirrored)} '
                  'frames: a mirror, or a camera that flips its images; flip its images '
                  'and run again (a mirrored view has no camera model)')
    if detections.hint:
        notes += f'; {detections.hint}'
    return notes


def calibrate_rig(detections, board, config=CalibrationConfig(), fixed_intrinsics=None):
    """Calibrate the cameras of `detections` (list of CameraDetections, frames paired by
    index: instant f of every camera is corners[f]).

    fixed_intrinsics: {name: Camera} whose K and dist are kept (extrinsics only are fit);
    every camera must be in it. Cameras with fewer than 3 board views (no intrinsics) or
    no shared view with the largest connected group are left out with a warning.
    Raises ValueError when fewer than two cameras can be calibrated (naming why each other
    one is left out: too few board views, a board seen mirrored, markers that do not fit
    the board spec)."""
    names = [d.name for d in detections]
    corners = stack_detections(detections)
    C, F = corners.shape[:2]
    warnings, left_out, intrinsics, rms = [], {}, {}, {}
    for c, d in enumerate(detections):
        views = int((np.isfinite(corners[c, ..., 0]).sum(axis=1) >= MIN_CORNERS).sum())
        if views < config.min_views:
            warnings.append(f'camera {d.name!r}: only {views} board views (fewer than '
                            f'{config.min_views}): its calibration is poorly constrained')
        if fixed_intrinsics is not None:
            cam = fixed_intrinsics.get(d.name)
            if cam is None:
                raise ValueError(f'--intrinsics: no camera {d.name!r} in the calibration '
                                 f'({", ".join(fixed_intrinsics)})')
            if (cam.width, cam.height) != tuple(d.size):
                raise ValueError(f'--intrinsics: camera {d.name!r} is {cam.width}x{cam.height} '
                                 f'there, its images are {d.size[0]}x{d.size[1]}')
            dist = np.zeros(5)
            if cam.dist.size > 5 and np.any(cam.dist[5:]):
                raise ValueError(f'--intrinsics: camera {d.name!r} has rational / prism '
                                 'distortion terms; only k1 k2 p1 p2 k3 are supported')
            dist[:min(5, cam.dist.size)] = cam.dist[:5]
            intrinsics[c] = (np.array(cam.K), dist)
            continue
        if views < 3:
            left_out[d.name] = f'{views} board views (intrinsics need 3)' + board_notes(d)
            continue
        fit = calibrate_intrinsics(corners[c], board, d.size, config.distortion,
                                   config.square_pixels, config.fix_principal_point)
        intrinsics[c] = (fit['K'], fit['dist'])
        rms[d.name] = fit['rms']
    poses = []
    for c in range(C):
        if c not in intrinsics:
            poses.append({})
            continue
        frames, rvecs, tvecs = board_poses(corners[c], board, *intrinsics[c])
        poses.append({int(f): pose_matrix(r, t) for f, r, t in zip(frames, rvecs, tvecs)})
    shared = shared_views(poses)
    usable = [c for c in range(C) if c in intrinsics and poses[c]]
    groups = [g for g in components(shared[np.ix_(usable, usable)])]
    if not groups:
        raise ValueError('no camera has enough board views to calibrate ('
                         + '; '.join(f'{n}: {r}' for n, r in left_out.items()) + ')')
    group = [usable[i] for i in groups[0]]
    for other in groups[1:]:
        for i in other:
            left_out[names[usable[i]]] = 'no board view shared with ' + ', '.join(
                names[g] for g in group)
    if len(group) < 2:
        raise ValueError(f'only camera {names[group[0]]!r} can be calibrated; a rig needs 2 ('
                         + '; '.join(f'{n}: {r}' for n, r in left_out.items()) + ')')
    for c in group:
        if detections[c].mirrored:
            warnings.append(f'camera {names[c]!r}:{board_notes(detections[c])[1:]} (those '
                            'frames are not used)')
    for name, reason in left_out.items():
        warnings.append(f'camera {name!r} is NOT calibrated: {reason}')
    root, extrinsics, tree = chain_extrinsics(poses, group)
    poses0 = initial_board_poses(poses, extrinsics, F)
    posed = np.flatnonzero(np.isfinite(poses0[:, 0, 0]))
    obs = Observations.from_corners(corners, group, posed)
    fit = bundle_adjust(board, obs, {c: intrinsics[c] for c in group}, extrinsics, poses0,
                        root, config.distortion, fixed_intrinsics is None,
                        config.square_pixels, config.fix_principal_point, config.loss,
                        config.f_scale_px, config.max_nfev)
    cameras = [to_camera(names[c], detections[c].size, *fit['intrinsics'][c],
                         fit['extrinsics'][c]) for c in group]
    for c in group:
        mine = fit['errors'][obs.camera == c]
        if mine.size and mine.mean() > config.high_error_px:
            warnings.append(f'camera {names[c]!r}: mean reprojection error {mine.mean():.2f} '
                            f'px is high (> {config.high_error_px:g} px): check its '
                            'detections, its distortion model (--distortion) and the pairing')
    if fit['status'] <= 0:
        warnings.append(f'bundle adjustment did not converge: {fit["message"]}')
    return CalibrationResult(
        cameras=cameras, names=names, left_out=left_out, board_poses=fit['board_poses'],
        observations=obs, errors=fit['errors'], initial_errors=fit['initial_errors'],
        intrinsics_rms=rms, tree=[(names[p], names[c], n) for p, c, n in tree],
        root=names[root], shared=shared,
        bundle={k: fit[k] for k in ('cost', 'nfev', 'status', 'message')},
        warnings=warnings)
