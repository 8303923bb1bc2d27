"""save_anipose_toml: the anipose calibration.toml writer, read back by load_rig."""
import tomllib

import numpy as np
import pytest

from monet_ros.geometry import load_rig, save_anipose_toml
from monet_ros.synth import RigConfig, make_rig


def assert_same_cameras(a, b):
    assert [c.name for c in a] == [c.name for c in b]
    for x, y in zip(a, b):
        assert (x.width, x.height) == (y.width, y.height)
        np.testing.assert_array_equal(x.K, y.K)
        np.testing.assert_array_equal(np.pad(x.dist, (0, 5))[:5], y.dist[:5])
        np.testing.assert_allclose(x.R, y.R, atol=1e-14)
        np.testing.assert_array_equal(x.t, y.t)


def test_round_trip_of_a_synthetic_rig(tmp_path):
    cameras = make_rig(RigConfig(num_cameras=5), seed=3)
    path = tmp_path / 'calibration.toml'
    save_anipose_toml(path, cameras, {'error_px': 0.25, 'board': 'charuco "8 x 11"'})
    assert_same_cameras(cameras, load_rig(path))
    data = tomllib.loads(path.read_text())
    assert data['metadata'] == {'error_px': 0.25, 'board': 'charuco "8 x 11"', 'units': 'm'}
    assert data['cam_0']['name'] == 'cam0' and data['cam_0']['size'] == [640, 480]
    assert len(data['cam_4']['distortions']) == 5


def test_round_trip_of_the_sleap_anipose_file(shared_data, tmp_path):
    original = load_rig(shared_data / 'sleap_anipose_minimal_session' / 'calibration.toml')
    path = tmp_path / 'again.toml'
    save_anipose_toml(path, original)
    assert_same_cameras(original, load_rig(path))


def test_no_camera_is_an_error(tmp_path):
    with pytest.raises(ValueError, match='at least one camera'):
        save_anipose_toml(tmp_path / 'x.toml', [])
