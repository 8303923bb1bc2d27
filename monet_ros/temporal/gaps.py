"""Runs of missing frames per joint: which are bridged (bounded interior gaps) and which
stay empty (no ROS)."""
import numpy as np


def frames_for(seconds, stamps_ns):
    """Whole frames in `seconds` at the median frame period of stamps_ns (T,) (0 when
    fewer than 2 stamps)."""
    stamps = np.asarray(stamps_ns, np.int64)
    if len(stamps) < 2:
        return 0
    period = float(np.median(np.diff(stamps))) / 1e9
    # (tolerance: integer-ns periods, 16666667 ns at 60 Hz, make 0.25 s 14.9999994 frames)
    return int(np.floor(seconds / period * (1 + 1e-6))) if period > 0 else 0


def bridgeable(observed, max_frames):
    """bridged (T, C) bool: the frames not `observed` (T, C bool) that lie in a run of at
    most max_frames missing frames with observed frames on both sides. Missing frames
    before the first / after the last observation and in longer runs are not bridged."""
    observed = np.asarray(observed, bool)
    T = observed.shape[0]
    t = np.arange(T)[:, None]
    last = np.maximum.accumulate(np.where(observed, t, -1), axis=0)        # last seen <= t
    nxt = np.minimum.accumulate(np.where(observed, t, T)[::-1], axis=0)[::-1]  # next >= t
    run = nxt - last - 1                                                   # gap length
    return ~observed & (last >= 0) & (nxt < T) & (run <= max_frames)
