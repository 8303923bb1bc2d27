"""The offline 3D filters on a known trajectory: a `monet synth` human (constant bone
lengths) seen by an 8-camera synthetic ring through noisy 2D with 10% gross outliers and
dropped views. Accuracy is measured against the subject's true 3D and compared with
frame-by-frame robust triangulation of the same 2D (fusion.fuse_points)."""
import numpy as np
import pytest

from monet_ros.config import ConfigError
from monet_ros.fusion import FusionConfig, fuse_frames
from monet_ros.skeleton import load_skeleton
from monet_ros.synth import RigConfig, Subject, make_rig
from monet_ros.synth.noisy2d import noisy_detections
from monet_ros.temporal import FilterConfig, kalman_smooth, smooth_points

FPS = 30.0
T = 90


@pytest.fixture(scope='module')
def scene():
    skeleton = load_skeleton('human14')
    cameras = make_rig(RigConfig(num_cameras=8), seed=3)
    stamps = np.round(np.arange(T) * 1e9 / FPS).astype(np.int64)
    truth = Subject(skeleton, seed=5).keypoints3d(stamps / 1e9)
    noisy = noisy_detections(truth, cameras, noise_px=1.0, outlier_fraction=0.1,
                             drop_fraction=0.05, seed=7)
    return skeleton, cameras, stamps, truth, noisy


def frame_by_frame(points2d, score, cameras):
    """fuse_frames (fuse_points of every frame) -> X (T, C, 3), confidence, error."""
    r = fuse_frames(points2d, score, cameras, FusionConfig())
    return r['X'], r['score'], r['error']


def errors_mm(X, truth):
    e = np.linalg.norm(X - truth, axis=-1) * 1000
    return e[np.isfinite(e)]


def test_optimisation_recovers_trajectory_and_bone_lengths(scene):
    skeleton, cameras, stamps, truth, noisy = scene
    X, conf, err = frame_by_frame(noisy.points2d, noisy.score, cameras)
    raw = errors_mm(X, truth)
    s = smooth_points(X, conf, noisy.points2d, noisy.score, cameras, stamps,
                      skeleton.bone_indices, FilterConfig(method='optim'), error=err)
    out = errors_mm(s.X, truth)
    assert out.size == T * 14                         # every joint at every frame
    # stated bound: median <= 5 mm, p90 <= 8 mm (1 px noise, 8 cameras 4 m away)
    assert np.median(out) <= 5.0 and np.percentile(out, 90) <= 8.0, (
        np.median(out), np.percentile(out, 90))
    # and far better than frame-by-frame robust triangulation of the same 2D
    assert np.percentile(out, 90) < 0.5 * np.percentile(raw, 90)
    assert out.mean() < 0.5 * raw.mean() and out.max() < 0.25 * raw.max()
    # bone lengths constant: spread over frames within 3 mm, estimated lengths within 5 mm
    edges = np.array(skeleton.bone_indices)
    lengths = np.linalg.norm(s.X[:, edges[:, 0]] - s.X[:, edges[:, 1]], axis=-1)
    true_lengths = np.linalg.norm(truth[:, edges[:, 0]] - truth[:, edges[:, 1]], axis=-1)
    assert lengths.std(axis=0).max() * 1000 < 3.0
    np.testing.assert_allclose(s.lengths, true_lengths.mean(0), atol=5e-3)
    # outputs: change = |filtered - raw| (mm), confidence in [0, 1], errors recomputed
    np.testing.assert_allclose(s.change_mm, np.linalg.norm(s.X - X, axis=-1) * 1000)
    assert np.all((s.score >= 0) & (s.score <= 1))
    for t, c in [(10, 3), (45, 7), (80, 12)]:      # error / ncams: views within 15 px
        d = np.array([np.linalg.norm(cameras[v].project(s.X[t, c][None])[0]
                                     - noisy.points2d[t, v, c]) for v in range(8)])
        used = (noisy.score[t, :, c] >= 0.1) & (d <= 15.0)
        assert s.ncams[t, c] == used.sum() >= 2
        assert abs(d[used].mean() - s.error[t, c]) < 1e-9


def test_kalman_smoother_beats_frame_by_frame(scene):
    skeleton, cameras, stamps, truth, noisy = scene
    X, conf, err = frame_by_frame(noisy.points2d, noisy.score, cameras)
    raw = errors_mm(X, truth)
    s = smooth_points(X, conf, noisy.points2d, noisy.score, cameras, stamps,
                      config=FilterConfig(method='kalman'), error=err)
    out = errors_mm(s.X, truth)
    assert out.size >= X.shape[0] * 14 - 2
    # stated bound: p90 <= 10 mm, and a third of frame-by-frame's p90 or better
    assert np.percentile(out, 90) <= 10.0, np.percentile(out, 90)
    assert np.percentile(out, 90) < np.percentile(raw, 90) / 3
    assert out.mean() < raw.mean() / 2
    assert np.median(out) < np.median(raw)


