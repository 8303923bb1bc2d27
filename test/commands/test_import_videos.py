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


def _save_folder(folder, frames, numbers, pattern='frame_{:04d}.png'):
    folder.mkdir(parents=True)
    for f, n in zip(frames, numbers):
        cv2.imwrite(str(folder / pattern.format(n)), cv2.cvtColor(f, cv2.COLOR_RGB2BGR))


def _decoded(bag, topic):
    """{stamp: rgb image} of an image topic (CompressedImage or Image)."""
    from monet_ros.io.images import any_image_to_numpy
    return {m.stamp_ns: np.asarray(any_image_to_numpy(m.msg)) for m in bag.messages([topic])}


def test_image_folders_with_gaps_are_matched_by_file_number(session, tmp_path, capsys):
    """cam1 lacks frame_0004/0005: its views of instants 4 and 5 are missing (counted and
    printed), every other view is the file of its own number; numbering from 1 works and
    names without numbers fall back to name order with a note."""
    root, cams, _ = session
    frames = np.random.default_rng(5).integers(0, 256, (3, 10, 48, 64, 3), dtype=np.uint8)
    videos = tmp_path / 'gaps'
    numbers = {0: range(1, 11), 1: [n for n in range(1, 11) if n not in (5, 6)],
               2: range(2, 11)}                      # cam2 lacks its first file too
    for v, numbers_v in numbers.items():
        _save_folder(videos / f'cam{v}', frames[v, [n - 1 for n in numbers_v]], numbers_v)
    out = tmp_path / 'rec'
    assert main(['import', 'videos', str(videos), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(out), '--fps', '30',
                 '--format', 'png', '--start-ns', str(START), '--quiet']) == 0
    text = capsys.readouterr().out
    assert "instants without a view (missing frames): {'cam1': 2, 'cam2': 1}" in text
    bag = open_bag(out)
    for v, numbers_v in numbers.items():
        got = _decoded(bag, f'/cam{v}/image_raw/compressed')
        # file N is instant N - 1 (the session's smallest number is 1): stamp and pixels
        assert sorted(got) == [START + round((n - 1) * 1e9 / FPS) for n in numbers_v]
        for n in numbers_v:
            np.testing.assert_array_equal(got[START + round((n - 1) * 1e9 / FPS)],
                                          frames[v, n - 1])
    rec = load_recording(out, skeleton=('a',))
    assert rec.num_instants == 7 and rec.skipped == 3          # instants 0, 4, 5 incomplete
    # names without numbers: name order, said so
    plain = tmp_path / 'plain'
    for v in range(3):
        _save_folder(plain / f'cam{v}', frames[v, :3], 'abc', pattern='{}.png')
    assert main(['import', 'videos', str(plain), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(tmp_path / 'p'), '--fps', '30',
                 '--quiet']) == 0
    err = capsys.readouterr().err
    assert 'cam0: file names carry no frame number: frames taken in name order' in err
    # two files of one number: named
    _save_folder(tmp_path / 'dup' / 'cam0', frames[0, :2], (3, 3), pattern='{}_x.png')
    cv2.imwrite(str(tmp_path / 'dup' / 'cam0' / 'img03.png'), frames[0, 0])
    for v in (1, 2):
        _save_folder(tmp_path / 'dup' / f'cam{v}', frames[v, :1], (3,))
    assert main(['import', 'videos', str(tmp_path / 'dup'), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(tmp_path / 'd'), '--fps', '30',
                 '--quiet']) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and 'frame number 3 is also' in err


VFR_TIMES = np.array([0, 20, 40, 60, 80, 100, 133, 200, 266, 333, 433, 533]) / 1000.0


def _vfr_session(tmp_path, session):
    """cam0, cam1: constant 30 fps FFV1 .mkv; cam2: an MP4 whose frames have the container
    times VFR_TIMES (frame j is flat grey 20 j, so it is known after lossy coding)."""
    from helpers.videos import write_vfr_mp4

    root, cams, _ = session
    frames = np.random.default_rng(9).integers(0, 256, (2, 17, 48, 64, 3), dtype=np.uint8)
    videos = tmp_path / 'vfr'
    videos.mkdir()
    for v in range(2):
        writer = cv2.VideoWriter(str(videos / f'cam{v}.mkv'), cv2.VideoWriter_fourcc(*'FFV1'),
                                 FPS, (64, 48))
        for f in frames[v]:
            writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
        writer.release()
    grey = np.stack([np.full((48, 64, 3), 20 * j, np.uint8) for j in range(len(VFR_TIMES))])
    write_vfr_mp4(videos / 'cam2.mp4', grey, VFR_TIMES)
    # the container really holds these times (OpenCV's own reading)
    cap = cv2.VideoCapture(str(videos / 'cam2.mp4'))
    times = []
    while cap.read()[0]:
        times.append(cap.get(cv2.CAP_PROP_POS_MSEC))
    np.testing.assert_allclose(times, VFR_TIMES * 1000, atol=0.5)
    return root, videos, frames


