"""Compiled kernels (numba) for the per-frame hot paths whose numpy form is mostly the fixed
cost of many small array calls: a frame of the several-subject path holds a few hundred
points, where each numpy call costs 1-5 us whatever its size (bench/subjects.py).

`kernel(fn)` compiles fn with numba.njit on its first call: numba is imported then, so a
command that never calls a kernel does not pay its import (~0.3 s). Settings, the same
for every kernel: cache=True (the machine code is kept in the source's __pycache__, or in
numba's user cache where that is not writable, keyed by the CPU: a later process loads it
instead of compiling), nogil (a live node's other threads run beside it) and IEEE
arithmetic (no fastmath: the numbers of the loops as written, to rounding). A kernel is
plain Python over numpy arrays: NUMBA_DISABLE_JIT=1 runs it uncompiled (slow; for
debugging).
"""
import functools
import threading

_LOCK = threading.Lock()


def kernel(fn):
    """fn compiled by numba.njit(cache=True, nogil=True) on its first call (the module
    docstring); the uncompiled function stays at .py_func."""
    compiled = None

    @functools.wraps(fn)
    def call(*args):
        nonlocal compiled
        if compiled is None:
            with _LOCK:  # one compilation when threads call it first at once
                if compiled is None:
                    import numba
                    compiled = numba.njit(cache=True, nogil=True)(fn)
        return compiled(*args)

    call.py_func = fn
    return call
