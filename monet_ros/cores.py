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
