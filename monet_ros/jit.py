"""Compiled kernels (numba) for the per-frame hot paths whose numpy form is mostly the fixed
cost of many small array calls: a frame of the several-subject path holds a few hundred
points, where each numpy call costs 1-5 us whatever its size (bench/subjects.py).

`kernel(fn)` compiles fn with numba.njit on its first call: numba is imported then, so a
command that never calls a kernel does not pay its import. A process's first kernel call
takes ~0.7 s with the machine code cached (numba's import and start), ~2-5 s on a machine
that has not compiled it yet (measured on a 2-core EPYC); later calls cost ~2 us plus the
work. Array arguments are passed as read-only C-contiguous views (a copy only where they
are not C-contiguous), so each kernel compiles once per dtype, not once per memory layout
or flag, and cannot write to its inputs. Settings, the same
for every kernel: cache=True (the machine code is kept in the source's __pycache__, or in
numba's user cache where that is not writable, keyed by the CPU: a later process loads it
instead of compiling), nogil (a live node's other threads run beside it), numpy's error
model (a division by zero gives inf or NaN as in numpy, never ZeroDivisionError) and IEEE
arithmetic (no fastmath: the numbers of the loops as written, to rounding). numba's cache
is keyed by the kernel's source file, not these settings: after changing them, delete the
*.nbi / *.nbc files of __pycache__. A kernel is
plain Python over numpy arrays: NUMBA_DISABLE_JIT=1 runs it uncompiled (slow; for
debugging).
"""
import functools
import threading
import warnings

import numpy as np

_LOCK = threading.Lock()
_KERNELS = []                    # every kernel, with its example arguments (warm_up)


def kernel(fn=None, *, example=None):
    """fn compiled by numba.njit on its first call (the module docstring's settings); the
    uncompiled function stays at .py_func, numba's dispatcher is at
    .dispatcher once compiled. example: a function returning small arguments of the
    types the callers pass (warm_up compiles with them). As @kernel or
    @kernel(example=...)."""
    if fn is None:
        return functools.partial(kernel, example=example)
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
    call.example = example
    _KERNELS.append(call)
    return call


def warm_up():
    """Compile (or load from the cache) every kernel of the modules imported so far that
    has example arguments, by calling it on them: a live node does this at start so that
    its first frame does not wait for it. -> seconds taken."""
    import time
    start = time.perf_counter()
    for call in list(_KERNELS):
        if call.example is not None:
            call(*call.example())
    return time.perf_counter() - start


def _compile(fn):
    """fn compiled with the module docstring's settings; without the cache (compiled again
    in every process, and said once) where numba finds no writable place for it."""
    import numba
    settings = dict(nogil=True, error_model='numpy')
    try:
        return numba.njit(cache=True, **settings)(fn)
    except RuntimeError as error:  # numba: 'cannot cache function ...: no locator available'
        warnings.warn(f'monet_ros.jit: {fn.__qualname__} compiled without a cache ({error}); '
                      'set NUMBA_CACHE_DIR to a writable folder to keep it', RuntimeWarning,
                      stacklevel=3)
        return numba.njit(**settings)(fn)


def _plain(arg):
    """An array argument as a read-only, C-contiguous array: a read-only view (a copy only
    where it is not C-contiguous), as numba types read-only and strided arrays apart (each
    would be another compilation); kernels write only to the arrays they make. Others
    unchanged."""
    if not isinstance(arg, np.ndarray):
        return arg
    view = arg.view() if arg.flags.c_contiguous else np.ascontiguousarray(arg)
    view.flags.writeable = False
    return view
