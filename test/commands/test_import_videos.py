"""`monet import videos`: a generated 3-camera session (FFV1 .mkv, FFV1 .avi, a PNG folder)
+ calibration -> rosbag2 MCAP whose decoded frames are the source frames exactly, stamps
exactly start + round(i * 1e9 / fps), per-camera offsets, the calibration in camera_info +
/tf_static, resize with the calibration scaled; clear one-line errors; the real Pose2Sim
videos + calibration as a small check."""
import cv2
from helpers.ring import ring_rig
import numpy as np
import pytest

from monet_ros.cli import main
from monet_ros.geometry import save_rig
from monet_ros.io import open_bag, rig_from_bag
from monet_ros.learning.recording import load_recording

FPS = 30.0
START = 1_800_000_000_000_000_000


@pytest.fixture(scope='module')
def session(tmp_path_factory):
    root = tmp_path_factory.mktemp('session')
    cams = ring_rig(3, width=64, height=48, focal=60.0, dist=(-0.05, 0.01, 0.0, 0.0, 0.0))
    save_rig(root / 'calibration.yaml', cams)
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (3, 8, 48, 64, 3), dtype=np.uint8)      # rgb
    videos = root / 'videos'
    videos.mkdir()
    for v, (name, fourcc) in enumerate((('trial_cam0.mkv', 'FFV1'),
                                        ('trial_cam1.avi', 'FFV1'))):
        writer = cv2.VideoWriter(str(videos / name), cv2.VideoWriter_fourcc(*fourcc), FPS,
                                 (64, 48))
        for f in frames[v]:
            writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
        writer.release()
    folder = videos / 'trial_cam2'
    folder.mkdir()
    for i, f in enumerate(frames[2]):
        cv2.imwrite(str(folder / f'{i:04d}.png'), cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    (videos / 'notes.txt').write_text('not a video')
    return root, cams, frames


def test_lossless_import_is_exact_with_offsets(session, tmp_path, capsys):
    root, cams, frames = session
    out = tmp_path / 'rec'
    assert main(['import', 'videos', str(root / 'videos'), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(out), '--fps', '30', '--raw',
                 '--offsets', 'cam1=2', '--start-ns', str(START), '--quiet']) == 0
    text = capsys.readouterr().out
    assert '3 cameras x 8 instants at 30 fps' in text and "{'cam1': 2}" in text
    bag = open_bag(out)
    assert bag.topics['/cam0/image_raw'].count == 8 and bag.topics['/cam1/image_raw'].count == 6
    assert bag.topics['/tf_static'].count == 1
    # the calibration comes back from camera_info + /tf_static
    back = {c.name: c for c in rig_from_bag(out)}
    for cam in cams:
        got = back[cam.name]
        assert (got.width, got.height) == (cam.width, cam.height)
        np.testing.assert_allclose(got.K, cam.K, atol=1e-12)
        np.testing.assert_allclose(got.dist[:5], cam.dist[:5], atol=1e-15)
        np.testing.assert_allclose(got.R, cam.R, atol=1e-9)
        np.testing.assert_allclose(got.t, cam.t, atol=1e-9)
    rec = load_recording(out, skeleton=('a',))
    # cam1's first 2 frames were dropped: 6 complete instants, stamps exact
    assert rec.skipped == 2
    np.testing.assert_array_equal(rec.stamps, [START + round(i * 1e9 / FPS) for i in range(6)])
    names = [c.name for c in rec.cameras]
    np.testing.assert_array_equal(rec.frames[names.index('cam0')], frames[0, :6])
    np.testing.assert_array_equal(rec.frames[names.index('cam1')], frames[1, 2:8])
    np.testing.assert_array_equal(rec.frames[names.index('cam2')], frames[2, :6])


def test_png_compressed_and_resized(session, tmp_path, capsys):
    root, cams, frames = session
    out = tmp_path / 'half'
    assert main(['import', 'videos', str(root / 'videos'), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(out), '--fps', '30',
                 '--format', 'png', '--resize', '0.5', '--max-frames', '3', '--quiet']) == 0
    rec = load_recording(out, skeleton=('a',))
    assert rec.num_instants == 3
    for v, cam in enumerate(cams):
        got = rec.cameras[[c.name for c in rec.cameras].index(cam.name)]
        expected = cam.crop((0, 0, 64, 48), (32, 24))             # K' = S K
        np.testing.assert_allclose(got.K, expected.K, atol=1e-12)
        assert (got.width, got.height) == (32, 24)
        np.testing.assert_allclose(got.K[:2, 2], (cam.K[:2, 2] + 0.5) * 0.5 - 0.5)
        small = np.stack([cv2.resize(f, (32, 24), interpolation=cv2.INTER_AREA)
                          for f in frames[v, :3]])
        np.testing.assert_array_equal(rec.frames[[c.name for c in rec.cameras].index(
            cam.name)], small)
    # a point projects to the same place in the resized image (pixel-centre convention)
    X = np.array([[0.05, -0.02, 0.1]])
    np.testing.assert_allclose(got.project(X), (cams[2].project(X) + 0.5) * 0.5 - 0.5,
                               atol=1e-9)


def test_unmatched_cameras_and_bad_options_are_one_line(session, tmp_path, capsys):
    root, cams, _ = session
    renamed = [c.replace(name=f'cam_0{i}') for i, c in enumerate(cams)]
    save_rig(tmp_path / 'named.yaml', renamed)
    args = ['import', 'videos', str(root / 'videos'), '--calibration',
            str(tmp_path / 'named.yaml'), '--out', str(tmp_path / 'x'), '--fps', '30']
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0
    assert "camera 'cam_00' matches no file (looks like 'trial_cam0.mkv'" in err
    assert main(args + ['--camera-map', 'cam_00=cam0,cam_01=cam1,cam_02=cam2', '--raw',
                        '--quiet']) == 0
    capsys.readouterr()
    assert main(['import', 'videos', str(root / 'videos'), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(tmp_path / 'y')]) == 2
    assert 'trial_cam2 has no frame rate' in capsys.readouterr().err
    assert main(['import', 'videos', str(root / 'videos'), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(tmp_path / 'z'), '--fps', '30',
                 '--offsets', 'cam9=1']) == 2
    assert "--offsets: 'cam9=1': camera 'cam9' is not one of cam0, cam1, cam2" in \
        capsys.readouterr().err


def test_real_pose2sim_videos_and_calibration(shared_data, tmp_path, capsys):
    demo = shared_data / 'pose2sim_demo_balancing'
    videos = demo / 'S00_P00_SingleParticipant' / 'S00_P00_T01_BalancingTrial' / 'videos'
    out = tmp_path / 'p2s'
    assert main(['import', 'videos', str(videos), '--calibration',
                 str(demo / 'S00_Calibration' / 'Calib_qualisys.toml'), '--out', str(out),
                 '--camera-map', 'cam_01=cam01,cam_02=cam02,cam_03=cam03,cam_04=cam04',
                 '--resize', '0.5', '--max-frames', '3', '--quiet']) == 0
    captured = capsys.readouterr()
    # cam01/cam02 videos are 1080 wide, the calibration says 1088: named, K kept
    assert 'cam01: calibration 1088x1920, ' in captured.err
    assert ('cam01.mp4 is 1080x1920: K kept as calibrated (the size differs by a few pixels: '
            'codec padding?)') in captured.err
    assert '4 cameras x 3 instants at 60 fps' in captured.out
    ours = {c.name: c for c in rig_from_bag(out)}
    # the derived bag in shared data was made from the same inputs with the same K scaling
    derived = {c.name: c for c in rig_from_bag(
        shared_data / 'derived_pose2sim_4cam_mcap' / 'pose2sim_balancing_4cam')}
    for name, cam in derived.items():
        assert (ours[name].width, ours[name].height) == (cam.width, cam.height)
        np.testing.assert_allclose(ours[name].K, cam.K, atol=1e-9)
        np.testing.assert_allclose(ours[name].R, cam.R, atol=1e-9)
        np.testing.assert_allclose(ours[name].t, cam.t, atol=1e-9)
    rec = load_recording(out, skeleton=('a',))
    np.testing.assert_array_equal(np.diff(rec.stamps), [16_666_667, 16_666_666])


def test_negative_offset_delays_a_camera_and_a_failed_import_leaves_nothing(session,
                                                                            tmp_path, capsys):
    root, cams, frames = session
    out = tmp_path / 'late'
    assert main(['import', 'videos', str(root / 'videos'), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(out), '--fps', '30', '--raw',
                 '--offsets', 'cam2=-1', '--quiet']) == 0
    capsys.readouterr()
    bag = open_bag(out)
    stamps = {t: [m.stamp_ns for m in bag.messages([f'/{t}/image_raw'])] for t in
              ('cam0', 'cam2')}
    start = 1_767_225_600_000_000_000                 # the default --start-ns
    assert stamps['cam0'] == [start + round(i * 1e9 / FPS) for i in range(8)]
    assert stamps['cam2'] == [start + round(i * 1e9 / FPS) for i in range(1, 9)]
    rec = load_recording(out, skeleton=('a',))
    assert rec.skipped == 2                       # instant 0 lacks cam2, instant 8 the others
    names = [c.name for c in rec.cameras]
    np.testing.assert_array_equal(rec.frames[names.index('cam2')], frames[2, :7])
    np.testing.assert_array_equal(rec.frames[names.index('cam0')], frames[0, 1:8])
    # one image of another size half way: exit 2 naming it, and no output folder left
    import shutil
    broken = tmp_path / 'broken'
    shutil.copytree(root / 'videos', broken)
    cv2.imwrite(str(broken / 'trial_cam2' / '0004.png'), np.zeros((10, 10, 3), np.uint8))
    args = ['import', 'videos', str(broken), '--calibration', str(root / 'calibration.yaml'),
            '--out', str(tmp_path / 'b'), '--fps', '30', '--quiet']
    assert main(args) == 2
    assert 'trial_cam2: frame 4 is 10x10, the first was 64x48' in capsys.readouterr().err
    assert not (tmp_path / 'b').exists()
