"""`monet calibrate` speed on the real sleap-anipose session (4 cameras x 21 ChArUco images,
1280x1024): wall time of the board detection and of the calibration (intrinsics, spanning
tree, joint bundle adjustment), median of several runs, with OpenCV's own two-camera
calibration (calibrateCamera per camera + stereoCalibrate) side by side for back + mid,
and each result's back / mid focal lengths and reprojection error.

usage: python bench/calibrate.py [--runs 3] [--data ../shared/data]
"""
import argparse
import os
from pathlib import Path
import statistics
import sys
import time

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from monet_ros.calibration.board import load_board  # noqa: E402
from monet_ros.calibration.detect import BoardDetector, detect_frames  # noqa: E402
from monet_ros.calibration.intrinsics import calibrate_intrinsics  # noqa: E402
from monet_ros.calibration.rig import CalibrationConfig, calibrate_rig  # noqa: E402

CAMERAS = ('back', 'mid', 'side', 'top')


def timed(fn, runs):
    times, out = [], None
    for _ in range(runs):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), out


def detect_all(root, board):
    detector = BoardDetector(board)
    return [detect_frames(name, (cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in sorted(
        (root / name / 'calibration_images').glob('*.jpg'))), board, progress=False,
        detector=detector) for name in CAMERAS]


def opencv_stereo(detections, board):
    """calibrateCamera (k1 k2) per camera, then stereoCalibrate on the shared corners."""
    fits = [calibrate_intrinsics(d.corners, board, d.size, 'k1k2') for d in detections]
    both = np.isfinite(detections[0].corners[..., 0]) & np.isfinite(
        detections[1].corners[..., 0])
    frames = np.flatnonzero(both.sum(axis=1) >= 6)
    obj = [board.object_points[both[f]].astype(np.float32) for f in frames]
    img = [[d.corners[f][both[f]].astype(np.float32) for f in frames] for d in detections]
    rms, K1, d1, K2, d2, R, T, _, _ = cv2.stereoCalibrate(
        obj, img[0], img[1], fits[0]['K'], fits[0]['dist'], fits[1]['K'], fits[1]['dist'],
        detections[0].size, flags=cv2.CALIB_FIX_INTRINSIC)
    return rms, K1[0, 0], K2[0, 0]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=3)
    parser.add_argument('--data', default=str(Path(__file__).resolve().parents[2] / 'shared'
                                              / 'data'))
    args = parser.parse_args()
    root = Path(args.data) / 'sleap_anipose_minimal_session'
    board = load_board(root / 'board.toml')
    print(f'load average before: {os.getloadavg()}  (cores: {os.cpu_count()})')
    t_detect, detections = timed(lambda: detect_all(root, board), args.runs)
    images = sum(len(d.corners) for d in detections)
    print(f'detection: {t_detect:.2f} s for {images} images ({1000 * t_detect / images:.0f} '
          'ms / image), median of', args.runs)
    config = CalibrationConfig(distortion='k1k2')
    rows = []
    for names in (('back', 'mid'), CAMERAS):
        chosen = [d for d in detections if d.name in names]
        t, result = timed(lambda chosen=chosen: calibrate_rig(chosen, board, config),
                          args.runs)
        cams = {c.name: c for c in result.cameras}
        rows.append((f'monet calibrate ({"+".join(names)})', t, result.errors.mean(),
                     cams['back'].K[0, 0], cams['mid'].K[0, 0], result.bundle['nfev']))
    t, (rms, f_back, f_mid) = timed(lambda: opencv_stereo(detections[:2], board), args.runs)
    rows.append(('OpenCV calibrateCamera + stereoCalibrate (back+mid)', t, rms, f_back,
                 f_mid, '-'))
    print(f'{"calibration":<54}{"wall s":>8}{"err px":>8}{"f back":>8}{"f mid":>8}'
          f'{"nfev":>6}')
    for name, t, err, fb, fm, nfev in rows:
        print(f'{name:<54}{t:>8.2f}{err:>8.3f}{fb:>8.1f}{fm:>8.1f}{nfev!s:>6}')
    print('reference (sleap-anipose calibration.toml): f back 769.9, f mid 759.1; err px is '
          "the mean corner error (ours) / OpenCV's stereo RMS")
    print(f'load average after: {os.getloadavg()}')


if __name__ == '__main__':
    main()
