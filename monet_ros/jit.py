"""Compiled kernels (numba) for the per-frame hot paths whose numpy form is mostly the fixed
cost of many small array calls: a frame of the several-subject path holds a few hundred
points, where each numpy call costs 1-5 us whatever its size (bench/subjects.py).

`kernel(fn)` compiles fn with numba.njit on its first call: numba is imported then, so a
command that never calls a kernel does not pay its import. A process's first kernel call
takes ~0.7 s with the machine code cached (numba's import and start), ~2-5 s on a machine
that has not compiled it yet (measured on a 2-core EPYC); later calls cost ~2 us plus the
work. Array arguments are passed C-contiguous and writable (a copy where they are not),
so each kernel compiles once per dtype, not once per memory layout. Settings, the same
for every kernel: cache=True (the machine code is kept in the source's __pycache__, or in
numba's user cache where that is not writable, keyed by the CPU: a later process loads it
instead of compiling), nogil (a live node's other threads run beside it) and IEEE
arithmetic (no fastmath: the numbers of the loops as written, to rounding). A kernel is
plain Python over numpy arrays: NUMBA_DISABLE_JIT=1 runs it uncompiled (slow; for
debugging).
"""
import functools
import threading
import warnings

import numpy as np

_LOCK = threading.Lock()


def kernel(fn):
    """fn compiled by numba.njit(cache=True, nogil=True) on its first call (the module
    docstring); the uncompiled function stays at .py_func, numba's dispatcher is at
    .dispatcher once compiled."""
    compiled = None

    @functools.wraps(fn)
    def call(*args):
        nonlocal compiled
        if compiled is None:
            with _LOCK:  # one compilation when threads call it first at once
                if compiled is None:
                    compiled = call.dispatcher = _compile(fn)
        return compiled(*map(_plain, args))

    call.py_func = fn
    call.dispatcher = None        # numba's dispatcher once compiled (its .signatures)
    return call


def _compile(fn):
    """numba.njit(cache=True, nogil=True)(fn); without the cache (compiled again in every
    process, and said once) where numba finds no writable place for it."""
    import numba
    try:
        return numba.njit(cache=True, nogil=True)(fn)
    except RuntimeError as error:  # numba: 'cannot cache function ...: no locator available'
        warnings.warn(f'monet_ros.jit: {fn.__qualname__} compiled without a cache ({error}); '
                      'set NUMBA_CACHE_DIR to a writable folder to keep it', RuntimeWarning,
                      stacklevel=3)
        return numba.njit(nogil=True)(fn)


def _plain(arg):
    """An array argument as a C-contiguous, writable array (numba types read-only and
    strided arrays apart: each would be another compilation); others unchanged."""
    if isinstance(arg, np.ndarray) and not (arg.flags.c_contiguous and arg.flags.writeable):
        return np.array(arg, order='C')
    return arg
