"""Thin rclpy nodes: detector, fusion, learner, player.

When this package is imported because a node executable is starting
(`python -m monet_ros.nodes.<node>` or the `detector` / `fusion` / `learner` / `player`
console scripts), SIGINT and SIGTERM are made to exit 0 at once: a node stopped while it
still imports torch or rclpy has nothing to clean up, and must not print a
KeyboardInterrupt traceback or die with -15. run_node replaces these handlers with the
clean-shutdown ones before rclpy starts (see monet_ros.nodes.runner).
"""
import os
import signal
import sys

NODE_EXECUTABLES = ('detector', 'fusion', 'learner', 'player')


def launched_as_node(argv=None):
    """True when the process is a node executable starting up (see the module doc)."""
    argv = list(getattr(sys, 'orig_argv', sys.argv) if argv is None else argv)
    if '-m' in argv[:-1]:
        module = argv[argv.index('-m') + 1]
        return module in {f'monet_ros.nodes.{name}' for name in NODE_EXECUTABLES}
    return bool(sys.argv) and os.path.basename(sys.argv[0]) in NODE_EXECUTABLES


def _exit_now(signum, frame):
    os._exit(0)


def install_early_stop():
    """SIGINT / SIGTERM -> exit 0 immediately (only while nothing needs cleaning up)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _exit_now)


if launched_as_node():
    install_early_stop()
