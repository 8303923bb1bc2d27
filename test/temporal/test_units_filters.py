"""The same recording with the rig in m, cm or mm is filtered the same: the filters'
settings keep their units (measurement_noise_mm, acceleration_m_s2, bone_mm, the live
filter's filter_noise_mm, filter_acceleration m/s^2, filter_max_speed m/s) whatever the
rig's, so the 3D (converted by the stated unit), the gating and the bridging are equal,
and change_mm is in mm. Before, a mm rig was read as metres: the Kalman gate rejected
most points and the live filter gated almost every frame."""
import numpy as np
import pytest

from monet_ros.fusion import FusionConfig, fuse_frames
from monet_ros.geometry.units import per_metre, rescale
from monet_ros.skeleton import load_skeleton
from monet_ros.synth import RigConfig, Subject, make_rig
from monet_ros.synth.noisy2d import noisy_detections
from monet_ros.temporal import FilterConfig, smooth_points
from monet_ros.temporal.live import LiveFilter, LiveFilterConfig

FPS = 30.0
T = 45
UNITS = ('m', 'cm', 'mm')


@pytest.fixture(scope='module')
def scene():
    """The synthetic human of test_filters (metres), its noisy 2D and raw triangulation."""
    skeleton = load_skeleton('human14')
    cameras = make_rig(RigConfig(num_cameras=6), seed=3)
    stamps = np.round(np.arange(T) * 1e9 / FPS).astype(np.int64)
    truth = Subject(skeleton, seed=5).keypoints3d(stamps / 1e9)
    noisy = noisy_detections(truth, cameras, noise_px=1.0, outlier_fraction=0.1,
                             drop_fraction=0.05, seed=7)
    return skeleton, cameras, stamps, truth, noisy


def filtered(scene, units, method):
    """smooth_points of the scene with the rig and the points expressed in `units`."""
    skeleton, cameras, stamps, truth, noisy = scene
    rig = rescale(cameras, units)
    raw = fuse_frames(noisy.points2d, noisy.score, rig, FusionConfig())
    return raw, smooth_points(raw['X'], raw['score'], noisy.points2d, noisy.score, rig,
                              stamps, skeleton.bone_indices, FilterConfig(method=method),
                              error=raw['error'])


@pytest.mark.parametrize('method', ['kalman', 'optim'])
def test_filters_give_the_same_result_in_m_cm_and_mm(scene, method):
    truth = scene[3]
    base_raw, base = filtered(scene, 'm', method)
    assert base.units == 'm'
    # in metres the filter does its job (an independent check: against the true 3D)
    err = np.linalg.norm(base.X - truth, axis=-1) * 1000.0
    assert np.nanpercentile(err, 90) < 15.0
    for units in ('cm', 'mm'):
        k = per_metre(units)
        raw, s = filtered(scene, units, method)
        assert s.units == units
        np.testing.assert_allclose(raw['X'] / k, base_raw['X'], atol=1e-9)
        np.testing.assert_array_equal(np.isfinite(s.X), np.isfinite(base.X))
        np.testing.assert_allclose(s.X / k, base.X, atol=1e-6 if method == 'kalman' else 2e-4)
        np.testing.assert_array_equal(s.rejected, base.rejected)
        np.testing.assert_array_equal(s.bridged, base.bridged)
        np.testing.assert_allclose(s.change_mm, base.change_mm, atol=0.2, equal_nan=True)
        np.testing.assert_allclose(s.lengths / k, base.lengths, atol=1e-9, equal_nan=True)
        # change_mm is millimetres whatever the unit: |filtered - raw| converted
        np.testing.assert_allclose(s.change_mm, np.linalg.norm(s.X - raw['X'], axis=-1)
                                   * 1000.0 / k)
        assert s.summary().split('; change')[0] == base.summary().split('; change')[0]


def test_kalman_in_mm_gates_no_more_than_in_m(scene):
    _, base = filtered(scene, 'm', 'kalman')
    _, mm = filtered(scene, 'mm', 'kalman')
    raw = np.isfinite(base.raw).all(-1).sum()
    assert mm.rejected.sum() == base.rejected.sum() < 0.15 * raw


def trajectory(frames=300, joints=5, seed=0):
    """A smooth walk in metres: stamps (T,), measurements (T, J, 3) with 10 mm noise."""
    rng = np.random.default_rng(seed)
    stamps = 1_700_000_000_000_000_000 + np.arange(frames, dtype=np.int64) * 33_333_333
    t = (stamps - stamps[0]) / 1e9
    path = np.stack([1.2 * np.sin(0.8 * t), 0.9 * np.cos(0.6 * t), 1.0 + 0.1 * t / t[-1]],
                    -1)
    offsets = rng.uniform(-0.3, 0.3, (joints, 3))
    X = path[:, None] + offsets[None] + rng.normal(scale=0.010, size=(frames, joints, 3))
    return stamps, X


@pytest.mark.parametrize('units', UNITS)
def test_live_filter_is_the_same_in_every_unit(units):
    stamps, X = trajectory()
    config = LiveFilterConfig(filter=True)
    k = per_metre(units)
    base, scaled = LiveFilter(config), LiveFilter(config, units)
    for stamp, frame in zip(stamps, X):
        a, measured_a = base.update(stamp, frame)
        b, measured_b = scaled.update(stamp, frame * k)
        np.testing.assert_allclose(b / k, a, atol=1e-9)
        np.testing.assert_array_equal(measured_a, measured_b)
    assert (scaled.gated, scaled.restarts, scaled.resets) == \
        (base.gated, base.restarts, base.resets)
    assert base.gated <= 0.01 * X.shape[0] * X.shape[1]     # 10 mm noise, 20 mm setting
