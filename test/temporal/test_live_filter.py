"""temporal.live.LiveFilter against a textbook Kalman filter, and its resets and NaN rules."""
import numpy as np
import pytest

from monet_ros.config import ConfigError
from monet_ros.temporal.live import LOST_AFTER, LiveFilter, LiveFilterConfig

T0 = 1_700_000_000_000_000_000
NO_GATE = dict(filter=True, filter_gate=1e9, filter_max_gap_s=1e3, filter_max_speed=1e9)


def textbook(config, stamps, measured):
    """A 6-state [x y z vx vy vz] constant-velocity Kalman filter per joint with full
    matrices (F, Q = q G G^T, H, R), one joint at a time; a joint starts at its first
    measurement with velocity variance 4 (m/s)^2; no gating."""
    r2 = (config.filter_noise_mm * 1e-3) ** 2
    q = config.filter_acceleration ** 2
    J = measured.shape[1]
    x, P = np.zeros((J, 6)), np.zeros((J, 6, 6))
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    live = np.zeros(J, bool)
    out, last = [], None
    for stamp, X in zip(stamps, measured):
        dt = 0.0 if last is None else (stamp - last) * 1e-9
        last = stamp
        F = np.eye(6)
        F[:3, 3:] = dt * np.eye(3)
        G = np.vstack([dt * dt / 2 * np.eye(3), dt * np.eye(3)])
        frame = np.full((J, 3), np.nan)
        for j in range(J):
            if live[j]:
                x[j] = F @ x[j]
                P[j] = F @ P[j] @ F.T + q * G @ G.T
                if np.isfinite(X[j]).all():
                    K = P[j] @ H.T @ np.linalg.inv(H @ P[j] @ H.T + r2 * np.eye(3))
                    x[j] = x[j] + K @ (X[j] - H @ x[j])
                    P[j] = (np.eye(6) - K @ H) @ P[j]
                frame[j] = x[j, :3]
            elif np.isfinite(X[j]).all():
                x[j] = np.concatenate([X[j], np.zeros(3)])
                P[j] = np.diag([r2] * 3 + [4.0] * 3)
                live[j] = True
                frame[j] = X[j]
        out.append(frame)
    return np.stack(out)


def trajectory(rng, frames=60, joints=14, noise=0.02):
    """Stamps (irregular, 25-40 ms apart), truth and noisy measurements (F, J, 3) m."""
    stamps = T0 + np.cumsum(rng.integers(25_000_000, 40_000_000, frames))
    t = (stamps - stamps[0]) * 1e-9
    phase = rng.uniform(0, 2 * np.pi, (joints, 3))
    truth = 0.3 * np.sin(2 * np.pi * 0.7 * t[:, None, None] + phase) + 1.0
    return stamps, truth, truth + rng.normal(0, noise, truth.shape)


def run(f, stamps, measured):
    outputs = [f.update(s, X) for s, X in zip(stamps, measured)]
    return np.stack([o[0] for o in outputs]), np.stack([o[1] for o in outputs])


def test_equals_the_textbook_filter_and_smooths():
    rng = np.random.default_rng(0)
    stamps, truth, measured = trajectory(rng)
    measured[10:13, 4] = np.nan                  # a short gap: predicted, as the textbook
    config = LiveFilterConfig(**NO_GATE)
    got, measured_mask = run(LiveFilter(config), stamps, measured)
    np.testing.assert_allclose(got, textbook(config, stamps, measured), atol=1e-12)
    assert not measured_mask[10:13, 4].any() and measured_mask[13:, 4].all()
    late = slice(20, None)                       # after the start-up
    raw = np.sqrt(np.mean((measured[late] - truth[late]) ** 2))
    filtered = np.sqrt(np.mean((got[late] - truth[late]) ** 2))
    assert filtered < 0.85 * raw, (filtered, raw)


