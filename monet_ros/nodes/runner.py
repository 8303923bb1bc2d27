"""Clean start and exit of the node executables.

`run_node(factory)` initialises rclpy, builds the node (a bad parameter, file or model is
a clear one-line error and exit code 2), spins it, and on SIGINT / SIGTERM / Ctrl-C
destroys it and shuts rclpy down, exiting 0.
"""
from contextlib import contextmanager
import os
import signal
import sys
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from monet_ros.share import share_path

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
    """Print a start-up error as one clear line on stderr."""
    print(f'{name}: error: {error}', file=sys.stderr, flush=True)


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


def ignore_signals():
    """After the first SIGINT / SIGTERM: ignore further ones while the nodes are destroyed
    (a second Ctrl-C, or a launch file's SIGINT after the terminal's, must not raise
    KeyboardInterrupt inside destroy_node). Only possible in the main thread."""
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)


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
    CheckpointError, and OSError for missing files) print one line and return 2.
    """
    if large_data:
        use_large_data_profile()
    init_rclpy(args)
    node = None
    try:
        with until_shutdown():
            try:
                node = factory()
            except (ValueError, OSError) as error:
                start_error(name, error)
                return EXIT_BAD_START
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            while rclpy.ok() and not stop_requested():   # wakes up to see a signal
                executor.spin_once(timeout_sec=0.1)
    finally:
        ignore_signals()
        if node is not None:
            say_goodbye([node])
            node.destroy_node()
        rclpy.try_shutdown()
    return EXIT_OK
