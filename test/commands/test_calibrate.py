"""`monet calibrate` end to end on the real sleap-anipose calibration images: image folders,
videos made from them, --intrinsics, --timestamps, --format both, and bad input (exit 2,
one line)."""
import cv2
import numpy as np
import pytest

from monet_ros.calibration.extrinsics import rotation_angle_deg
from monet_ros.cli import main
from monet_ros.geometry import load_rig

pytestmark = pytest.mark.slow   # detects 21-42 real images per run (~2 min loaded)


@pytest.fixture(scope='module')
def session(shared_data):
    return shared_data / 'sleap_anipose_minimal_session'


def images(session, camera):
    """The camera's images in instant order (the number ending their names)."""
    return sorted((session / camera / 'calibration_images').glob('*.jpg'),
                  key=lambda f: int(f.stem.rsplit('-', 1)[1]))


def link_images(folder, files):
    folder.mkdir(parents=True)
    for f in files:
        (folder / f.name).symlink_to(f)
    return folder


def run(argv, capsys):
    code = main(['calibrate', *map(str, argv), '--quiet'])
    out, err = capsys.readouterr()
    return code, out, err


def relative(a, b):
    R = b.R @ a.R.T
    return R, b.t - R @ a.t


def check_back_mid(path, reference_path):
    cams = {c.name: c for c in load_rig(path)}
    ref = {c.name: c for c in load_rig(reference_path)}
    assert sorted(cams) == ['back', 'mid']
    for name in ('back', 'mid'):
        assert abs(cams[name].K[0, 0] / ref[name].K[0, 0] - 1) < 0.05
    R, t = relative(cams['back'], cams['mid'])
    R0, t0 = relative(ref['back'], ref['mid'])
    assert rotation_angle_deg(R @ R0.T) < 2.0
    assert np.degrees(np.arccos(t @ t0 / np.linalg.norm(t) / np.linalg.norm(t0))) < 3.0
    return cams


@pytest.fixture(scope='module')
def image_run(session, tmp_path_factory):
    out = tmp_path_factory.mktemp('calibrate') / 'calibration.toml'
    code = main(['calibrate', str(session / 'back' / 'calibration_images'),
                 str(session / 'mid' / 'calibration_images'), '--board',
                 str(session / 'board.toml'), '--out', str(out), '--distortion', 'k1k2',
                 '--format', 'both', '--quiet'])
    return code, out


def test_image_folders(image_run, session):
    code, out = image_run
    assert code == 0
    cams = check_back_mid(out, session / 'calibration.toml')
    # --format both: the project rig YAML holds the same cameras
    yaml_cams = {c.name: c for c in load_rig(out.with_suffix('.yaml'))}
    for name, cam in cams.items():
        np.testing.assert_allclose(yaml_cams[name].K, cam.K)
        np.testing.assert_allclose(yaml_cams[name].t, cam.t)
    report = cv2.imread(str(out.with_name('calibration_report.png')))
    assert report is not None and report.shape[0] > 400 and report.shape[1] > 600
    assert report.std() > 10                      # not a blank page


def test_summary_printed(session, tmp_path, capsys):
    # --out in a folder that does not exist yet: made, as other commands make their --out
    code, out, err = run([session / 'back' / 'calibration_images',
                          session / 'mid' / 'calibration_images', '--board',
                          session / 'board.toml', '--out', tmp_path / 'new' / 'c.toml',
                          '--no-report', '--distortion', 'k1k2'], capsys)
    assert code == 0, err
    assert load_rig(tmp_path / 'new' / 'c.toml')
    assert 'back: 21 frames, board in 21, no board in 0' in err
    lines = out.splitlines()
    back = next(line for line in lines if line.startswith('back '))
    assert back.split()[1:4] == ['21', '0', '21']
    assert float(back.split()[5]) < 1.0           # mean px
    assert any(line.startswith('back - mid') for line in lines)
    geometry = next(line for line in lines if line.startswith('board geometry'))
    median = float(geometry.split('triangulated ')[1].split()[0])
    assert abs(median - 24.0) <= 0.5
    assert not (tmp_path / 'new' / 'c_report.png').exists()


def test_video_input(session, tmp_path, capsys):
    videos = []
    for camera in ('back', 'mid'):
        path = tmp_path / f'{camera}.mp4'
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'mp4v'), 10.0,
                                 (1280, 1024))
        assert writer.isOpened()
        for f in images(session, camera):
            writer.write(cv2.imread(str(f)))
        writer.release()
        videos.append(path)
    out = tmp_path / 'calibration.toml'
    code, _, err = run([*videos, '--board', session / 'board.toml', '--out', out,
                        '--distortion', 'k1k2', '--no-report'], capsys)
    assert code == 0, err
    assert 'mid: 21 frames, board in 21' in err
    check_back_mid(out, session / 'calibration.toml')


