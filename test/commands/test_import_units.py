"""`monet import videos` with a calibration in mm (an anipose TOML that states no unit):
the recording's /tf_static is in metres, as ROS has it, with a note; the recording then
reads as a metre rig with the same geometry."""
import re

import cv2
from helpers.ring import ring_rig
import numpy as np

from monet_ros.cli import main
from monet_ros.geometry import save_anipose_toml
from monet_ros.geometry.units import rescale
from monet_ros.io import rig_from_bag


def test_a_mm_calibration_is_written_in_metres(tmp_path, capsys):
    cams = ring_rig(2, width=64, height=48, focal=60.0)          # metres, 8 m across
    toml = tmp_path / 'calibration.toml'
    save_anipose_toml(toml, rescale(cams, 'mm'))
    toml.write_text(re.sub(r'(?m)^units = .*\n', '', toml.read_text()))
    videos = tmp_path / 'videos'
    videos.mkdir()
    rng = np.random.default_rng(0)
    for cam in cams:
        writer = cv2.VideoWriter(str(videos / f'{cam.name}.avi'),
                                 cv2.VideoWriter_fourcc(*'FFV1'), 30.0, (64, 48))
        for _ in range(3):
            writer.write(rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
        writer.release()
    out = tmp_path / 'rec'
    assert main(['import', 'videos', str(videos), '--calibration', str(toml), '--out',
                 str(out), '--quiet']) == 0
    err = capsys.readouterr().err
    assert 'taken as mm' in err                                  # the rule, noted
    assert f'{toml} is in mm: /tf_static written in metres (ROS REP 103)' in err
    back = {c.name: c for c in rig_from_bag(out)}
    for cam in cams:
        assert back[cam.name].units == 'm'
        np.testing.assert_allclose(back[cam.name].t, cam.t, atol=1e-9)
        np.testing.assert_allclose(back[cam.name].R, cam.R, atol=1e-9)