def test_filters_bridge_short_gaps_and_flag_them(scene):
    skeleton, cameras, stamps, truth, noisy = scene
    points = noisy.points2d.copy()
    score = noisy.score.copy()
    wrist = skeleton.index('l_wrist')
    short = slice(30, 35)     # 5 frames = 0.17 s <= max_gap_s 0.25 s: bridged
    long = slice(50, 70)      # 20 frames = 0.67 s: left empty
    for gap in (short, long):
        points[gap, :, wrist] = np.nan
        score[gap, :, wrist] = 0.0
    X, conf, err = frame_by_frame(points, score, cameras)
    assert np.isnan(X[short, wrist]).all() and np.isnan(X[long, wrist]).all()
    for method in ('kalman', 'optim'):
        s = smooth_points(X, conf, points, score, cameras, stamps, skeleton.bone_indices,
                          FilterConfig(method=method, max_gap_s=0.25), error=err)
        assert s.bridged[short, wrist].all() and np.isfinite(s.X[short, wrist]).all()
        gap_err = np.linalg.norm(s.X[short, wrist] - truth[short, wrist], axis=-1)
        assert gap_err.max() < 0.04, (method, gap_err)   # within 40 mm across 0.17 s
        assert np.isnan(s.X[long, wrist]).all() and not s.bridged[long, wrist].any()
        assert s.score[short, wrist].max() == 0.0 if method == 'kalman' else True
        # outside the gaps only frames whose raw point was missing are flagged
        flagged = s.bridged.copy()
        flagged[short, wrist] = False
        assert not (flagged & np.isfinite(X).all(-1)).any()
        assert f'{int(s.bridged.sum())} bridged' in s.summary()


def test_kalman_gates_a_gross_outlier_and_smooths_noise():
    rng = np.random.default_rng(0)
    Tn = 120
    stamps = np.round(np.arange(Tn) * 1e9 / 60).astype(np.int64)
    t = stamps / 1e9
    truth = np.stack([0.5 * t, 0.2 + 0.0 * t, 1.0 - 0.1 * t], -1)[:, None]   # constant velocity
    X = truth + rng.normal(0, 0.01, truth.shape)                              # 10 mm noise
    X[60, 0] += [0.4, 0.0, 0.0]                                               # 400 mm off
    X[80:83] = np.nan                                                         # a gap
    r = kalman_smooth(X, stamps, FilterConfig(measurement_noise_mm=10.0, max_gap_s=0.1))
    assert r.rejected[60, 0] and r.rejected.sum() == 1
    # bridged: no measurement used (the gap and the gated-out frame)
    assert r.bridged[80:83, 0].all() and r.bridged[60, 0] and r.bridged.sum() == 4
    err = np.linalg.norm(r.X - truth, axis=-1)[:, 0]
    raw = np.linalg.norm(X - truth, axis=-1)[:, 0]
    assert err[60] < 0.01                     # the outlier did not move the estimate
    # a constant-velocity path: the smoother averages the noise down (RMS < half the raw)
    ok = np.isfinite(raw) & (np.arange(Tn) != 60)
    assert np.sqrt(np.mean(err[ok] ** 2)) < 0.5 * np.sqrt(np.mean(raw[ok] ** 2))
    assert np.all(r.sd_mm[np.isfinite(r.sd_mm)] > 0)


def test_filter_config_rejects_bad_values():
    from monet_ros.config import ConfigError
    with pytest.raises(ConfigError, match='method'):
        FilterConfig(method='butterworth')
    with pytest.raises(ConfigError, match='max_gap_s'):
        FilterConfig(max_gap_s=-1.0)
    with pytest.raises(ConfigError, match='acceleration_m_s2'):
        FilterConfig(acceleration_m_s2=0.0)


def test_a_joint_never_triangulated_or_started_late_is_no_error():
    """A keypoint with no 3D point until late in the recording (or never: a joint no view
    saw) has only process noise before its start, a rank-1 covariance (exactly singular at
    4 Hz: powers of two); the smoother must leave it NaN there and smooth the rest (it
    raised LinAlgError: singular matrix)."""
    stamps = np.arange(40, dtype=np.int64) * 250_000_000       # 4 Hz
    t = stamps / 1e9
    X = np.stack([np.stack([t, np.sin(t), np.zeros_like(t) + 2.0], -1)] * 3, axis=1)
    X[:, 1] = np.nan                        # never measured
    X[:25, 2] = np.nan                      # measured from frame 25 on
    result = kalman_smooth(X, stamps, FilterConfig())
    assert np.isnan(result.X[:, 1]).all() and np.isnan(result.X[:25, 2]).all()
    assert np.allclose(result.X[25:, 2], X[25:, 2], atol=0.01)
    assert np.allclose(result.X[:, 0], X[:, 0], atol=0.01)


