"""`monet triangulate` of OpenPose / Pose2Sim JSON folders: the real Pose2Sim demo's
pose-associated folders give Pose2Sim's own .trc markers (by name, in its frames), a copy
of them renamed OpenPose's way that starts at frame 10 keeps frame 10, and input it cannot
read is one line naming the formats it reads."""
import shutil

import numpy as np

from monet_ros.cli import main as monet
from monet_ros.io.export_tables import read_anipose_csv, read_trc

DEMO = 'pose2sim_demo_balancing'
TRIAL = f'{DEMO}/S00_P00_SingleParticipant/S00_P00_T01_BalancingTrial'
CALIB = f'{DEMO}/S00_Calibration/Calib_qualisys.toml'
MAP = ['--camera-map', 'cam01=cam_01,cam02=cam_02,cam03=cam_03,cam04=cam_04']
# Pose2Sim's triangulation parameters of the demo (its Config.toml, see the MANIFEST)
PARAMS = ['--confidence-threshold', '0.3', '--threshold-px', '15', '--fps', '60',
          '--pose-model', 'BODY_25B', '--quiet']


def run(args, capsys):
    code = monet(['triangulate', *map(str, args)])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_pose2sim_json_folders_give_pose2sims_markers_and_keep_late_frames(
        shared_data, tmp_path, capsys):
    assoc = shared_data / TRIAL / 'pose-associated'
    rig = shared_data / CALIB
    code, text, err = run([assoc, '--rig', rig, *MAP, *PARAMS, '--out', tmp_path / 'all'],
                          capsys)
    assert code == 0, err
    assert '100 frames (from frame 0) x 4 cameras' in text
    assert 'rows of the openpose format' in text
    assert 'keypoint names of BODY_25B' in err
    ours = read_anipose_csv(tmp_path / 'all' / 'keypoints3d.csv')
    trc_path = next((shared_data / TRIAL / 'pose-3d').glob('*.trc'))
    theirs = read_trc(trc_path, axes='yzx')                  # Pose2Sim's file is Y-up
    index = [ours['keypoints'].index(k) for k in theirs['keypoints']]
    # Pose2Sim's Frame# 1 is its frame 0: the same frames, the same markers by name
    np.testing.assert_array_equal(theirs['frames'] - 1, ours['fnum'])
    d = np.linalg.norm(ours['X'][:, index] - theirs['X'], axis=-1)
    assert np.nanmedian(d) < 1e-4                            # metres: 0.1 mm
    assert np.mean(d < 5e-4) > 0.98                          # a few frames Pose2Sim filled
    # the same folders renamed OpenPose's way, from video frame 10 on
    late = tmp_path / 'late'
    for cam in ('cam01', 'cam02', 'cam03', 'cam04'):
        (late / f'{cam}_json').mkdir(parents=True)
        for f in sorted((assoc / f'{cam}_json').glob('*.json'))[10:]:
            frame = int(f.stem.split('.')[-1])
            shutil.copy(f, late / f'{cam}_json' / f'{cam}_{frame:012d}_keypoints.json')
    code, text, err = run([*sorted(late.iterdir()), '--rig', rig, *MAP, *PARAMS,
                           '--out', tmp_path / 'late_out'], capsys)
    assert code == 0, err
    assert '90 frames (from frame 10)' in text
    part = read_anipose_csv(tmp_path / 'late_out' / 'keypoints3d.csv')
    np.testing.assert_array_equal(part['fnum'], np.arange(10, 100))
    np.testing.assert_array_equal(part['X'], ours['X'][10:])
    trc = read_trc(tmp_path / 'late_out' / 'keypoints3d.trc')
    np.testing.assert_array_equal(trc['frames'], np.arange(11, 101))
    np.testing.assert_allclose(trc['times'], np.arange(10, 100) / 60, rtol=0, atol=1e-9)


def test_unreadable_input_says_which_formats_are_read(shared_data, tmp_path, capsys):
    rig = shared_data / CALIB
    (tmp_path / 'videos').mkdir()
    (tmp_path / 'videos' / 'notes.txt').write_text('no tables here\n')
    code, _, err = run([tmp_path / 'videos', '--rig', rig, '--out', tmp_path / 'o'], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and 'Traceback' not in err, err
    assert 'no 2D tables found in the folder; read: ' in err
    for name in ('DeepLabCut', 'SLEAP', 'anipose', 'OpenPose / Pose2Sim JSON', 'frame,camera'):
        assert name in err
    # 25 keypoints per person without a stated model: one line naming --pose-model
    assoc = shared_data / TRIAL / 'pose-associated'
    code, _, err = run([assoc, '--rig', rig, *MAP, '--out', tmp_path / 'o2'], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert 'state the model with --pose-model' in err
    assert not (tmp_path / 'o').exists() and not (tmp_path / 'o2').exists()
