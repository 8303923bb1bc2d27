"""`monet demo` reproduces Pose2Sim's demo triangulation and reports per-camera errors."""
from monet_ros.cli import main


def test_demo_on_pose2sim_data(shared_data, capsys):
    assert main(['demo', '--data', str(shared_data)]) == 0
    out = capsys.readouterr().out
    assert '100 frames x 21 markers = 2100 points, 4 cameras' in out
    assert '2094 of 2100 points within 0.1 mm' in out
    lines = [line.split() for line in out.splitlines() if line.startswith('cam_0')]
    assert [row[0] for row in lines] == ['cam_01', 'cam_02', 'cam_03', 'cam_04']
    errors = [float(row[-1]) for row in lines]
    # each accepted point has a mean error <= 15 px over its views, so a view is within 2x
    assert all(0 < e < 30.0 for e in errors)


def test_demo_without_data_is_a_clear_error(tmp_path, capsys):
    assert main(['demo', '--data', str(tmp_path)]) == 2
    assert 'not found' in capsys.readouterr().err


def test_synthetic_demo(capsys):
    assert main(['demo', '--synthetic']) == 0
    out = capsys.readouterr().out
    assert 'synthetic demo: 100 frames x 14 keypoints, 8 cameras' in out
    mean_mm = float(out.split('3D error mean ')[1].split(' mm')[0])
    assert mean_mm < 5.0  # 0.5 px noise on a 4 m ring; outliers are removed
    flagged, total = out.split('outliers flagged ')[1].split()[0].split('/')
    assert int(flagged) == int(total) > 0
