"""`monet synth` options for scenes where bootstrapping is not free: non-coplanar rings,
occluding pillars, left/right limbs that differ in appearance."""
import numpy as np
import pytest

from monet_ros.synth.recording import SynthConfig, SynthError, plan
from monet_ros.synth.render import part_colors
from monet_ros.synth.rig import make_rig

BASE = dict(cameras=5, frames=40, width=160, height=120, seed=3)


def test_height_spread_makes_the_ring_non_coplanar_and_zero_changes_nothing():
    flat = make_rig(SynthConfig(**BASE).rig, seed=3)
    same = make_rig(SynthConfig(**BASE, height_spread=0.0).rig, seed=3)
    for a, b in zip(flat, same):
        np.testing.assert_array_equal(a.R, b.R)
        np.testing.assert_array_equal(a.t, b.t)
    tall = make_rig(SynthConfig(**BASE, height_spread=0.8).rig, seed=3)
    z_flat = np.array([c.center[2] for c in flat])
    z = np.array([c.center[2] for c in tall])
    assert np.ptp(z_flat) < 0.25 and np.ptp(z) > 0.8
    # alternately above and below, by 0.4..0.8 m
    offset = z - z_flat
    assert (np.sign(offset) == (-1.0) ** np.arange(5)).all()
    assert (np.abs(offset) >= 0.4 - 1e-9).all() and (np.abs(offset) <= 0.8 + 1e-9).all()


def test_occluders_hide_keypoints_behind_pillars_only():
    without = plan(SynthConfig(**BASE))
    with_pillars = plan(SynthConfig(**BASE, occluders=2))
    body = without['A'].shape[1]
    assert with_pillars['A'].shape[1] == body + 2
    assert with_pillars['parts'][-2:] == ('occluder', 'occluder')
    extra = with_pillars['occluded'] & ~without['occluded']
    assert extra.any()
    # brute force: every newly hidden keypoint has a pillar within its radius on the
    # segment camera centre -> keypoint
    cams = with_pillars['cameras']
    X = with_pillars['keypoints3d']
    radius = with_pillars['radii'][-1]
    s = np.linspace(0.0, 1.0, 2001)[:, None]
    for t, v, c in np.argwhere(extra):
        ray = cams[v].center + s * (X[t, c] - cams[v].center)             # (S, 3)
        hit = False
        for a, b in zip(with_pillars['A'][t, body:], with_pillars['B'][t, body:]):
            u = np.clip((ray - a) @ (b - a) / np.dot(b - a, b - a), 0.0, 1.0)
            dist = np.linalg.norm(ray - (a + u[:, None] * (b - a)), axis=1)
            hit |= bool(dist.min() < radius + 1e-3)
        assert hit, (t, v, c)
    with pytest.raises(SynthError, match='occluders'):
        SynthConfig(**BASE, occluders=9)


def test_distinct_sides_colour_left_arm_and_leg_differently():
    same = plan(SynthConfig(**BASE))['parts']
    assert not any(p.startswith('left_') for p in same)
    parts = plan(SynthConfig(**BASE, distinct_sides=True))['parts']
    assert parts.count('left_arm') == 2 and parts.count('left_leg') == 2
    colours = part_colors(parts, np.random.default_rng(0))
    assert np.abs(colours['left_arm'] - colours['arm']).max() > 30
    assert np.abs(colours['left_leg'] - colours['leg']).max() > 30


def test_motion_seed_changes_the_motion_only_and_defaults_to_the_seed():
    base = plan(SynthConfig(**BASE, subjects=2))
    same = plan(SynthConfig(**BASE, subjects=2, motion_seed=BASE['seed']))
    for key, value in base.items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(same[key], value, err_msg=key)
    other = plan(SynthConfig(**BASE, subjects=2, motion_seed=4))
    for a, b in zip(base['cameras'], other['cameras']):          # the rig: the seed's
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_array_equal(a.R, b.R)
        np.testing.assert_array_equal(a.t, b.t)
    assert other['parts'] == base['parts']                       # the look's materials
    np.testing.assert_array_equal(other['labelled'], base['labelled'])
    np.testing.assert_array_equal(other['stamps'], base['stamps'])
    moved = np.linalg.norm(other['subjects_keypoints3d'] - base['subjects_keypoints3d'], axis=-1)
    assert np.median(moved) > 0.1                                # metres: another motion
    assert SynthConfig(**BASE).to_dict() == {
        k: v for k, v in SynthConfig(**BASE, motion_seed=9).to_dict().items()
        if k != 'motion_seed'}
    with pytest.raises(SynthError, match='motion_seed'):
        SynthConfig(**BASE, motion_seed=-1)
