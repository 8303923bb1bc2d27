"""A node executable run as a child process of a command (`monet pipeline`'s player and
detectors).

Why: Python threads share one interpreter lock. With the detector, the fusion and the
player in one process, every short GIL-free call of the detector (OpenCV crop, torch op,
publish) waits for the lock behind the other nodes' Python; bench/pipeline.py measured that
layout 3-4x slower than separate processes on a quiet 2-core machine (detector crop 34 vs
3 ms, publish 42 vs 2 ms per batch). A detector in its own process has its own lock.
The player too: sharing fusion's process, its publishing put a tail on fusion's latency
(p95 106 / 312 ms float32 / bfloat16 at 8 cameras @ 30 Hz against 48 / 28 ms apart).

`ChildNode(module, params, ros_args)` starts `python -m monet_ros.nodes.<module>` with the
command's own --ros-args (remappings, namespace) and the parameters (`-p name:=value`),
in the command's environment (ROS_DOMAIN_ID, the Fast DDS profile); it shares the terminal
(its log lines are the command's), is killed if the command dies (MONET_PARENT_PID:
monet_ros.nodes.die_with_parent), and `stop()` ends it cleanly (SIGTERM: the node
executables exit 0 on it).
"""
import json
import os
import signal
import subprocess
import sys

from monet_ros.nodes import PARENT_PID


class ChildNode:
    """A node executable in a child process. `params`: {name: value} (str, bool, int,
    float or lists of them; empty lists are left out: their ROS type is unknown);
    `ros_args`: the command's arguments after --ros-args."""

    def __init__(self, module, params, ros_args=()):
        self.name = module
        args = []
        for key, value in params.items():
            if isinstance(value, (list, tuple)) and not value:
                continue
            value = list(value) if isinstance(value, tuple) else value
            args += ['-p', f'{key}:={json.dumps(value)}']     # JSON is YAML, as rcl reads
        ros_args = [a for a in ros_args if a != '--ros-args']
        argv = [sys.executable, '-m', f'monet_ros.nodes.{module}', '--ros-args', *ros_args,
                *args]
        env = dict(os.environ, **{PARENT_PID: str(os.getpid())})
        self.process = subprocess.Popen(argv, env=env)

    def exit_code(self):
        """None while it runs, else its exit code."""
        return self.process.poll()

    def stop(self, timeout_s=10.0):
        """SIGTERM (a clean exit 0 of the node executables), SIGKILL after timeout_s; returns
        the exit code (0 also when it had already stopped on the terminal's SIGINT)."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.returncode
