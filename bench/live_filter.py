"""The fusion node's live filter (temporal.live.LiveFilter): cost per frame, accuracy, lag.

Synthetic keypoints with a known truth:
  walk      the human14 `monet synth` subject walking, 30 Hz, 20 s; measured = truth +
            NOISE_MM Gaussian noise per axis, OUTLIER_RATE of the joints moved 0.3 m in a
            random direction (a wrong view kept), MISSING_RATE NaN (not triangulated)
  sine      one joint on x = 0.2 m sin(2 pi f t) (f = 0.5, 1, 2 Hz), 30 Hz, NOISE_MM noise:
            the lag is the time shift of the truth that fits the filtered output best
            (sub-frame, linear interpolation), i.e. the delay the constant-velocity model
            adds while the joint accelerates (0 for constant speed)
Cost: LiveFilter.update per frame at 14 joints (median of --runs runs over the walk),
beside the raw output (no filter) and a per-joint loop with 6x6 matrices (the textbook
form). Accuracy: 3D error (mm) of raw and filtered against the truth (median / p90 / max
of the per-frame errors; outliers included in raw). A sweep over filter_acceleration and
filter_noise_mm shows how the defaults were chosen.

usage: python bench/live_filter.py [--runs 7]
"""
import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')  # one core, before numpy loads BLAS

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from monet_ros.skeleton import load_skeleton  # noqa: E402
from monet_ros.synth.subject import Subject  # noqa: E402
from monet_ros.temporal.live import LiveFilter, LiveFilterConfig  # noqa: E402

RATE = 30.0
NOISE_MM = 20.0
OUTLIER_RATE = 0.03
MISSING_RATE = 0.02


def walk(rng, seconds=20.0):
    t = np.arange(int(seconds * RATE)) / RATE
    truth = Subject(load_skeleton('human14'), seed=4).keypoints3d(t)
    measured = truth + rng.normal(0, NOISE_MM * 1e-3, truth.shape)
    bad = rng.random(truth.shape[:2]) < OUTLIER_RATE
    direction = rng.normal(size=truth.shape)
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    measured[bad] += 0.3 * direction[bad]
    measured[rng.random(truth.shape[:2]) < MISSING_RATE] = np.nan
    return (t * 1e9).astype(np.int64), truth, measured


def run_filter(config, stamps, measured):
    f = LiveFilter(config)
    return np.stack([f.update(s, X)[0] for s, X in zip(stamps, measured)])


def errors_mm(X, truth):
    e = 1e3 * np.linalg.norm(X - truth, axis=-1).reshape(-1)
    return e[np.isfinite(e)]


def reference_loop(config, stamps, measured):
    """The same filter as textbook matrices, one joint at a time (6-state x, P 6x6)."""
    r2 = (config.filter_noise_mm * 1e-3) ** 2
    q = config.filter_acceleration ** 2
    J = measured.shape[1]
    x = np.zeros((J, 6))
    P = np.zeros((J, 6, 6))
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    live = [False] * J
    out = []
    last = None
    for stamp, X in zip(stamps, measured):
        dt = 0.0 if last is None else (stamp - last) * 1e-9
        last = stamp
        F = np.eye(6)
        F[:3, 3:] = dt * np.eye(3)
        G = np.vstack([dt * dt / 2 * np.eye(3), dt * np.eye(3)])
        Q = q * G @ G.T
        frame = np.full((J, 3), np.nan)
        for j in range(J):
            if live[j]:
                x[j] = F @ x[j]
                P[j] = F @ P[j] @ F.T + Q
                if np.isfinite(X[j]).all():
                    S = H @ P[j] @ H.T + r2 * np.eye(3)
                    y = X[j] - H @ x[j]
                    if y @ np.linalg.solve(S, y) <= config.filter_gate ** 2:
                        K = P[j] @ H.T @ np.linalg.inv(S)
                        x[j] = x[j] + K @ y
                        P[j] = (np.eye(6) - K @ H) @ P[j]
                frame[j] = x[j, :3]
            elif np.isfinite(X[j]).all():
                x[j] = np.concatenate([X[j], np.zeros(3)])
                P[j] = np.diag([r2] * 3 + [4.0] * 3)
                live[j] = True
                frame[j] = X[j]
        out.append(frame)
    return np.stack(out)


def median_ms(fn, runs, frames):
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) / frames)
    return 1e3 * float(np.median(times))