def test_known_intrinsics_and_names_from_the_calibration(session, tmp_path, capsys):
    back = link_images(tmp_path / 'rig_back_images', images(session, 'back')[:12])
    mid = link_images(tmp_path / 'rig_mid_images', images(session, 'mid')[:12])
    reference = session / 'calibration.toml'
    out = tmp_path / 'calibration.toml'
    code, _, err = run([mid, back, '--board', session / 'board.toml', '--out', out,
                        '--intrinsics', reference, '--no-report'], capsys)
    assert code == 0, err
    cams = {c.name: c for c in load_rig(out)}
    ref = {c.name: c for c in load_rig(reference)}
    # the board is in mm (24 mm squares): the rule says so, the calibration states it
    assert 'camera centres up to' in err and 'the calibration is taken as mm' in err
    assert 'units = "mm"' in out.read_text()
    assert {c.units for c in cams.values()} == {'mm'}
    for name in ('back', 'mid'):
        np.testing.assert_array_equal(cams[name].K, ref[name].K)
        np.testing.assert_array_equal(cams[name].dist, ref[name].dist)
    check_back_mid(out, reference)


def test_timestamps_pair_unequal_frame_counts(session, tmp_path, capsys):
    back = link_images(tmp_path / 'back', images(session, 'back')[:12])
    mid = tmp_path / 'mid'
    mid.mkdir()
    # mid started one frame early: an extra (board-less) first frame, then the 12 images
    cv2.imwrite(str(mid / 'mid_000.jpg'), np.full((1024, 1280, 3), 90, np.uint8))
    for k, f in enumerate(images(session, 'mid')[:12]):
        (mid / f'mid_{k + 1:03d}.jpg').symlink_to(f)
    args = [back, mid, '--board', session / 'board.toml', '--out', tmp_path / 'c.toml',
            '--no-report', '--distortion', 'k1k2']
    code, _, err = run(args, capsys)
    assert code == 2
    assert err.strip().splitlines() == [
        'monet calibrate: error: frame counts do not match across cameras (back: 12, '
        'mid: 13); pair frames with --timestamps CSV']
    csv = tmp_path / 'times.csv'
    rows = [f'back,{k},{k / 10:.3f}' for k in range(12)]
    rows += [f'mid,{k},{(k - 1) / 10 + 0.004:.3f}' for k in range(13)]
    csv.write_text('camera,frame,time_s\n' + '\n'.join(rows) + '\n')
    code, _, err = run(args + ['--timestamps', csv], capsys)
    assert code == 0, err
    assert 'mid: 13 frames, board in 12, no board in 1' in err
    assert '12 instants paired by time' in err
    check_back_mid(tmp_path / 'c.toml', session / 'calibration.toml')


def impossible_board(tmp_path):
    path = tmp_path / 'board.toml'
    path.write_text('board_x = 8\nboard_y = 11\nsquare_length = 24.0\nmarker_length = 30.0\n'
                    'marker_bits = 4\ndict_size = 1000\n')
    return path


