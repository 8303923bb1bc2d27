"""The one rule for SIGINT and SIGTERM, for the `monet` command and every node executable:
exit 0 at any moment, quietly (never a KeyboardInterrupt traceback, never killed by the
signal with -2 / -15). Three phases, each with its handlers here:

- start-up, nothing to clean up yet (imports of numpy, torch, cv2, rclpy ...):
  exit_0_on_stop() - the process ends at once with 0 (os._exit, nothing printed);
  installed by the executables' first line of our code (monet_ros.entry,
  monet_ros.nodes);
- the work: interrupt_on_stop() - both signals raise KeyboardInterrupt, which the command
  (cli.main) or node (nodes.runner) catches to stop cleanly and return 0;
- the end: ignore_stop_signals() - once the work has returned, a further signal (while
  nodes are destroyed, or Python's exit hooks run) is ignored.

Within the work, stop_signals_deferred() holds a signal back to the end of a block (the
lazy imports of C extensions, which can turn the KeyboardInterrupt into an ImportError) and
then gives it to the handler in force.

Standard library only: imported before any heavy module.
"""
from contextlib import contextmanager
import os
import signal
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _in_main_thread():
    return threading.current_thread() is threading.main_thread()


def exit_0(signum, frame):
    """Signal handler: end the process now with exit code 0 (no clean-up, nothing
    printed)."""
    os._exit(0)


def exit_0_on_stop():
    """SIGINT / SIGTERM -> exit_0 (only while nothing needs cleaning up: start-up). Main
    thread only; elsewhere a no-op."""
    if _in_main_thread():
        for sig in STOP_SIGNALS:
            signal.signal(sig, exit_0)


def raise_interrupt(signum, frame):
    """Signal handler: raise KeyboardInterrupt (the clean stop the command or node
    catches)."""
    raise KeyboardInterrupt


def interrupt_on_stop():
    """SIGINT and SIGTERM raise KeyboardInterrupt from now on (main thread only; elsewhere a
    no-op)."""
    if _in_main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, raise_interrupt)


def ignore_stop_signals():
    """SIGINT and SIGTERM ignored from now on (main thread only; elsewhere a no-op). A
    signal that lands while this runs raises KeyboardInterrupt at most once per signal
    received; it is swallowed and the handlers are set again."""
    if not _in_main_thread():
        return
    while True:
        try:
            for sig in STOP_SIGNALS:
                signal.signal(sig, signal.SIG_IGN)
            return
        except KeyboardInterrupt:
            continue


@contextmanager
def stop_signals_deferred():
    """SIGINT / SIGTERM that land inside the block are delivered when it ends, to the
    handler in force before it (a clean stop stays a clean stop: KeyboardInterrupt from the
    command's handler, the trainer's stop between steps, ...). For imports of C extensions:
    a KeyboardInterrupt raised while one initialises can come out as an ImportError
    (onnxruntime's does: ImportError('import numpy failed')), and the stop would be lost
    and the package taken for missing. Main thread only; elsewhere the block runs as is."""
    if not _in_main_thread():
        yield
        return
    got = []
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    previous = {s: h for s, h in previous.items() if h is not None}   # not set from Python

    def defer(signum, frame):
        got.append(signum)

    for sig in previous:
        signal.signal(sig, defer)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if got:
            handler = previous[got[0]]
            if callable(handler):
                handler(got[0], None)
            elif handler == signal.SIG_DFL:
                os.kill(os.getpid(), got[0])          # its default action, as it came