@pytest.mark.parametrize('jump_ns', [-5_000_000_000, -1, 1_500_000_000])
def test_a_time_jump_resets_the_state(jump_ns):
    """A stamp going backwards (a replay loop) or jumping more than filter_reset_s: every
    joint restarts from the new measurement (the output IS the measurement), counted;
    a normal step after it filters again."""
    rng = np.random.default_rng(1)
    stamps, _, measured = trajectory(rng, frames=30)
    f = LiveFilter(LiveFilterConfig(filter=True, filter_reset_s=1.0))
    run(f, stamps[:20], measured[:20])
    far = measured[20] + 0.5                     # somewhere else entirely
    out, measured_mask = f.update(stamps[19] + jump_ns, far)
    np.testing.assert_array_equal(out, far)
    assert measured_mask.all() and f.resets == 1
    out, _ = f.update(stamps[19] + jump_ns + 33_000_000, far + 0.01)
    assert np.abs(out - (far + 0.01)).max() > 1e-4          # filtered, not a copy
    assert f.resets == 1
    # no reset for a normal step: the output is not the measurement
    g = LiveFilter(LiveFilterConfig(filter=True))
    run(g, stamps[:20], measured[:20])
    out, _ = g.update(stamps[20], measured[20])
    assert g.resets == 0 and np.abs(out - measured[20]).max() > 1e-4


def test_nan_input_does_not_poison_the_state():
    """A NaN joint is predicted (bridged up to filter_max_gap_s, then NaN and restarted
    from its next measurement); the other joints are exactly as without it; a whole NaN
    frame or inf leaves the state finite."""
    rng = np.random.default_rng(2)
    stamps, truth, measured = trajectory(rng, frames=60, joints=5)
    holey = measured.copy()
    holey[20:24, 2] = np.nan                     # ~120 ms: bridged
    holey[30:45, 3] = np.nan                     # ~500 ms: longer than filter_max_gap_s
    holey[50] = np.nan                           # a frame with nothing triangulated
    holey[51, 1] = np.inf
    config = LiveFilterConfig(filter=True, filter_max_gap_s=0.25, filter_gate=1e9)
    got, mask = run(LiveFilter(config), stamps, holey)
    alone, _ = run(LiveFilter(config), stamps, np.where(np.isnan(holey[:, [0]]), np.nan,
                                                        holey[:, [0]]))
    np.testing.assert_array_equal(got[:, 0], alone[:, 0])       # joints are independent
    assert np.isfinite(got[20:24, 2]).all() and not mask[20:24, 2].any()
    # predicted: on the straight line of constant velocity from the last estimate
    velocity = (got[20:24, 2] - got[19, 2]) / ((stamps[20:24] - stamps[19]) * 1e-9)[:, None]
    np.testing.assert_allclose(velocity, np.broadcast_to(velocity[0], velocity.shape),
                               atol=1e-9)
    gap = (stamps[30:45] - stamps[29]) * 1e-9
    np.testing.assert_array_equal(np.isnan(got[30:45, 3]).all(axis=1), gap > 0.25)
    np.testing.assert_array_equal(got[45, 3], holey[45, 3])       # restarted from it
    assert np.isfinite(got[52:]).all() and mask[52:].all()
    assert np.abs(got[55:] - truth[55:]).max() < 0.1


def test_an_outlier_is_gated_and_a_real_jump_followed():
    """One frame 0.5 m off is gated; a real jump is gated once, then followed from the
    second measurement that agrees with the first (a pair: velocity by differencing);
    outliers that disagree with each other restart the joint after LOST_AFTER."""
    rng = np.random.default_rng(3)
    stamps, truth, measured = trajectory(rng, frames=60, joints=4, noise=0.01)
    spiked = measured.copy()
    spiked[30, 1] += [0.5, 0.0, 0.0]             # one frame 0.5 m off: rejected
    spiked[40:, 2] += [0.0, 0.6, 0.0]            # the joint really moved: followed
    for k, d in enumerate(([0.6, 0, 0], [0, 0.6, 0], [0, 0, 0.6])):
        spiked[40 + k, 3] += d                   # 3 outliers far from each other
    f = LiveFilter(LiveFilterConfig(filter=True))
    got, mask = run(f, stamps, spiked)
    assert not mask[30, 1] and np.abs(got[30, 1] - truth[30, 1]).max() < 0.05
    assert not mask[40, 2] and mask[41, 2]
    np.testing.assert_array_equal(got[41, 2], spiked[41, 2])
    assert np.abs(got[42:, 2] - truth[42:, 2] - [0, 0.6, 0]).max() < 0.05
    assert not mask[40:40 + LOST_AFTER - 1, 3].any()
    np.testing.assert_array_equal(got[40 + LOST_AFTER - 1, 3], spiked[40 + LOST_AFTER - 1, 3])
    assert f.gated == 1 + 1 + LOST_AFTER + 1     # the last: the restarted joint's next one


