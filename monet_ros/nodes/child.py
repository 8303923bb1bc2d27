"""A node executable run as a child process of a command (`monet pipeline`'s detector).

Why: Python threads share one interpreter lock. With the detector, the fusion and the
player in one process, every short GIL-free call of the detector (OpenCV crop, torch op,
publish) waits for the lock behind the other nodes' Python; bench/pipeline.py measured that
layout 3-4x slower than separate processes on a quiet 2-core machine (detector crop 34 vs
3 ms, publish 42 vs 2 ms per batch). A detector in its own process has its own lock.

`ChildNode(module, params, ros_args)` starts `python -m monet_ros.nodes.<module>` with the
parameters in a temporary YAML file (for the node in any namespace) and the command's own
--ros-args (remappings, namespace), in the command's environment (ROS_DOMAIN_ID, the Fast DDS
profile); it shares the terminal (its log lines are the command's), gets SIGTERM if the
command dies (MONET_PARENT_PID: monet_ros.nodes.die_with_parent), and `stop()` ends it
cleanly (SIGTERM: the node executables exit 0 on it).
"""
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile

import yaml

from monet_ros.nodes import PARENT_PID


class ChildNode:
    """A node executable in a child process. `params`: {name: value} (empty lists are left
    out: their ROS type is unknown); `ros_args`: the command's arguments after --ros-args."""

    def __init__(self, module, params, ros_args=(), node_name=None):
        self.name = node_name or module
        values = {k: v for k, v in params.items() if not (isinstance(v, (list, tuple))
                                                          and not v)}
        values = {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}
        handle, path = tempfile.mkstemp(prefix=f'monet_{self.name}_', suffix='.yaml')
        with os.fdopen(handle, 'w') as stream:
            yaml.safe_dump({f'/**/{self.name}': {'ros__parameters': values}}, stream)
        self.params_file = Path(path)
        ros_args = [a for a in ros_args if a != '--ros-args']
        argv = [sys.executable, '-m', f'monet_ros.nodes.{module}', '--ros-args', *ros_args,
                '--params-file', str(self.params_file)]
        env = dict(os.environ, **{PARENT_PID: str(os.getpid())})
        self.process = subprocess.Popen(argv, env=env)

    def exit_code(self):
        """None while it runs, else its exit code."""
        return self.process.poll()

    def stop(self, timeout_s=10.0):
        """SIGTERM (a clean exit 0 of the node executables), SIGKILL after timeout_s; returns
        the exit code (0 also when it had already stopped on the terminal's SIGINT)."""
        try:
            if self.process.poll() is None:
                self.process.send_signal(signal.SIGTERM)
                try:
                    self.process.wait(timeout=timeout_s)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait()
            return self.process.returncode
        finally:
            self.params_file.unlink(missing_ok=True)
