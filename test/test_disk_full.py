"""A full disk while a checkpoint is written (the learner's and the trainer's path): one
error that names the file and says the disk is full, and nothing partial left behind.

A real full file system: a 256 KiB tmpfs mounted in a private mount namespace
(`unshare -m`, needs root or user namespaces; skipped where the machine cannot), and a real
torch.save of a ~1 MB checkpoint into it.
"""
import shutil
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import os, sys, torch
    from monet_ros.models import build_model, save_checkpoint
    folder = sys.argv[1]
    model = build_model('small', 3, width=48)
    try:
        save_checkpoint(os.path.join(folder, 'ckpt', 'model.pt'), model,
                        {'keypoints': ['a', 'b', 'c']})
    except OSError as error:
        print('ERROR', type(error).__name__, error)
    print('LEFT', sorted(os.listdir(os.path.join(folder, 'ckpt'))))
""")


def _in_small_tmpfs(tmp_path, script):
    if shutil.which('unshare') is None:
        pytest.skip('no unshare(1)')
    mount = tmp_path / 'full'
    mount.mkdir()
    (tmp_path / 'script.py').write_text(script)
    shell = (f'mount -t tmpfs -o size=256k tmpfs {mount} || exit 77; '
             f'exec {sys.executable} {tmp_path / "script.py"} {mount}')
    done = subprocess.run(['unshare', '-m', 'sh', '-c', shell], capture_output=True,
                          text=True, timeout=120)
    if done.returncode == 77 or 'Operation not permitted' in done.stderr:
        pytest.skip('cannot mount a small tmpfs here')
    return done, mount


def test_checkpoint_on_full_disk_names_path_and_leaves_nothing(tmp_path):
    done, mount = _in_small_tmpfs(tmp_path, SCRIPT)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    error = next(line for line in lines if line.startswith('ERROR'))
    assert 'DiskFullError' in error and 'disk full' in error
    assert str(mount / 'ckpt' / 'model.pt') in error
    assert 'inline_container' not in error
    assert lines[-1] == 'LEFT []'          # no partial file, no temporary file


LOG_SCRIPT = textwrap.dedent("""
    import os, sys
    from monet_ros.atomic import write_error
    path = os.path.join(sys.argv[1], 'train_log.csv')
    try:
        with open(path, 'w') as stream:
            stream.write('x' * (1 << 20))
    except OSError as error:
        error = write_error(path, error)
        print('ERROR', type(error).__name__, error)
""")


def test_plain_file_write_on_full_disk_names_the_file(tmp_path):
    """The trainer's CSV log (a plain append, not atomic) on a full disk."""
    done, mount = _in_small_tmpfs(tmp_path, LOG_SCRIPT)
    assert done.returncode == 0, done.stderr
    error = next(line for line in done.stdout.splitlines() if line.startswith('ERROR'))
    assert 'DiskFullError' in error and 'disk full' in error
    assert str(mount / 'train_log.csv') in error