def test_an_outlier_right_after_a_restart_is_not_followed():
    """A joint restarting (after a gap longer than filter_max_gap_s, or at the start) is
    tentative: a measurement 0.3 m off right after its first one is gated (output: the
    first measurement, not the outlier) and the velocity is not thrown off (the joint
    then tracks the truth as closely as without the outlier); a first measurement that
    was the outlier is replaced by the pair of the next two (output = the second)."""
    rng = np.random.default_rng(5)
    stamps, truth, measured = trajectory(rng, frames=60, joints=2, noise=0.01)
    holey = measured.copy()
    holey[20:35] = np.nan                        # ~500 ms gap: both joints restart at 35
    clean = holey.copy()
    holey[36, 0] += [0.3, 0.0, 0.0]              # right after joint 0's restart
    holey[35, 1] += [0.0, 0.0, -0.3]             # joint 1 restarts from an outlier
    f = LiveFilter(LiveFilterConfig(filter=True))
    got, mask = run(f, stamps, holey)
    want, _ = run(LiveFilter(LiveFilterConfig(filter=True)), stamps, clean)
    np.testing.assert_array_equal(got[35, 0], holey[35, 0])           # restarted here
    assert not mask[36, 0]
    np.testing.assert_array_equal(got[36, 0], holey[35, 0])           # held, v = 0
    assert np.abs(got[36, 0] - truth[36, 0]).max() < 0.05
    assert np.abs(got[37:, 0] - truth[37:, 0]).max() < 0.05
    assert np.abs(got[45:, 0] - want[45:, 0]).max() < 0.01           # as without it
    assert not mask[36, 1] and mask[37, 1]
    np.testing.assert_array_equal(got[37, 1], holey[37, 1])           # the pair 36, 37
    assert np.abs(got[38:, 1] - truth[38:, 1]).max() < 0.05
    # the bound: filter_max_speed x dt + gate x sqrt(2) x noise
    reach = 4.0 * (stamps[36] - stamps[35]) * 1e-9 + 4.0 * np.sqrt(2) * 0.02
    assert np.linalg.norm(holey[36, 0] - holey[35, 0]) > reach


def test_bad_settings_and_shapes_are_named():
    with pytest.raises(ConfigError, match="'filter_noise_mm'"):
        LiveFilterConfig(filter_noise_mm=0.0)
    with pytest.raises(ConfigError, match="'filter_reset_s'"):
        LiveFilterConfig(filter_reset_s=-1.0)
    with pytest.raises(ValueError, match=r'X must be \(J, 3\)'):
        LiveFilter().update(T0, np.zeros((14, 2)))


def test_an_outlier_after_a_missed_frame_cannot_throw_the_velocity_off():
    """After a missed frame the gate is wide: a 0.3 m outlier passes it (accepted with the
    speed guard off) but would make the joint faster than filter_max_speed, so it is gated
    and the joint stays on its path; the next measurements are accepted."""
    rng = np.random.default_rng(6)
    stamps = T0 + np.arange(60) * 33_333_333
    truth = np.broadcast_to([1.0, 0.5, 0.8], (60, 1, 3))               # standing still
    measured = truth + rng.normal(0, 0.005, truth.shape)
    measured[30] = np.nan                                             # a missed frame
    measured[31, 0] += [0.3, 0.0, 0.0]
    off, off_mask = run(LiveFilter(LiveFilterConfig(filter=True, filter_max_speed=1e9)),
                        stamps, measured)
    assert off_mask[31, 0] and np.abs(off[31:34, 0] - truth[31:34, 0]).max() > 0.05
    f = LiveFilter(LiveFilterConfig(filter=True))
    got, mask = run(f, stamps, measured)
    assert not mask[31, 0] and mask[32:, 0].all() and f.gated == 1
    assert np.abs(got[31:, 0] - truth[31:, 0]).max() < 0.03


# Issue 37: values inside the declared ranges whose squares or products overflow (or
# underflow to 0) are refused naming the field; every accepted one filters to finite output.
TINY, HUGE, FLOAT_MAX = 5e-324, 1e200, 1.7976931348623157e308
FLOAT_FIELDS = [name for name, value in vars(LiveFilterConfig()).items()
                if isinstance(value, float)]


