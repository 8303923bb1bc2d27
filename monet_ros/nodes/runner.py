"""Clean start and exit of the node executables.

`run_node(factory)` initialises rclpy, builds the node (a bad parameter, file or model is
a clear one-line error and exit code 2), spins it, and on SIGINT / SIGTERM / Ctrl-C
destroys it and shuts rclpy down, exiting 0 - at any moment, start-up included (the
package installs exit-0 handlers before the heavy imports, monet_ros.nodes).

Nothing that arrives on a topic stops a node: every subscription and timer callback runs
under a CallbackGuard, which counts an exception per topic and kind, logs each kind once,
and reports the counts in /diagnostics ('monet <node>: callback errors').
"""
from collections import Counter
from contextlib import contextmanager
import functools
import os
import re
import signal
import sys
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from monet_ros.error_text import error_line
from monet_ros.share import share_path
from monet_ros.stop_signals import ignore_stop_signals, interrupt_on_stop

EXIT_OK = 0
EXIT_BAD_START = 2

FASTDDS_PROFILE = 'fastdds_profile.xml'


def use_large_data_profile():
    """Point Fast DDS at config/fastdds_profile.xml (64 MB shared memory) unless the user
    already chose a profile. Must run before the first rclpy.init of the process."""
    if 'FASTRTPS_DEFAULT_PROFILES_FILE' not in os.environ:
        try:
            profile = share_path('config', FASTDDS_PROFILE)
        except FileNotFoundError:
            return
        os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(profile)


def start_error(name, error):
    """Print a start-up error as one clear line on stderr (whitespace collapsed: torch's
    and other libraries' texts span lines; error_text.error_line)."""
    print(f'{name}: error: {error_line(error, name)}', file=sys.stderr, flush=True)


def stopped_by_shutdown(context=None):
    """True once SIGINT / SIGTERM (rclpy's signal handler) or rclpy.shutdown() has closed the
    context. An executor caught inside spin at that moment raises RCLError ('context is not
    valid') instead of ExternalShutdownException: that is a clean stop, not a failure."""
    return not rclpy.ok(context=context)


@contextmanager
def until_shutdown():
    """Treat the ways a spin ends on SIGINT / SIGTERM as a clean stop: KeyboardInterrupt,
    ExternalShutdownException, and any error raised once the context is shut down (see
    stopped_by_shutdown). Anything else propagates."""
    try:
        yield
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if not stopped_by_shutdown():
            raise


def stop_executor(executor, timeout_sec=2.0):
    """Shut `executor` down and wait for the callbacks still running in its threads.

    rclpy 7's Executor.shutdown does not wait for a MultiThreadedExecutor's in-flight
    callbacks; destroying the nodes under them makes them fail ("cannot use Destroyable"),
    and the failed tasks print "exception was never retrieved" when collected. Waiting for
    them (and collecting what they raised while the context closed) keeps the exit quiet."""
    executor.shutdown(timeout_sec=timeout_sec)
    deadline = time.monotonic() + timeout_sec
    for task in list(getattr(executor, '_futures', ())):     # MultiThreadedExecutor only
        while not task.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        if task.done():
            task.exception()          # marks it retrieved: a stop-time failure, not a bug


class CallbackGuard:
    """Runs a node's subscription and timer callbacks so that an exception costs only that
    call: counted per topic (timer callbacks: per callback name) and exception type, logged
    once per kind (with the message), published on /diagnostics every second while any
    were counted. `errors`: Counter {(source, exception type name): count}."""

    def __init__(self, node):
        self.node = node
        self.errors = Counter()
        self.last = {}
        for sub in list(node.subscriptions):
            sub.callback = self.wrap(sub.topic_name, sub.callback)
        for timer in list(node.timers):
            label = getattr(timer.callback, '__name__', 'timer')
            timer.callback = self.wrap(f'timer {label}', timer.callback)
        from diagnostic_msgs.msg import DiagnosticArray
        self._array = DiagnosticArray
        self.pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        node.create_timer(1.0, self.publish)

    def wrap(self, source, callback):
        # functools.wraps keeps the callback's signature (inspect.signature follows
        # __wrapped__): rclpy passes a subscription's MessageInfo only to a callback that
        # takes two arguments
        @functools.wraps(callback)
        def guarded(*args):
            try:
                return callback(*args)
            except Exception as error:  # noqa: BLE001 - nothing on a topic may stop the node
                if stopped_by_shutdown(self.node.context):
                    raise
                self.record(source, error)
                return None
        return guarded

    def record(self, source, error):
        kind = (source, type(error).__name__)
        self.errors[kind] += 1
        self.last[source] = f'{type(error).__name__}: {error_line(error)}'
        if self.errors[kind] == 1:
            self.node.get_logger().error(
                f'{source}: message not handled ({self.last[source]}); the node '
                'goes on, further errors of this kind are counted in /diagnostics')

    def publish(self):
        if not self.errors:
            return
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
        msg = self._array()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        by_source = Counter()
        for (source, _), count in self.errors.items():
            by_source[source] += count
        for source, count in sorted(by_source.items()):
            msg.status.append(DiagnosticStatus(
                level=DiagnosticStatus.WARN, name=f'monet {self.node.get_name()}: callback '
                f'errors: {source}', hardware_id=source,
                message=f'{count} message(s) not handled on {source}',
                values=[KeyValue(key='errors', value=str(count)),
                        KeyValue(key='last_error', value=self.last[source])]))
        self.pub.publish(msg)


