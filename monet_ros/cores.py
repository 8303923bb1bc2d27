"""The CPU cores this process may use, shared out between workers running at once: one
rule for `monet process --jobs` (threads per job) and `monet pipeline`'s detector
processes (threads per process)."""
import os


def usable_cores():
    """CPU cores this process may run on: its affinity mask (a container's or taskset's
    limit), not the machine's count."""
    return len(os.sched_getaffinity(0))


def threads_each(workers, cores=None):
    """Threads per worker when `workers` run at once on `cores` (default usable_cores()):
    the cores shared out, at least 1 each. More threads than cores oversubscribe them:
    2 detector processes x 2 threads on 2 cores were slower than 1 thread each
    (bench/results/pipeline.md)."""
    cores = usable_cores() if cores is None else cores
    return max(1, cores // max(1, workers))


def decode_threads(threads=0, cores=None):
    """Threads decoding the views of one instant (io.jpeg_scale.CropDecoder): `threads`
    when given (> 0), else the cores this process may use (usable_cores()). The decode runs
    before the network's forward pass, never beside it, so it may use the cores the network
    uses: a detector's `threads` (shared out between detector processes by threads_each)
    bounds both."""
    if threads > 0:
        return int(threads)
    return max(1, usable_cores() if cores is None else int(cores))