def run_extreme_steps(live):
    """Frames at the shortest (1 ns) and longest (filter_reset_s) steps, with a NaN, a
    far outlier and two agreeing jumps, in the filter's unit: (J, 3) outputs of every
    frame."""
    rng = np.random.default_rng(0)
    scale = {'m': 1.0, 'cm': 100.0, 'mm': 1000.0}[live.units]
    X = rng.uniform(-1, 1, (5, 3))
    longest = int(live.config.filter_reset_s * 1e9)
    stamps = np.cumsum([T0, 1, longest, 1, max(longest, 1), 1, 33_000_000, 1])
    outs = []
    for k, stamp in enumerate(stamps):
        frame = X + 0.01 * k
        frame[0] = np.nan if k == 2 else frame[0]
        frame[1] += 50.0 if k in (3, 4) else 0.0
        outs.append(live.update(int(stamp), frame * scale)[0])
    return np.array(outs)


# The settings keep their units and are checked once converted into the rig's (LiveFilter
# units): 1e155 mm is a usable noise in a metre rig, an overflow in a millimetre one.
@pytest.mark.parametrize('units', ['m', 'cm', 'mm'])
@pytest.mark.parametrize('name', FLOAT_FIELDS)
@pytest.mark.parametrize('value', [TINY, 1e-200, 1e-160, 1e146, 1e155, HUGE, FLOAT_MAX])
def test_extreme_settings_are_refused_by_name_or_filter_finitely(units, name, value):
    try:
        config = LiveFilterConfig(filter=True, **{name: value})
    except ConfigError as error:       # outside the declared range (none here is)
        assert error.field == name
        return
    per_mm = {'m': 1e-3, 'cm': 0.1, 'mm': 1.0}[units]
    try:
        live = LiveFilter(config, units)
    except ConfigError as error:
        assert error.field == name, error
        assert repr(value) in str(error) or f'{value!r}'.replace('e+', 'e') in str(error)
        # what overflowed, computed independently in Python floats: the noise's variance in
        # the rig unit, or the covariance of a restart from two measurements 1 ns apart
        try:
            pair = 2 * (config.filter_noise_mm * per_mm) ** 2 / 1e-18
        except OverflowError:
            pair = float('inf')
        assert name != 'filter_noise_mm' or not 0 < pair < float('inf')
        return
    assert live.units == units
    assert live.r2 == pytest.approx((config.filter_noise_mm * per_mm) ** 2) and live.r2 > 0
    out = run_extreme_steps(live)
    seen = ~np.isnan(out)
    assert np.isfinite(out[seen]).all(), (name, value)
    assert seen[-1].all(), 'every joint measured in the last frame has an output'


def test_the_reported_value_is_refused_naming_it():
    with pytest.raises(ConfigError, match=r"'filter_noise_mm': 1e\+200 gives a measurement "
                       r'variance of inf m\^2'):
        LiveFilter(LiveFilterConfig(filter_noise_mm=1e200))
    with pytest.raises(ConfigError, match="'filter_acceleration': 1e\\+200"):
        LiveFilter(LiveFilterConfig(filter_acceleration=1e200))
    # in the rig unit: usable in metres, not in millimetres
    assert LiveFilter(LiveFilterConfig(filter_noise_mm=1e146)).r2 == pytest.approx(1e286)
    with pytest.raises(ConfigError, match=r"'filter_noise_mm': 1e\+146 mm gives a non-finite "
                       'restart covariance in mm'):
        LiveFilter(LiveFilterConfig(filter_noise_mm=1e146), 'mm')
    with pytest.raises(ConfigError, match=r"'filter_noise_mm': 1e\+155 gives a measurement "
                       r'variance of inf mm\^2'):
        LiveFilter(LiveFilterConfig(filter_noise_mm=1e155), 'mm')
    with pytest.raises(ConfigError, match=r"'filter_max_speed': filter_max_speed 1e\+306 m/s "
                       r'.* non-finite reach in mm'):
        LiveFilter(LiveFilterConfig(filter_max_speed=1e306), 'mm')
    LiveFilter(LiveFilterConfig(filter_max_speed=1e306), 'm')