@pytest.mark.parametrize('case, expected', [
    ('impossible board', "board field 'marker_length': must be positive and smaller"),
    ('board option', '--board-x: must be in 2..100, got 1'),
    ('no board', '--board: a board TOML'),
    ('empty folder', "(camera 'empty'): no image"),
    ('missing input', 'no such file or folder'),
    ('bad tolerance', '--tolerance must be positive'),
    ('out under a file', 'is not a folder'),
])
def test_bad_input_is_one_line_exit_2(session, tmp_path, capsys, case, expected):
    back = session / 'back' / 'calibration_images'
    board = ['--board', session / 'board.toml']
    empty = tmp_path / 'empty'
    empty.mkdir()
    args = {'impossible board': [back, back.parent.parent / 'mid' / 'calibration_images',
                                 '--board', impossible_board(tmp_path)],
            'board option': [back, '--board-x', '1', '--board-y', '11', '--square-length',
                             '24'],
            'no board': [back],
            'empty folder': [back, empty] + board,
            'missing input': [back, tmp_path / 'absent'] + board,
            'bad tolerance': [back, '--tolerance', '-1'] + board,
            'out under a file': [back, back.parent.parent / 'mid' / 'calibration_images']
            + board}[case]
    (tmp_path / 'file').write_text('a file, not a folder')
    out_path = tmp_path / ('file/c.toml' if case == 'out under a file' else 'c.toml')
    code, out, err = run(args + ['--out', out_path], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('monet calibrate: error: '), err
    assert expected in lines[0]
    assert not (tmp_path / 'c.toml').exists()


def test_camera_names_from_paths(tmp_path):
    from monet_ros.commands.calibrate import _short, input_names
    for name in ('back', 'mid'):
        (tmp_path / name / 'calibration_images').mkdir(parents=True)
    assert input_names([tmp_path / 'back' / 'calibration_images',
                        tmp_path / 'mid' / 'calibration_images']) == ['back', 'mid']
    assert _short(['minimal_session-back-calibration', 'minimal_session-mid-calibration']) \
        == ['back', 'mid']
    assert _short(['cam1', 'cam2']) == ['cam1', 'cam2']      # no separator: kept whole
    assert _short(['Cam_01.mp4', 'Cam_02.mp4']) == ['01', '02']


# Issue 37: a camera that sees the board mirrored, a wrong board spec and a truncated JPEG
# are said plainly; fewer than 2 calibrated cameras is exit 2. Four real images per camera.
def first_images(session, camera, folder, count=4, flip=False):
    folder.mkdir(parents=True)
    for f in images(session, camera)[:count]:
        if flip:                              # what a mirror (or a flipping camera) gives
            cv2.imwrite(str(folder / f.name), cv2.flip(cv2.imread(str(f)), 1))
        else:
            (folder / f.name).symlink_to(f)
    return folder


def test_a_mirrored_camera_is_named_and_one_camera_is_no_rig(session, tmp_path, capsys):
    back = first_images(session, 'back', tmp_path / 'back')
    mid = first_images(session, 'mid', tmp_path / 'mid', flip=True)
    code, out, err = run([back, mid, '--board', session / 'board.toml', '--out',
                          tmp_path / 'c.toml'], capsys)
    assert code == 2, err
    assert 'mid: 4 frames, board in 0, no board in 0, board only mirrored in 4' in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("monet calibrate: error: only camera 'back' can be calibrated; a "
                           'rig needs 2 (mid: 0 board views (intrinsics need 3); the board is '
                           'seen mirrored (left-right) in 4 frames'), last
    assert 'Traceback' not in err and not (tmp_path / 'c.toml').exists()


@pytest.mark.parametrize('options, expected', [
    (['--board-x', '11', '--board-y', '8', '--marker-bits', '4'],
     '44 DICT_4X4_1000 markers found (ids 0-43) that do not fit a 11 x 8 board: check '
     'board_x 11, board_y 8 (swapped?), square_length and marker_length'),
    (['--board-x', '8', '--board-y', '11', '--marker-bits', '5'],
     'markers of 4-bit dictionaries found, none of DICT_5X5_1000: check marker_bits (5; '
     'these are 4) and dict_size'),
    (['--board-x', '4', '--board-y', '5', '--marker-bits', '4'],
     'DICT_4X4_1000 markers found with ids up to 43, but a 4 x 5 board has ids 0-9: check '
     'board_x 4, board_y 5 and dict_size'),
])
def test_a_wrong_board_spec_names_the_fields_to_check(session, tmp_path, capsys, options,
                                                      expected):
    back = first_images(session, 'back', tmp_path / 'back', count=1)
    mid = first_images(session, 'mid', tmp_path / 'mid', count=1)
    spec = ['--square-length', '24', '--marker-length', '18.75', '--dict-size', '1000']
    code, out, err = run([back, mid, *spec, *options, '--out', tmp_path / 'c.toml'], capsys)
    assert code == 2, err
    assert 'back: no board view: ' in err and expected in err, err
    last = err.strip().splitlines()[-1]
    assert last.startswith('monet calibrate: error: no camera has enough board views') \
        and expected in last, last


def test_a_truncated_jpeg_is_named_and_counted_unreadable(session, tmp_path, capsys):
    back = first_images(session, 'back', tmp_path / 'back')
    mid = first_images(session, 'mid', tmp_path / 'mid')
    broken = sorted(back.iterdir())[1]
    data = broken.read_bytes()
    broken.unlink()
    broken.write_bytes(data[:len(data) // 2])          # a copy cut short
    assert cv2.imread(str(broken)) is not None         # OpenCV decodes it (grey below)
    code, out, err = run([back, mid, '--board', session / 'board.toml', '--out',
                          tmp_path / 'c.toml', '--no-report'], capsys)
    assert code == 0, err
    assert 'back: 4 frames, board in 3, no board in 0, unreadable 1' in err, err
    assert f'back: unreadable: {broken}: truncated JPEG (no end-of-image marker)' in err
    assert sorted(c.name for c in load_rig(tmp_path / 'c.toml')) == ['back', 'mid']
