"""Option errors name the option as typed and say what a value must be: a non-finite --fps
is refused as not finite, `monet pipeline --threshold-px inf` names --threshold-px (as its
other options are named), before anything starts; one line, exit 2."""
import subprocess
import sys

from monet_ros.cli import main as monet


def test_an_infinite_fps_is_refused_as_not_finite(tmp_path, capsys):
    points = tmp_path / 'points.csv'
    points.write_text('frame,camera,keypoint,u,v,score\n0,cam0,nose,1.0,2.0,0.9\n')
    rig = tmp_path / 'rig.yaml'
    rig.write_text('cameras: []\n')
    assert monet(['triangulate', str(points), '--rig', str(rig), '--out',
                  str(tmp_path / 'out'), '--fps', '1e400']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'fps'" in err[0] and 'finite' in err[0] and 'inf' in err[0], err
    assert not (tmp_path / 'out').exists()


def test_pipeline_threshold_px_inf_names_the_option(tmp_path):
    # a process of its own: `monet pipeline` sets up threads and ROS for the whole process
    result = subprocess.run([sys.executable, '-m', 'monet_ros.cli', 'pipeline',
                             '--workdir', str(tmp_path / 'work'), '--threshold-px', 'inf'],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and '--threshold-px: ' in lines[0] and 'finite' in lines[0], lines
    assert not (tmp_path / 'work').exists()         # refused before the demo was prepared