_NUMBERS = re.compile(r'[-+]?\d+(\.\d*)?([eE][-+]?\d+)?')


def log_bad_once(node, source, error, count):
    """Log a bad message from `source` once per kind (the text with its numbers blanked,
    so "image is 320x240" and "image is 640x480" are one kind); later ones are only
    counted (the node's /diagnostics). Returns True when it logged."""
    seen = node.__dict__.setdefault('_bad_kinds_logged', set())
    kind = (source, _NUMBERS.sub('#', str(error))[:160])
    if kind in seen:
        return False
    if len(seen) < 1000:
        seen.add(kind)
    node.get_logger().warning(f'{source}: bad message ({error}); {count} so far; further '
                              'messages of this kind are counted in /diagnostics')
    return True


def clean_stop_handlers():
    """SIGINT and SIGTERM raise KeyboardInterrupt (a clean stop in until_shutdown) until
    rclpy's own handlers take over (they chain to these)."""
    interrupt_on_stop()


_STOP = threading.Event()


def stop_requested():
    """True once SIGINT or SIGTERM arrived (see init_rclpy)."""
    return _STOP.is_set()


def init_rclpy(args=None):
    """rclpy.init without rclpy's signal handlers: SIGINT and SIGTERM only set a flag
    (stop_requested) that the spin loops check every 0.1 s, instead of closing the context
    at once or raising inside a callback, so the nodes can still publish their goodbye
    (on_stop: DELETEALL markers) before they are destroyed. Main thread only."""
    _STOP.clear()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)

    def request_stop(signum, frame):
        _STOP.set()
    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)


def say_goodbye(nodes):
    """Call each node's on_stop() (when it has one) while the context is still valid; a
    failure there is reported in one line, never a traceback."""
    for node in nodes:
        on_stop = getattr(node, 'on_stop', None)
        if on_stop is None or not rclpy.ok(context=node.context):
            continue
        try:
            on_stop()
        except Exception as error:  # noqa: BLE001 - stopping anyway
            print(f'{node.get_name()}: on stop: {error}', file=sys.stderr, flush=True)


def run_node(factory, name, args=None, large_data=False):
    """Run the node built by `factory()` until shutdown; return the process exit code.

    Errors while building the node (ValueError subclasses such as ConfigError, RigError,
    CheckpointError, OSError for missing files, and any other exception, with its type)
    print one line and return 2. SIGINT /
    SIGTERM at any moment return 0. The node's callbacks run under a CallbackGuard.
    """
    if large_data:
        use_large_data_profile()
    node = executor = None
    try:
        clean_stop_handlers()       # a signal before the flag handlers of init_rclpy: exit 0
        init_rclpy(args)
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return EXIT_OK
    except Exception as error:  # noqa: BLE001 - e.g. malformed --ros-args: one line, exit 2
        start_error(name, f'cannot start ROS: {error}')
        return EXIT_BAD_START
    try:
        with until_shutdown():
            try:
                node = factory()
            except (ValueError, OSError) as error:
                start_error(name, error)
                return EXIT_BAD_START
            except Exception as error:  # noqa: BLE001 - never a traceback: one line, exit 2
                if stopped_by_shutdown():
                    raise
                start_error(name, f'{type(error).__name__}: {error}')
                return EXIT_BAD_START
            node.callback_guard = CallbackGuard(node)
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            while rclpy.ok() and not stop_requested():   # wakes up to see a signal
                executor.spin_once(timeout_sec=0.1)
    finally:
        ignore_stop_signals()     # no KeyboardInterrupt inside destroy_node (a second
                                  # Ctrl-C, or a launch file's SIGINT after the terminal's)
        try:
            if node is not None:
                say_goodbye([node])
            if executor is not None:   # now, not in its __del__ at interpreter exit (which
                stop_executor(executor, timeout_sec=0.5)   # printed a traceback at times)
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        except KeyboardInterrupt:
            pass
    return EXIT_OK