def lag_ms(filtered, truth_fn, t):
    """Shift (ms) of the truth that best fits the filtered trajectory (after 1 s warm-up)."""
    keep = t > 1.0
    shifts = np.arange(0, 0.2, 0.001)
    rms = [np.sqrt(np.mean((filtered[keep] - truth_fn(t[keep] - s)) ** 2)) for s in shifts]
    return 1e3 * shifts[int(np.argmin(rms))]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--runs', type=int, default=7)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    stamps, truth, measured = walk(rng)
    config = LiveFilterConfig(filter=True)
    print(f'load average {os.getloadavg()}; walk: {len(stamps)} frames x 14 joints at '
          f'{RATE:.0f} Hz, noise {NOISE_MM} mm, {100 * OUTLIER_RATE:.0f}% outliers (0.3 m), '
          f'{100 * MISSING_RATE:.0f}% missing')
    frames = len(stamps)
    short = slice(0, 60)
    ms = median_ms(lambda: run_filter(config, stamps, measured), args.runs, frames)
    ref = median_ms(lambda: reference_loop(config, stamps[short], measured[short]), args.runs,
                    60)
    print('\n## Cost per frame, 14 joints (median of runs)')
    print('| method | ms/frame |')
    print('|---|---|')
    print('| raw (no filter) | 0 |')
    print(f'| LiveFilter.update (batched over joints) | {ms:.4f} |')
    print(f'| per-joint loop, 6x6 matrices (reference) | {ref:.4f} |')
    X = run_filter(config, stamps, measured)
    # the check: measurements with noise only (the reference has neither the gap restarts
    # nor the velocity guards, which outliers and gaps set off)
    noisy = truth[short] + np.random.default_rng(1).normal(0, NOISE_MM * 1e-3,
                                                           truth[short].shape)
    check = reference_loop(config, stamps[short], noisy)
    gap = np.nanmax(np.abs(run_filter(config, stamps[short], noisy) - check)) * 1e3
    print(f'(batched vs reference loop, first 60 frames of noise-only measurements: max '
          f'difference {gap:.2e} mm)')
    print('\n## Accuracy on the walk (3D error, mm)')
    print('| output | median | p90 | p99 | max |')
    print('|---|---|---|---|---|')
    for name, out in (('raw', measured), ('filtered (defaults)', X)):
        e = errors_mm(out, truth)
        print(f'| {name} | {np.median(e):.1f} | {np.percentile(e, 90):.1f} | '
              f'{np.percentile(e, 99):.1f} | {e.max():.1f} |')
    print('\n## Sweep (walk median / p90 / p99 mm; sine 1 and 2 Hz lag ms)')
    print('| filter_acceleration m/s^2 | filter_noise_mm | walk median | walk p90 | walk p99 | '
          'lag 1 Hz | lag 2 Hz |')
    print('|---|---|---|---|---|---|---|')
    t = np.arange(int(10 * RATE)) / RATE
    for accel in (3.0, 5.0, 10.0, 25.0, 50.0):
        for noise in (10.0, 20.0, 40.0):
            c = LiveFilterConfig(filter=True, filter_acceleration=accel, filter_noise_mm=noise)
            e = errors_mm(run_filter(c, stamps, measured), truth)
            print(f'| {accel:g} | {noise:g} | {np.median(e):.1f} | {np.percentile(e, 90):.1f} | '
                  f'{np.percentile(e, 99):.1f} | {sine_lag(c, rng, t, 1.0):.0f} | '
                  f'{sine_lag(c, rng, t, 2.0):.0f} |')
    print('\n## Lag on x = 0.2 m sin(2 pi f t) (defaults)')
    print('| f Hz | peak acceleration m/s^2 | lag ms | RMS raw mm | RMS filtered mm |')
    print('|---|---|---|---|---|')
    for f in (0.5, 1.0, 2.0):
        lag, raw, filt = sine_lag(config, rng, t, f, full=True)
        print(f'| {f:g} | {0.2 * (2 * np.pi * f) ** 2:.1f} | {lag:.0f} | {raw:.1f} | '
              f'{filt:.1f} |')
    print(f'\nload average {os.getloadavg()}')
    return 0


def sine_lag(config, rng, t, f, full=False):
    def truth_fn(times):
        return 0.2 * np.sin(2 * np.pi * f * times)
    x = truth_fn(t)
    X = np.zeros((len(t), 1, 3))
    X[:, 0, 0] = x + rng.normal(0, NOISE_MM * 1e-3, len(t))
    out = run_filter(config, (t * 1e9).astype(np.int64), X)[:, 0, 0]
    lag = lag_ms(out, truth_fn, t)
    if not full:
        return lag
    keep = t > 1.0
    rms = [1e3 * np.sqrt(np.mean((a[keep] - x[keep]) ** 2)) for a in (X[:, 0, 0], out)]
    return lag, rms[0], rms[1]


if __name__ == '__main__':
    sys.exit(main())
