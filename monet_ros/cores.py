"""The CPU cores this process may use, shared out between workers running at once: one
rule for `monet process --jobs` (threads per job) and `monet pipeline`'s detector
processes (threads per process); the CPU's name, which every benchmark figure states; and
the memory available, which a command checks before an allocation it can size."""
import os
import platform


def usable_cores():
    """CPU cores this process may run on: its affinity mask (a container's or taskset's
    limit), not the machine's count."""
    return len(os.sched_getaffinity(0))


def cpu_model(cpuinfo='/proc/cpuinfo'):
    """The CPU's model name ('model name' of /proc/cpuinfo; platform.processor() or
    platform.machine() where there is none, e.g. not Linux)."""
    try:
        with open(cpuinfo) as f:
            for line in f:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or 'unknown CPU'


def available_memory(meminfo='/proc/meminfo'):
    """Bytes of memory available to start new work without swapping (MemAvailable of
    /proc/meminfo: free memory plus what the kernel can reclaim), or None where it is not
    known (not Linux)."""
    try:
        with open(meminfo) as f:
            for line in f:
                if line.startswith('MemAvailable:'):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def threads_each(workers, cores=None):
    """Threads per worker when `workers` run at once on `cores` (default usable_cores()):
    the cores shared out, at least 1 each. More threads than cores oversubscribe them:
    2 detector processes x 2 threads on 2 cores were slower than 1 thread each
    (bench/results/pipeline.md)."""
    cores = usable_cores() if cores is None else cores
    return max(1, cores // max(1, workers))


def view_threads(threads=0, cores=None):
    """Threads for the per-view work of one instant (ViewThreads: JPEG decodes, crops):
    `threads` when given (> 0), else the cores this process may use (usable_cores()). That
    work runs before the network's forward pass, never beside it, so it may use the cores
    the network uses: a detector's `threads` (shared out between detector processes by
    threads_each) bounds both."""
    if threads > 0:
        return int(threads)
    return max(1, usable_cores() if cores is None else int(cores))


class ViewThreads:
    """Run the per-view work of one instant on view_threads(threads) threads: OpenCV's
    decode, resize and warp release the GIL, so V views on T threads take about V / T
    views' time, each computed by the same calls as sequentially (bit-identical).

    The views are dealt out round-robin, one task per thread, the caller's thread taking
    the first share: a batch costs T - 1 hand-overs, not V. 1 thread: no pool at all. The
    pool's threads start on first use and end with close() or when it is garbage."""

    def __init__(self, threads=0):
        self.threads = view_threads(threads)
        self._pool = None

    def run(self, work, n):
        """work(i) for i in range(n); returns when every thread's share is done. An exception
        ends its thread's share and is re-raised here once the others are done (a caller
        that must not lose the other views catches its own, as io.jpeg_scale.decode_views)."""
        workers = min(self.threads, n)
        if workers <= 1:
            for i in range(n):
                work(i)
            return
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor
            self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix='monet-views')

        def share(first):
            for i in range(first, n, workers):
                work(i)
        futures = [self._pool.submit(share, k) for k in range(1, workers)]
        try:
            share(0)
        finally:
            for future in futures:
                future.exception()              # wait for every share, even after an error
        for future in futures:
            future.result()

    def close(self):
        """Stop the threads (a later run starts them again)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
