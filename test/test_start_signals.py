"""SIGINT / SIGTERM during an executable's start-up (its imports of numpy, torch, cv2,
rclpy ...) exit 0 with no traceback, for every executable in setup.py: the rule is "at any
moment", and `monet` with `monet_ros.cli:console_main` as its target printed a
KeyboardInterrupt traceback (SIGINT) or died with -15 (SIGTERM) while monet_ros.cli itself
was imported.

Each run is the console script as pip generates it (setuptools' template differs only in
how it finds the same function) with a preamble: an import hook that sends the signal to
the process itself, with os.kill, when a given module starts being imported. So the signal
lands at that moment whatever the machine's load, and the run says it was sent. The
interpreter's own start-up before the script's first line is no one's to mend (see
monet_ros.entry) and is not tested."""
from pathlib import Path
import subprocess
import sys

from helpers.commands import setup_executables
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]

# The import hook, ahead of the generated script.
SIGNAL_AT = """\
import os
import signal
import sys


class SignalAt:
    sent = False

    def find_spec(self, name, path=None, target=None):
        if name == {module!r} and not self.sent:
            self.sent = True
            os.write(2, b'sent {signal} at {module}\\n')
            os.kill(os.getpid(), signal.{signal})


sys.meta_path.insert(0, SignalAt())
"""

# pip's console-script template (distlib's), for `name = module:function`.
CONSOLE_SCRIPT = """\
import re
import sys
from {module} import {function}
if __name__ == '__main__':
    sys.argv[0] = re.sub(r'(-script\\.pyw|\\.exe)?$', '', sys.argv[0])
    sys.exit({function}())
"""

# Modules each executable imports after our first line, in order (the moments tested).
MOMENTS = {'monet': ['monet_ros.cli', 'monet_ros.commands', 'numpy', 'torch', 'cv2']}
NODE_MOMENTS = ['monet_ros.nodes.{name}', 'rclpy']


def cases():
    for name, target in setup_executables(REPO_ROOT).items():
        for moment in MOMENTS.get(name, NODE_MOMENTS):
            for signal in ('SIGINT', 'SIGTERM'):
                yield pytest.param(name, target, moment.format(name=name), signal,
                                   id=f'{name}-{moment.format(name=name)}-{signal}')


@pytest.mark.parametrize('name, target, moment, signal', list(cases()))
def test_a_signal_during_start_up_exits_0_quietly(name, target, moment, signal, tmp_path,
                                                  ros_env):
    module, function = target.split(':')
    script = tmp_path / name             # the executable's own name, as installed
    script.write_text(SIGNAL_AT.format(module=moment, signal=signal)
                      + CONSOLE_SCRIPT.format(module=module, function=function))
    # without the signal: `monet` exits 2 (no command), a node 2 (no such rig file)
    args = [] if name == 'monet' else ['--ros-args', '-p', f'rig:={tmp_path / "none.yaml"}']
    result = subprocess.run([sys.executable, str(script), *args], env=ros_env, cwd=tmp_path,
                            capture_output=True, text=True, timeout=300)
    assert f'sent {signal} at {moment}' in result.stderr, result.stderr   # it landed there
    assert result.returncode == 0, result.stderr
    assert 'Traceback' not in result.stderr and 'KeyboardInterrupt' not in result.stderr, \
        result.stderr
