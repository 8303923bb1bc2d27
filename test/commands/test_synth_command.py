"""`monet synth` as a subprocess: writes a recording, refuses bad options and existing
output with a clear message and exit code 2."""
import os
from pathlib import Path
import subprocess
import sys

import numpy as np

from monet_ros.labels import read_labels

REPO = Path(__file__).resolve().parents[2]


def monet(*args):
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(REPO), env.get('PYTHONPATH')]))
    return subprocess.run([sys.executable, '-m', 'monet_ros.cli', 'synth', *args],
                          capture_output=True, text=True, timeout=120, env=env, cwd=REPO)


def test_cli_writes_a_recording(tmp_path):
    out = tmp_path / 'rec'
    proc = monet('--out', str(out), '--cameras', '3', '--frames', '4', '--width', '64',
                 '--height', '48', '--label-fraction', '0.5', '--seed', '9', '--layout', 'dome',
                 '--distortion=-0.05,0.01', '--fps', '10')
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith('monet synth: wrote 4 instants x 3 cameras')
    assert '4/4' in proc.stderr                       # the tqdm progress bar
    assert sorted(p.name for p in out.iterdir()) == ['README.md', 'ground_truth.npz',
                                                     'labels.csv', 'recording', 'rig.yaml']
    gt = np.load(out / 'ground_truth.npz')
    assert gt['keypoints2d'].shape == (4, 3, 14, 2)
    np.testing.assert_array_equal(np.diff(gt['stamps']), [100_000_000] * 3)
    assert len(read_labels(out / 'labels.csv')) == 2
    assert 'Seed 9' in (out / 'README.md').read_text()


def test_cli_errors(tmp_path):
    proc = monet('--out', str(tmp_path / 'a'), '--cameras', '1')
    assert proc.returncode == 2 and "field 'cameras'" in proc.stderr
    proc = monet('--out', str(tmp_path / 'a'), '--distortion', 'x,1')
    assert proc.returncode == 2 and '--distortion' in proc.stderr
    (tmp_path / 'full').mkdir()
    (tmp_path / 'full' / 'x').write_text('keep')
    proc = monet('--out', str(tmp_path / 'full'), '--frames', '1')
    assert proc.returncode == 2 and 'not overwriting' in proc.stderr
    assert (tmp_path / 'full' / 'x').read_text() == 'keep'


def test_cli_motion_seed_keeps_the_rig_and_the_room(tmp_path):
    a, b = tmp_path / 'a', tmp_path / 'b'
    common = ('--cameras', '2', '--frames', '1', '--width', '64', '--height', '48', '--seed',
              '5', '--quiet')
    assert monet('--out', str(a), *common).returncode == 0
    proc = monet('--out', str(b), *common, '--motion-seed', '6')
    assert proc.returncode == 0, proc.stderr
    assert (a / 'rig.yaml').read_text() == (b / 'rig.yaml').read_text()
    ga, gb = np.load(a / 'ground_truth.npz'), np.load(b / 'ground_truth.npz')
    assert np.abs(ga['keypoints3d'] - gb['keypoints3d']).max() > 0.1
    assert 'Seed 5 (motion seed 6)' in (b / 'README.md').read_text()
    proc = monet('--out', str(tmp_path / 'c'), '--motion-seed', '-2')
    assert proc.returncode == 2 and "field 'motion_seed'" in proc.stderr
