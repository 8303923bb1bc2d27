"""`monet eval --reference` with the rig given in m (rig YAML) and in mm (an anipose TOML
that states no unit, --rig-units mm): the same printed 3D errors, in mm both times (before,
a mm rig printed them 1000x too large)."""
import csv
import re

from helpers.recordings import noise_recording, small_checkpoint
from helpers.scenes import cv2_project
import numpy as np

from monet_ros.cli import main as monet
from monet_ros.geometry import save_anipose_toml, save_rig
from monet_ros.geometry.units import rescale
from monet_ros.labels import label_rows, write_labels
from monet_ros.skeleton import load_skeleton

FIGURES = ('mm_median', 'mm_mean', 'mm_p90', 'coverage', 'px_median')


def test_eval_reference_prints_the_same_mm_errors_for_a_rig_in_m_and_mm(tmp_path, capsys):
    rig, stamps = noise_recording(tmp_path / 'rec', cameras=3, frames=4)
    model = small_checkpoint(tmp_path / 'm.pt', seed=0)
    keypoints = load_skeleton('human14').keypoints
    rng = np.random.default_rng(3)
    X = np.array([0.0, 0.0, 1.0]) + rng.uniform(-0.3, 0.3, (2, 14, 3))   # metres
    uv = np.stack([[cv2_project(c, X[t]) for c in rig] for t in range(2)])
    write_labels(tmp_path / 'labels.csv', label_rows([stamps[0], stamps[2]],
                                                      [c.name for c in rig], keypoints, uv))
    save_rig(tmp_path / 'rig_m.yaml', rig)
    toml = tmp_path / 'rig_mm.toml'
    save_anipose_toml(toml, rescale(rig, 'mm'))
    toml.write_text(re.sub(r'(?m)^units = .*\n', '', toml.read_text()))
    rows, printed = {}, {}
    for units, options in (('m', ['--rig', tmp_path / 'rig_m.yaml']),
                           ('mm', ['--rig', toml, '--rig-units', 'mm'])):
        out_dir = tmp_path / f'report_{units}'
        code = monet(['eval', str(model), '--data', str(tmp_path / 'rec'), '--reference',
                      str(tmp_path / 'labels.csv'), '--out', str(out_dir),
                      *map(str, options)])
        out = capsys.readouterr().out
        assert code == 0
        assert f'3D errors in mm (the rig and the 3D in {units}, converted)' in out
        printed[units] = out.splitlines()[-1]           # the checkpoint's table row
        with open(out_dir / 'reference.csv') as f:
            rows[units] = next(csv.DictReader(f))
    assert printed['m'] == printed['mm']
    # equal up to float32 rounding: the tracked crops follow keypoints3d kept at float32
    # (crop_rule.TrackedCrops), whose rounding in m and in mm differs in the last bits
    for key in FIGURES:
        assert np.isclose(float(rows['m'][key]), float(rows['mm'][key]), rtol=1e-4,
                          equal_nan=True), key
    assert int(rows['m']['joints_3d']) == int(rows['mm']['joints_3d']) == 2 * 14
