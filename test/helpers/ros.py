"""Real ROS 2 plumbing for tests: node executables as subprocesses, an in-test rclpy node.

    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as fusion:
        got = ros.collect('/monet/keypoints3d', PointCloud2)
        ros.spin_until(lambda: got, timeout=10)
        assert fusion.stop() == 0

No mocks: the node under test is the real executable (`python -m monet_ros.nodes.<name>`)
in its own process, on a random ROS_DOMAIN_ID (the `ros_env` fixture).
"""
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
import yaml

from monet_ros.nodes.qos import STREAM_IN


def write_params_file(path, node_name, params):
    """A --params-file YAML for one node in any namespace
    ({/**/name: {ros__parameters: params}})."""
    clean = {k: list(v) if isinstance(v, tuple) else v for k, v in params.items()}
    Path(path).write_text(yaml.safe_dump({f'/**/{node_name}': {'ros__parameters': clean}}))
    return Path(path)


def newest_status(diagnostics, name):
    """The newest DiagnosticStatus called `name` in a list of received DiagnosticArray
    messages (None if none yet)."""
    for msg in reversed(diagnostics):
        for status in msg.status:
            if status.name == name:
                return status
    return None


class NodeProcess:
    """`python -m monet_ros.nodes.<module>` (or any argv) as a subprocess with output in files.

    params: dict written to a params file; extra_args: more --ros-args arguments.
    terminal: the process leads its own process group and stop() signals the whole group,
    as a terminal's Ctrl-C does (what `ros2 launch` relies on: it leaves its nodes to the
    SIGINT they get from the terminal, and sends SIGTERM only 5 s later).
    A fusion node given params fuses every frame however long it waited in its input queue
    (max_queue_ms 0, unless the test sets it): on a loaded machine the node may fall behind
    by more than the default 100 ms, and a test that waits for a frame's 3D would wait for
    a frame skipped as stale (the stale skip has its own test, test_fusion_stale.py).
    """
    DEFAULTS = {'fusion': {'max_queue_ms': 0.0}}

    def __init__(self, module, env, params=None, node_name=None, extra_args=(), argv=None,
                 workdir=None, cwd=None, terminal=False):
        self.env = dict(env)
        self.cwd = cwd
        self.terminal = terminal
        self.workdir = Path(workdir or self.env.get('ROS_LOG_DIR', '/tmp')).parent
        self.workdir.mkdir(parents=True, exist_ok=True)
        tag = f'{module}_{time.monotonic_ns()}'
        if argv is None:
            argv = [sys.executable, '-m', f'monet_ros.nodes.{module}', '--ros-args']
            if params:
                params = {**self.DEFAULTS.get(module, {}), **params}
                path = write_params_file(self.workdir / f'{tag}.yaml', node_name or module,
                                         params)
                argv += ['--params-file', str(path)]
            argv += list(extra_args)
        self.argv = argv
        self.stdout_path = self.workdir / f'{tag}.out'
        self.stderr_path = self.workdir / f'{tag}.err'
        self.process = None

    def start(self):
        self._out = open(self.stdout_path, 'wb')
        self._err = open(self.stderr_path, 'wb')
        self.process = subprocess.Popen(self.argv, env=self.env, stdout=self._out,
                                        stderr=self._err, stdin=subprocess.DEVNULL,
                                        cwd=self.cwd, process_group=0 if self.terminal else None)
        return self

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        if self.process.poll() is None:
            self.stop()
        self._out.close()
        self._err.close()

    def running(self):
        return self.process.poll() is None

    def wait(self, timeout=30):
        """Wait for the process to exit on its own; returns the exit code."""
        return self.process.wait(timeout=timeout)

    def stop(self, sig=signal.SIGINT, timeout=60):
        """Send `sig`, wait, return the exit code (kill and fail loudly on a hang)."""
        if self.process.poll() is None:
            if self.terminal:
                os.killpg(self.process.pid, sig)
            else:
                self.process.send_signal(sig)
            try:
                self.process.wait(timeout=timeout)
            except subprocess.TimeoutExpired as error:
                self.process.kill()
                self.process.wait()
                raise AssertionError(f'{self.argv} did not exit within {timeout} s of {sig!r}'
                                     f'\n{self.output()}') from error
        return self.process.returncode

    def output(self):
        """stdout + stderr so far (for assertion messages)."""
        out = self.stdout_path.read_text(errors='replace') if self.stdout_path.exists() else ''
        err = self.stderr_path.read_text(errors='replace') if self.stderr_path.exists() else ''
        return f'--- stdout\n{out}--- stderr\n{err}'