# Issue 37: a Kalman setting whose square overflows (or underflows to 0) in the rig's unit
# is refused naming it, as the live filter's; every accepted one smooths to finite points.
# The settings keep their units (mm, m/s^2) and are checked once converted into the rig's:
# measurement_noise_mm 1e155 is (1e152 m)^2 in a metre rig but (1e155 mm)^2 = inf in a
# millimetre one; 1e-160 mm underflows to 0 only in metres.
UNITS = ('m', 'cm', 'mm')


@pytest.mark.parametrize('units', UNITS)
@pytest.mark.parametrize('name', ['measurement_noise_mm', 'acceleration_m_s2', 'gate_sigma',
                                  'max_gap_s'])
@pytest.mark.parametrize('value', [5e-324, 1e-200, 1e-160, 1e155, 1e200,
                                   1.7976931348623157e308])
def test_extreme_kalman_settings_are_refused_by_name_or_smooth_finitely(units, name, value):
    config = FilterConfig(method='kalman', **{name: value})     # inside the declared range
    try:
        physical = config.in_units(units)
    except ConfigError as error:
        assert error.field == name, str(error)
        assert repr(value) in str(error), str(error)
        return
    # accepted: the numbers in the rig unit are usable (computed here in Python floats)
    per_metre = {'m': 1.0, 'cm': 100.0, 'mm': 1000.0}[units]
    noise = config.measurement_noise_mm * per_metre / 1000.0
    assert 0 < physical.r2 < float('inf') and physical.r2 == pytest.approx(noise * noise)
    rng = np.random.default_rng(1)
    X = (rng.normal(0, 0.01, (6, 4, 3)) + [0.0, 0.0, 1.0]) * per_metre
    X[2, 1] = np.nan
    stamps = np.arange(6) * 33_000_000 + 10 ** 18
    result = kalman_smooth(X, stamps, config, units=units)
    seen = ~np.isnan(result.X)
    assert seen.any() and np.isfinite(result.X[seen]).all(), (name, value)


def test_a_noise_is_checked_in_the_rig_unit():
    huge = FilterConfig(method='kalman', measurement_noise_mm=1e155)
    assert huge.in_units('m').r2 == pytest.approx(1e304)
    with pytest.raises(ConfigError, match=r"'measurement_noise_mm': 1e\+155 gives a "
                       r'measurement variance of 1e\+308 cm\^2 whose innovation variance'):
        huge.in_units('cm')             # finite, but twice it is not
    with pytest.raises(ConfigError, match=r"^FilterConfig: parameter 'measurement_noise_mm': "
                       r'1e\+155 gives a measurement variance of inf mm\^2 '):
        huge.in_units('mm')
    tiny = FilterConfig(method='kalman', measurement_noise_mm=1e-160)
    with pytest.raises(ConfigError, match=r'of 0\.0 m\^2 \(must be finite and > 0\)'):
        tiny.in_units('m')
    assert tiny.in_units('mm').r2 > 0
    with pytest.raises(ConfigError, match="'acceleration_m_s2': 1e\\+153 gives a process "
                       r'noise variance of inf \(mm/s\^2\)\^2'):
        FilterConfig(method='kalman', acceleration_m_s2=1e153).in_units('mm')


@pytest.mark.parametrize('units, value', [('m', '1e200'), ('mm', '1e155')])
def test_the_filter_options_name_the_option(tmp_path, capsys, units, value):
    from monet_ros.cli import main
    from monet_ros.geometry import save_rig
    from monet_ros.geometry.units import rescale
    rig = tmp_path / 'rig.yaml'
    save_rig(rig, rescale(make_rig(RigConfig(num_cameras=3), seed=3), units))
    code = main(['triangulate', str(tmp_path / 'absent.csv'), '--rig', str(rig), '--out',
                 str(tmp_path / 'out'), '--fps', '30', '--filter', 'kalman',
                 '--measurement-noise-mm', value])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0] == ("monet triangulate: error: --measurement-noise-mm: FilterConfig: "
                      f"parameter 'measurement_noise_mm': {float(value)!r} "
                      f'gives a measurement variance of inf {units}^2 (must be finite and '
                      '> 0)'), err
    assert not (tmp_path / 'out').exists()