def test_variable_frame_rate_video_is_stamped_by_container_time(session, tmp_path, capsys):
    """A VFR camera beside two 30 fps ones: without --fps the rates disagree (exit 2,
    advising --fps); with --fps 30 each of its frames is at the instant nearest its
    container time (frame 11 at 533 ms -> instant 16, not 11), the nearer of two frames
    of one instant is kept, and the note names the VFR video and what --fps did."""
    root, videos, frames = _vfr_session(tmp_path, session)
    args = ['import', 'videos', str(videos), '--calibration', str(root / 'calibration.yaml'),
            '--start-ns', str(START), '--raw', '--quiet']
    assert main(args + ['--out', str(tmp_path / 'x')]) == 2
    assert 'disagree on the frame rate' in capsys.readouterr().err
    out = tmp_path / 'rec'
    assert main(args + ['--out', str(out), '--fps', '30']) == 0
    captured = capsys.readouterr()
    assert 'cam2.mp4 has a variable frame rate (frame intervals 20.0..100.0 ms)' in \
        captured.err
    assert '--fps 30 is the instant grid' in captured.err and 'not to its index' in \
        captured.err
    bag = open_bag(out)
    got = _decoded(bag, '/cam2/image_raw')
    # independent: instant of each frame = round(time * fps); per instant the nearest frame
    instant = np.round(VFR_TIMES * FPS).astype(int)
    expected = {}
    for i in np.unique(instant):
        js = np.flatnonzero(instant == i)
        expected[i] = js[np.argmin(np.abs(VFR_TIMES[js] - i / FPS))]
    assert sorted(got) == [START + round(i * 1e9 / FPS) for i in sorted(expected)]
    for i, j in expected.items():
        stamp = START + round(i * 1e9 / FPS)
        assert abs(float(got[stamp].mean()) - 20 * j) < 4, (i, j)
        assert abs(stamp - START - VFR_TIMES[j] * 1e9) <= 0.5e9 / FPS
    assert START + round(16 * 1e9 / FPS) in got                    # frame 11 at 533 ms
    n_missing = 17 - len(expected)
    assert f"instants without a view (missing frames): {{'cam2': {n_missing}}}" in \
        captured.out
    assert f"frames dropped (a second frame nearest one instant): {{'cam2': " \
        f"{len(VFR_TIMES) - len(expected)}}}" in captured.out
    # the constant-rate cameras: frame j at instant j, exactly
    for v in range(2):
        cfr = _decoded(bag, f'/cam{v}/image_raw')
        assert sorted(cfr) == [START + round(i * 1e9 / FPS) for i in range(17)]
        np.testing.assert_array_equal(cfr[START + round(5 * 1e9 / FPS)], frames[v, 5])
    # --timing index: by index, and said so
    assert main(args + ['--out', str(tmp_path / 'idx'), '--fps', '30', '--timing',
                        'index']) == 0
    assert '--timing index stamped its frames by index' in capsys.readouterr().err
    assert len(_decoded(open_bag(tmp_path / 'idx'), '/cam2/image_raw')) == len(VFR_TIMES)


def test_default_is_compressed_jpeg_and_format_png_alone_works(session, tmp_path, capsys):
    """No transport option: CompressedImage jpeg topics (as help and README say); --format
    png alone: CompressedImage png, lossless; --raw: Image."""
    root, cams, frames = session
    base = ['import', 'videos', str(root / 'videos'), '--calibration',
            str(root / 'calibration.yaml'), '--fps', '30', '--max-frames', '2', '--quiet']
    assert main(base + ['--out', str(tmp_path / 'd')]) == 0
    assert '(CompressedImage jpeg)' in capsys.readouterr().out
    bag = open_bag(tmp_path / 'd')
    for cam in cams:
        assert f'/{cam.name}/image_raw' not in bag.topics
        info = bag.topics[f'/{cam.name}/image_raw/compressed']
        assert info.msgtype == 'sensor_msgs/msg/CompressedImage' and info.count == 2
    assert {m.msg.format for m in bag.messages(['/cam0/image_raw/compressed'])} == {'jpeg'}
    assert main(base + ['--out', str(tmp_path / 'p'), '--format', 'png']) == 0
    bag = open_bag(tmp_path / 'p')
    assert {m.msg.format for m in bag.messages(['/cam2/image_raw/compressed'])} == {'png'}
    got = _decoded(bag, '/cam2/image_raw/compressed')
    np.testing.assert_array_equal([got[s] for s in sorted(got)], frames[2, :2])
    assert main(base + ['--out', str(tmp_path / 'r'), '--raw']) == 0
    assert open_bag(tmp_path / 'r').topics['/cam0/image_raw'].msgtype == \
        'sensor_msgs/msg/Image'
    capsys.readouterr()
    assert main(base + ['--out', str(tmp_path / 'rp'), '--raw', '--format', 'png']) == 2
    assert '--format png applies to CompressedImage topics, not --raw' in \
        capsys.readouterr().err


@pytest.mark.parametrize('option, value, message', [
    ('--max-frames', '-1', '--max-frames must be >= 0 (0 = every instant), got -1'),
    ('--start-ns', '-5', '--start-ns must be >= 0 ns, got -5'),
    ('--fps', '0', '--fps must be a finite number > 0 (frames/s), got 0.0'),
    ('--fps', '1e400', '--fps must be a finite number > 0 (frames/s), got inf'),
    ('--quality', '0', '--quality must be in 1..100, got 0'),
    ('--resize', '2', '--resize must be in (0, 1], got 2.0'),
])
def test_option_errors_name_the_option(session, tmp_path, capsys, option, value, message):
    root, _, _ = session
    assert main(['import', 'videos', str(root / 'videos'), '--calibration',
                 str(root / 'calibration.yaml'), '--out', str(tmp_path / 'o'), '--fps', '30',
                 option, value, '--quiet']) == 2
    err = capsys.readouterr().err.strip()
    assert err == f'monet import videos: {message}'
    assert not (tmp_path / 'o').exists()
