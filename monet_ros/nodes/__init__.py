"""Thin rclpy nodes: detector, fusion, learner, player.

When this package is imported because a node executable is starting
(`python -m monet_ros.nodes.<node>` or the `detector` / `fusion` / `learner` / `player`
console scripts), SIGINT and SIGTERM are made to exit 0 at once: a node stopped while it
still imports torch or rclpy has nothing to clean up, and must not print a
KeyboardInterrupt traceback or die with -15 (monet_ros.stop_signals.exit_0_on_stop, the
same as the `monet` executable's, monet_ros.entry). run_node replaces these handlers with the
clean-shutdown ones before rclpy starts (see monet_ros.nodes.runner). Left open: the
interpreter's start-up before this package runs (see monet_ros.entry).
A node executable's OpenMP (torch) threads wait passively (passive_openmp; `monet pipeline`
does the same): by default a process with as many torch threads as cores spins them between
operations, and once another process wants a core the spinning stalls every forward pass
(the detector's batch on 2 cores beside busy processes: 530 ms spinning, 25 ms passive,
23 ms with one thread). Live nodes always share the machine with other processes. ONNX
Runtime's threads (backend onnxruntime, precision int8) follow the same policy
(models.onnx_backend.spinning).
Large message buffers come from the heap (heap_for_large_buffers; `monet pipeline` too): by
default glibc maps an allocation over 128 KB (one 640x480 rgb8 frame is 900 KB, one
heatmap message 230 KB) fresh from the kernel or gives freed heap back to it (its
thresholds adapt, but not to a node's traffic), so a message can cost all its pages'
faults: a subscriber took 2.2 ms of CPU per received frame, most of it in the kernel,
against 1.0 ms with the buffers reused (bench/pipeline.py --receive).
In `monet pipeline` the player's thread and the fusion node's callbacks share one
interpreter: a thread coming back from a blocking call (a publish, a wait, a read) waits for
the GIL until the running thread's switch interval ends, 5 ms by default, every time. The
command sets 1 ms (short_gil_switch): at 4 cameras @ 60 Hz its median latency went from
119-137 to 49-61 ms and p95 from 436-492 to 135-185 ms, throughput unchanged
(bench/pipeline.py, pipeline layout).
A node started by a command as its child (monet_ros.nodes.child, with MONET_PARENT_PID in
its environment) is killed (SIGKILL) when that command dies, so it is never left behind: with
the command gone there is nothing to stop cleanly, and a clean stop could wait forever on the
dead process (e.g. a shared-memory transport lock it held; a SIGTERM'd child outlived its
killed command by over a minute, once in a full test run).
"""
import os
import signal
import sys

from monet_ros.stop_signals import exit_0_on_stop

NODE_EXECUTABLES = ('detector', 'fusion', 'learner', 'player')


def launched_as_node(argv=None):
    """True when the process is a node executable starting up (see the module doc)."""
    argv = list(getattr(sys, 'orig_argv', sys.argv) if argv is None else argv)
    if '-m' in argv[:-1]:
        module = argv[argv.index('-m') + 1]
        return module in {f'monet_ros.nodes.{name}' for name in NODE_EXECUTABLES}
    return bool(sys.argv) and os.path.basename(sys.argv[0]) in NODE_EXECUTABLES


def passive_openmp():
    """OMP_WAIT_POLICY=PASSIVE unless the user set it (see the module doc); effective only
    before torch is imported (OpenMP reads it when it loads)."""
    os.environ.setdefault('OMP_WAIT_POLICY', 'PASSIVE')


# glibc mallopt(3) parameters (malloc.h): M_TRIM_THRESHOLD, M_MMAP_THRESHOLD
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 * 1024 * 1024     # glibc's largest (DEFAULT_MMAP_THRESHOLD_MAX, 64-bit)
_TRIM_THRESHOLD = 128 * 1024 * 1024    # free memory kept before it is given back


def heap_for_large_buffers():
    """Serve allocations up to 32 MB from the heap and keep up to 128 MB of freed memory
    for reuse (glibc mallopt; see the module doc). True when applied; False where the C
    library has no mallopt (not glibc) or refuses. Respects MALLOC_MMAP_THRESHOLD_ /
    MALLOC_TRIM_THRESHOLD_ when the user set them."""
    if 'MALLOC_MMAP_THRESHOLD_' in os.environ or 'MALLOC_TRIM_THRESHOLD_' in os.environ:
        return False
    try:
        import ctypes
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and \
        bool(mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))


GIL_SWITCH_S = 0.001


def short_gil_switch(interval_s=GIL_SWITCH_S):
    """sys.setswitchinterval(interval_s) unless the interval is already shorter (see the
    module doc); returns the interval in force (s)."""
    if sys.getswitchinterval() > interval_s:
        sys.setswitchinterval(interval_s)
    return sys.getswitchinterval()


PARENT_PID = 'MONET_PARENT_PID'
_PR_SET_PDEATHSIG = 1


def die_with_parent(environ=None):
    """With MONET_PARENT_PID set: SIGKILL to this process when its parent dies (Linux
    prctl PR_SET_PDEATHSIG; see the module doc), and exit 0 now if that parent is already
    gone. The parent's own stop() still ends the child with SIGTERM, cleanly."""
    parent = (os.environ if environ is None else environ).get(PARENT_PID)
    if not parent:
        return
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):      # not Linux: the parent's stop() still ends it
        pass
    if os.getppid() != int(parent):
        os._exit(0)


if launched_as_node():
    exit_0_on_stop()
    passive_openmp()
    heap_for_large_buffers()
    die_with_parent()
