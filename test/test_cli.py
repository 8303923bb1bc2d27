"""monet's argument errors: one line, exit 2, named by the command, the typo before what
it hides; and its exit code when a signal lands after the work."""
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time

import pytest

from monet_ros.cli import main as monet


@pytest.mark.parametrize('argv, line', [
    (['triangulate', 'x.csv', '--rgi', 'r.yaml', '--out', 'o'],
     'monet triangulate: error: unrecognized arguments: --rgi (did you mean --rig?)'),
    (['triangulate', 'x.csv', '--rig=r.yaml', '--out', 'o', '--bogus'],
     'monet triangulate: error: unrecognized arguments: --bogus'),
    (['process', 'rec', '--precison', 'int8'],
     'monet process: error: unrecognized arguments: --precison (did you mean --precision?)'),
    (['triangulate', 'x.csv', '--ri', 'r.yaml', '--out', 'o'],   # argparse's own answer
     'monet triangulate: error: ambiguous option: --ri could match --rig, --rig-units'),
])
def test_unknown_options_are_named_by_their_command(argv, line, capsys, tmp_path,
                                                    monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert monet(argv) == 2
    err = capsys.readouterr().err
    assert err.strip() == line
    assert not (tmp_path / 'o').exists()


def test_abbreviations_still_parse(capsys, tmp_path):
    # a unique prefix is an option (argparse's abbreviation): the command runs and fails
    # on the missing file, not on the option
    assert monet(['triangulate', str(tmp_path / 'x.csv'), '--rig', str(tmp_path / 'r.yaml'),
                  '--rig-u', 'mm', '--out', str(tmp_path / 'o')]) == 2
    err = capsys.readouterr().err
    assert 'unrecognized' not in err and ('x.csv' in err or 'r.yaml' in err)


@pytest.mark.parametrize('extra, start', [
    (['--fps', '-1'], "monet triangulate: error: --fps: parameter 'fps': must be a finite "
     "number > 0"),
    (['--fps=-1'], "monet triangulate: error: --fps: parameter 'fps': must be a finite "
     "number > 0"),
    # the setting is named, but its value was not typed as --fps: no option is named
    (['--filter', 'kalman'], "monet triangulate: error: parameter 'fps': --filter kalman"),
])
def test_a_bad_setting_given_as_an_option_names_the_option(extra, start, capsys, tmp_path):
    assert monet(['triangulate', str(tmp_path / 'x.csv'), '--rig', str(tmp_path / 'r.yaml'),
                  '--out', str(tmp_path / 'o'), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(start) and '\n' not in err, err


@pytest.mark.parametrize('argv', [
    ['triangulate', 'x.csv', '--rig', 'r.yaml', '--out', 'o', '--gate-mm', '300'],
    ['process', 'rec', '--model', 'm.pt', '--out', 'o', '--link-mm', '500'],
    ['process', 'rec', '--model', 'm.pt', '--out', 'o', '--no-rival-peaks'],
    ['process', 'rec', '--model', 'm.pt', '--out', 'o', '--no-foreign-views'],
    ['process', 'rec', '--model', 'm.pt', '--out', 'o', '--min-score', '0.3'],
    ['pipeline', '--bag', 'rec', '--model', 'm.pt', '--link-mm', '500'],
])
def test_a_subjects_only_option_without_subjects_is_refused(argv, capsys, tmp_path,
                                                            monkeypatch):
    # it would be ignored (one subject): refused before any file is read
    monkeypatch.chdir(tmp_path)
    option = next(a for a in argv[5:] if a.startswith('--'))
    for flag in ('rival-peaks', 'foreign-views'):
        option = f'--{flag} / --no-{flag}' if option.endswith(flag) else option
    assert monet(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f'monet {argv[0]}: error: {option} applies only with --subjects N (N >= 2);'
                   f' monet {argv[0]} runs one subject without it')
    assert monet([*argv, '--subjects', '2']) == 2       # accepted: fails on the missing files
    assert 'applies only' not in capsys.readouterr().err


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_after_the_work_still_exits_0_quietly(repo_root, tmp_path, signum):
    """SIGINT / SIGTERM "at any moment" includes the end: once the command has written its
    output, while main returns and Python shuts down (torch's exit hooks take up to a
    second), a signal killed the process by the signal (exit -2 / -15) or printed a
    KeyboardInterrupt traceback from an exit hook. The signal is sent again and again from
    the last line until the process has gone, so it lands in every phase of the exit."""
    env = dict(os.environ, PYTHONPATH=str(repo_root))
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    proc = subprocess.Popen(
        [sys.executable, '-m', 'monet_ros.cli', 'synth', '--out', str(tmp_path / 'rec'),
         '--cameras', '2', '--frames', '3', '--width', '64', '--height', '48'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=tmp_path)
    lines = []
    for line in proc.stdout:                      # until the command has written its output
        lines.append(line)
        if line.startswith('monet synth: wrote'):
            break
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:
        proc.send_signal(signum)
        time.sleep(0.01)
    rest, _ = proc.communicate(timeout=120)
    output = ''.join(lines) + rest
    assert any(line.startswith('monet synth: wrote') for line in lines), output
    assert proc.returncode == 0, output
    assert 'Traceback' not in output and 'KeyboardInterrupt' not in output, output
    assert (tmp_path / 'rec' / 'rig.yaml').is_file()     # the work stands


def test_a_full_disk_names_the_output(repo_root, shared_data, tmp_path):
    """`monet triangulate --out` on a full file system (a real 16 KiB tmpfs in a private
    mount namespace, as test/test_disk_full.py): exit 2 and one line that names the output
    and says the disk is full (the line named no file: the OS gives none for a write into
    an open file)."""
    if shutil.which('unshare') is None:
        pytest.skip('no unshare(1)')
    mouse = shared_data / 'sleap_anipose_minimal_session'
    mount = tmp_path / 'full'
    mount.mkdir()
    out = mount / 'tri'
    tables = sorted(str(p) for p in mouse.glob('*/minimal_*_proofread.analysis.h5'))
    argv = ['triangulate', *tables, '--rig', str(mouse / 'calibration.toml'), '--fps', '30',
            '--out', str(out)]
    shell = (f'mount -t tmpfs -o size=16k tmpfs {mount} || exit 77; '
             f'exec {shlex.join([sys.executable, "-m", "monet_ros.cli", *argv])}')
    env = dict(os.environ, PYTHONPATH=str(repo_root))
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    done = subprocess.run(['unshare', '-m', 'sh', '-c', shell], capture_output=True,
                          text=True, timeout=300, env=env, cwd=tmp_path)
    if done.returncode == 77 or 'Operation not permitted' in done.stderr:
        pytest.skip('cannot mount a small tmpfs here')
    assert done.returncode == 2, done.stderr
    errors = [line for line in done.stderr.splitlines() if ': error: ' in line]
    assert len(errors) == 1 and 'Traceback' not in done.stderr, done.stderr
    assert errors[0].startswith(f'monet triangulate: error: {out}'), errors[0]
    assert errors[0].endswith('no space left on device (disk full)'), errors[0]
