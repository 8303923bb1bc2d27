"""Synthetic rig: poses aim at the target, layouts, seeded jitter, distortion validation
(checked against cv2.projectPoints)."""
import cv2
import numpy as np
import pytest

from monet_ros.synth.rig import RigConfig, RigConfigError, look_at, make_rig


def test_ring_without_jitter_is_exact():
    config = RigConfig(num_cameras=6, radius=3.0, camera_height=1.5, jitter=0.0,
                       image_width=320, image_height=240, hfov_deg=70.0)
    cams = make_rig(config, seed=3)
    assert [c.name for c in cams] == [f'cam{i}' for i in range(6)]
    assert [c.topic for c in cams] == [f'/cam{i}/image_raw' for i in range(6)]
    centers = np.array([c.center for c in cams])
    np.testing.assert_allclose(np.hypot(centers[:, 0], centers[:, 1]), 3.0, atol=1e-12)
    np.testing.assert_allclose(centers[:, 2], 1.5, atol=1e-12)
    azimuth = np.unwrap(np.arctan2(centers[:, 1], centers[:, 0]))
    np.testing.assert_allclose(np.diff(azimuth), 2 * np.pi / 6, atol=1e-12)
    fx = 160 / np.tan(np.radians(35.0))
    for cam in cams:
        np.testing.assert_allclose(cam.K, [[fx, 0, 159.5], [0, fx, 119.5], [0, 0, 1]])
        # the target projects (undistorted: it lies on the axis) onto the principal point
        np.testing.assert_allclose(cam.project(np.array([config.target]))[0], [159.5, 119.5],
                                   atol=1e-9)
        # image rows point down the world z axis: a point above the target is higher up
        above = cam.project(np.array([config.target]) + [0, 0, 0.5])[0]
        assert above[1] < 119.5 and abs(above[0] - 159.5) < 1e-6


def test_jittered_rig_is_seeded_and_aims_near_the_target():
    config = RigConfig(num_cameras=8)
    a, b, c = make_rig(config, seed=1), make_rig(config, seed=1), make_rig(config, seed=2)
    assert all(x == y for x, y in zip(a, b))
    assert not any(x == y for x, y in zip(a, c))
    for cam in a:
        to_target = np.asarray(config.target) - cam.center
        cos = cam.R[2] @ to_target / np.linalg.norm(to_target)
        assert cos > np.cos(np.radians(3.0))
        uv = cam.project(np.array([config.target]))[0]
        assert np.all(np.abs(uv - [320, 240]) < 40)
        assert cam.has_distortion


def test_dome_layout_spreads_elevations():
    config = RigConfig(num_cameras=10, layout='dome', radius=5.0, jitter=0.0,
                       dome_elevation_deg=(10.0, 60.0))
    cams = make_rig(config)
    centers = np.array([c.center for c in cams])
    np.testing.assert_allclose(np.linalg.norm(centers, axis=1), 5.0, atol=1e-12)
    elevation = np.degrees(np.arcsin(centers[:, 2] / 5.0))
    assert np.all((elevation > 10) & (elevation < 60))
    assert elevation.max() - elevation.min() > 40
    azimuth = np.degrees(np.arctan2(centers[:, 1], centers[:, 0])) % 360
    assert np.histogram(azimuth, bins=4, range=(0, 360))[0].min() >= 1


def test_look_at_matches_cv2_rodrigues_roll():
    R0 = look_at([3.0, 1.0, 2.0], [0.0, 0.0, 1.0])
    R1 = look_at([3.0, 1.0, 2.0], [0.0, 0.0, 1.0], roll=0.3)
    np.testing.assert_allclose(R0 @ R0.T, np.eye(3), atol=1e-12)
    roll, _ = cv2.Rodrigues(np.array([0.0, 0.0, 0.3]))
    np.testing.assert_allclose(R1, roll @ R0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R1), 1.0)


def _radii_cv2(dist, r_max):
    """Distorted radius of ideal normalised radii 0..r_max along x, by cv2.projectPoints."""
    r = np.linspace(0, r_max, 400)
    pts = np.stack([r, np.zeros_like(r), np.ones_like(r)], 1)
    uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), np.eye(3), np.asarray(dist))
    return uv[:, 0, 0]


def test_distortion_fold_over_is_rejected():
    ok = RigConfig(distortion=(-0.08, 0.02))
    assert np.all(np.diff(_radii_cv2(ok.distortion5, ok.max_normalized_radius * 1.25)) > 0)
    bad = (-0.6,)
    r_max = RigConfig().max_normalized_radius * 1.25
    assert np.any(np.diff(_radii_cv2([-0.6, 0, 0, 0, 0], r_max)) <= 0)
    with pytest.raises(RigConfigError, match="'distortion'"):
        RigConfig(distortion=bad)


@pytest.mark.parametrize('field, value', [
    ('num_cameras', 1), ('num_cameras', 2.5), ('layout', 'cube'), ('radius', -1.0),
    ('image_width', 8), ('hfov_deg', 170.0), ('distortion', ()), ('target', (0, 0)),
    ('jitter', -1.0), ('dome_elevation_deg', (50.0, 10.0)),
])
def test_bad_config_names_the_field(field, value):
    with pytest.raises(RigConfigError, match=f"'{field}'"):
        RigConfig(**{field: value})
