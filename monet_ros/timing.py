"""Cheap per-stage wall-time accumulators (time.perf_counter) for the live nodes' profiles.

A node times each stage of its hot path with `with timer('forward'):` (about 1 us of
overhead) and reports `timer.summary()` in /diagnostics; bench/pipeline.py reads those
figures to print where the time of a frame goes.
"""
from contextlib import contextmanager, nullcontext
import time


class StageTimer:
    """Totals and counts of named stages. Not thread-safe (one per executor thread)."""

    def __init__(self):
        self.totals = {}
        self.counts = {}

    def add(self, stage, seconds, count=1):
        """Account `seconds` (wall) to `stage`, as `count` calls."""
        self.totals[stage] = self.totals.get(stage, 0.0) + seconds
        self.counts[stage] = self.counts.get(stage, 0) + count

    @contextmanager
    def __call__(self, stage):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.add(stage, time.perf_counter() - start)

    def summary(self):
        """{'<stage>_ms_mean': mean milliseconds per call, '<stage>_calls': calls} for every
        stage timed so far (insertion order)."""
        out = {}
        for stage, total in self.totals.items():
            calls = self.counts[stage]
            out[f'{stage}_ms_mean'] = f'{1e3 * total / max(calls, 1):.3f}'
            out[f'{stage}_calls'] = str(calls)
        return out


class _NoTimer:
    """A StageTimer stand-in that times nothing (the default of optional `timer` args)."""

    def __call__(self, stage):
        return nullcontext()

    def add(self, stage, seconds, count=1):
        pass


NO_TIMER = _NoTimer()