class RosHarness:
    """An rclpy node inside the test process on the test's ROS domain.

    Sets the ROS environment variables of `env` in os.environ (restored on close) so that
    discovery range and Fast DDS profile match the node processes.
    """

    KEYS = ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTRTPS_DEFAULT_PROFILES_FILE',
            'ROS_LOG_DIR')

    def __init__(self, env, name='test_harness'):
        self._saved = {k: os.environ.get(k) for k in self.KEYS}
        for key in self.KEYS:
            if key in env:
                os.environ[key] = env[key]
        self.context = Context()
        rclpy.init(context=self.context, domain_id=int(env['ROS_DOMAIN_ID']))
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        for key, value in self._saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value

    def publisher(self, topic, msg_type, qos=10):
        return self.node.create_publisher(msg_type, topic, qos)

    def collect(self, topic, msg_type, qos=STREAM_IN):
        """Subscribe and return the list the messages are appended to."""
        received = []
        self.node.create_subscription(msg_type, topic, received.append, qos)
        return received

    def spin_for(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def spin_until(self, predicate, timeout=20.0, process=None):
        """Spin until predicate() is true (returns True) or the timeout (returns False).
        Fails at once if `process` (a NodeProcess) died."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            if process is not None and not process.running():
                raise AssertionError(f'node exited early with {process.process.returncode}\n'
                                     f'{process.output()}')
            self.executor.spin_once(timeout_sec=0.05)
        return bool(predicate())

    def wait_for_subscribers(self, publisher, count=1, timeout=20.0, process=None):
        """Spin until `publisher` is matched by `count` subscriptions."""
        ok = self.spin_until(lambda: publisher.get_subscription_count() >= count, timeout,
                             process)
        assert ok, f'no subscriber on {publisher.topic_name} after {timeout} s'

    def call(self, srv_type, name, request, process=None, attempts=3):
        """One service call -> its response; sent again (up to `attempts` times) when no
        response comes: service_is_ready means the request side is matched, and a response
        sent before the client's response reader is matched by the server is lost (DDS
        discovery is not symmetric). Fails at once if `process` died."""
        clients = self.__dict__.setdefault('_clients', {})
        client = clients.get((srv_type, name))
        if client is None:      # one client per service: discovered once, reused
            client = clients[srv_type, name] = self.node.create_client(srv_type, name)
        assert self.spin_until(client.service_is_ready, timeout=30, process=process), name
        for _ in range(attempts):
            future = client.call_async(request)
            if self.spin_until(future.done, timeout=10, process=process):
                return future.result()
            client.remove_pending_request(future)
        raise AssertionError(f'{name}: no response to {attempts} requests')

    def wait_heard(self, diagnostics, names, timeout=120.0, process=None):
        """Spin until a /diagnostics status of every one of `names` arrived in
        `diagnostics` (a collect() list). A node heard from has matched this harness's
        readers: create the diagnostics collector after the others, so that its readers
        are announced last and every earlier one is known to the node too (the first
        messages of a node whose discovery of the harness lagged were lost otherwise)."""
        ok = self.spin_until(lambda: all(newest_status(diagnostics, n) is not None
                                         for n in names), timeout, process)
        assert ok, f'no /diagnostics of {names} after {timeout} s'

    def wait_for_publishers(self, topic, count=1, timeout=20.0, process=None):
        ok = self.spin_until(lambda: self.node.count_publishers(topic) >= count, timeout,
                             process)
        assert ok, f'no publisher on {topic} after {timeout} s'
