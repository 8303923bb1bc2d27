"""`monet import videos` of sleap-anipose's layout, a folder per camera holding its video:
the real minimal session (camera = folder name, matched to calibration.toml's names; the
calibration_images/ subfolders are not read) gives the videos' frames; a generated camera
folder with two videos is one line naming them."""
import cv2
from helpers.ring import ring_rig
import numpy as np

from monet_ros.cli import main
from monet_ros.geometry import load_rig, save_rig
from monet_ros.learning.recording import load_recording

SESSION = 'sleap_anipose_minimal_session'


def video_frames(path, count, size):
    """The first `count` frames of a video, RGB, resized as the importer does."""
    capture = cv2.VideoCapture(str(path))
    out = []
    for _ in range(count):
        ok, frame = capture.read()
        assert ok
        out.append(cv2.resize(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB), size,
                              interpolation=cv2.INTER_AREA))
    capture.release()
    return np.stack(out)


def test_sleap_anipose_session_folders_are_the_cameras(shared_data, tmp_path, capsys):
    root = shared_data / SESSION
    out = tmp_path / 'rec'
    code = main(['import', 'videos', str(root), '--calibration', str(root / 'calibration.toml'),
                 '--out', str(out), '--raw', '--resize', '0.25', '--max-frames', '2',
                 '--quiet'])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert '4 cameras x 2 instants at 30 fps' in captured.out
    names = [c.name for c in load_rig(root / 'calibration.toml')]
    assert names == ['back', 'mid', 'side', 'top']
    for name in names:
        assert f'  {name} <- {root / name / f"minimal_{name}.mp4"} (320x256, ' in captured.out
    rec = load_recording(out, skeleton=('a',))
    got = [c.name for c in rec.cameras]
    for name in names:
        np.testing.assert_array_equal(rec.frames[got.index(name)],
                                      video_frames(root / name / f'minimal_{name}.mp4', 2,
                                                   (320, 256)))


def write_video(path, frames):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'FFV1'), 30.0,
                             frames.shape[2:0:-1])
    for f in frames:
        writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    writer.release()


def test_camera_folders_one_video_each_else_one_line(tmp_path, capsys):
    cams = ring_rig(2, width=64, height=48, focal=60.0)
    save_rig(tmp_path / 'calibration.yaml', cams)
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (2, 4, 48, 64, 3), dtype=np.uint8)
    session = tmp_path / 'session'
    for v, cam in enumerate(cams):
        (session / cam.name / 'calibration_images').mkdir(parents=True)
        write_video(session / cam.name / f'trial_{cam.name}.mkv', frames[v])
        write_video(session / cam.name / 'calibration_images' / 'board.mkv', frames[1 - v])
    out = tmp_path / 'rec'
    args = ['import', 'videos', str(session), '--calibration',
            str(tmp_path / 'calibration.yaml'), '--raw', '--quiet']
    assert main([*args, '--out', str(out)]) == 0
    capsys.readouterr()
    rec = load_recording(out, skeleton=('a',))
    got = [c.name for c in rec.cameras]
    for v, cam in enumerate(cams):
        np.testing.assert_array_equal(rec.frames[got.index(cam.name)], frames[v])
    # a second video in one camera's folder: which one is meant is not guessed
    write_video(session / cams[1].name / 'retake.mkv', frames[0])
    assert main([*args, '--out', str(tmp_path / 'rec2')]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and 'Traceback' not in err, err
    assert (f'{session / cams[1].name}: 2 videos (retake.mkv, trial_{cams[1].name}.mkv): a '
            'camera folder holds one video') in err
    assert not (tmp_path / 'rec2').exists()
