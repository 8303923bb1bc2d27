"""Group messages of several streams by stamp: ONE rule for the fusion node and for the
offline readers (monet_ros.io.multiview.iter_multiview_frames: `monet process`, `monet train`).

Pure Python (no rclpy; message_filters is not in the pip wheels). The rule:

- An item joins the open group whose stamp is nearest to its own within `slop_ns` (exact
  when 0) and that has no item of its key yet; otherwise it opens a new group. So two items
  of one stream never merge into one instant, whatever their stamps.
- A stream that repeats a stamp it already gave (a driver that leaves every stamp at 0,
  or re-sends a frame) is detected: the repeat is dropped and counted per key
  (`stats.repeated_by_key`), never merged into another instant's group.
- Groups are released in stamp order, oldest first, when complete (every expected key and
  at least `min_keys`),
  or when every missing key's stream has moved past the group's stamp by more than
  `slop_ns + reorder_ns` (its view was lost), or `timeout_s` after the group's first item
  arrived, or when more than `max_pending` groups are open (bounded memory).
  Arrival order therefore does not matter within the reorder window: items logged out of
  order, or streams whose stamps run backwards, group exactly as in-order ones.
- An item of an instant already released (within slop of a recently released stamp) is
  late and counted. A stamp more than `reset_after_ns` before the last released one means
  time jumped back (a restarted source): open groups are released and history forgotten.
- Released groups with fewer than `min_keys` items are dropped and counted.

Every item added ends in exactly one place, counted per key: a released group, a dropped
group (`stats.dropped_by_key`), late (`late_by_key`), repeated (`repeated_by_key`), or an
open group (`open_items`).

`newest_common_instant` is the same idea for a consumer that runs behind its streams (the
detector's batch): of the few items each stream has pending, the newest instant that every
stream has, with the same tolerance (stamps within `slop_ns` of one another are one instant).
"""
from collections import Counter, deque
from dataclasses import dataclass, field
import math
import time

import numpy as np


def newest_common_instant(stamps, slop_ns=0):
    """Which pending item of each stream to take so that all are one instant, the newest one.

    stamps: sequence (V streams) of sequences of int stamps (ns) of each stream's pending
    items in arrival order (any stamps: repeats, backwards). An instant is a stamp T of one
    of the items such that every stream has an item within slop_ns of T (0 = the exact
    stamp); the newest such T wins. Returns V indices into the streams' sequences (per
    stream its newest-arriving item within slop_ns of T), or None when no instant is common
    to every stream (a stream has no item, or their stamps never meet).
    Raises ValueError when slop_ns < 0.
    """
    if slop_ns < 0:
        raise ValueError(f'slop_ns must be >= 0, got {slop_ns}')
    if not stamps or not all(len(s) for s in stamps):
        return None
    depth = max(len(s) for s in stamps)
    # (V, K) stamps padded with the stream's first stamp; `valid` masks the padding
    table = np.array([list(s) + [s[0]] * (depth - len(s)) for s in stamps], dtype=np.int64)
    valid = np.arange(depth)[None, :] < np.array([len(s) for s in stamps])[:, None]
    candidates = np.unique(table[valid])[::-1]                        # newest first
    # (T, V, K): item k of stream v is within slop of candidate t (int64: ns stay exact)
    near = (np.abs(table[None] - candidates[:, None, None]) <= slop_ns) & valid[None]
    common = near.any(axis=2).all(axis=1)
    if not common.any():
        return None
    first = int(np.argmax(common))                                    # the newest common T
    # the newest-arriving near item of each stream: last True along K
    return (depth - 1 - np.argmax(near[first][:, ::-1], axis=1)).tolist()


@dataclass
class Group:
    """Items of one stamp: `items` key -> item, `missing` keys without an item."""
    stamp_ns: int
    items: dict
    missing: tuple = ()
    first_arrival: float = field(default=0.0, repr=False)


@dataclass
class SyncStats:
    complete: int = 0
    partial: int = 0
    dropped: int = 0        # groups released with fewer than min_keys items
    late: int = 0           # items of an instant already released
    repeated: int = 0       # items whose key already gave that exact stamp (dropped)
    unknown_key: int = 0
    resets: int = 0         # time jumped back (e.g. a restarted source)
    repeated_by_key: Counter = field(default_factory=Counter)
    late_by_key: Counter = field(default_factory=Counter)
    dropped_by_key: Counter = field(default_factory=Counter)   # items of dropped groups


class StampSynchronizer:
    """Match items of `keys` by stamp; `add`, `poll` and `flush` return the groups ready,
    oldest first (see the module docstring for the rule).

    keys: stream names (e.g. camera names); slop_ns: stamp tolerance (0 = exact);
    timeout_s: how long to wait for the missing keys of a group after its first item
    (math.inf = never: offline, where the streams' positions decide); min_keys: fewest keys
    a released group must have (default: all); max_pending: bound on open groups;
    clock: monotonic seconds (injectable for tests); reset_after_ns: see the module
    docstring; reorder_ns: how far (in stamp time) a stream may run out of order before a
    view it has not delivered counts as lost (0 for live streams, which arrive in order);
    history: stamps remembered per key (repeat detection) and released stamps (late items).
    Raises ValueError for bad arguments.
    """

    def __init__(self, keys, slop_ns=0, timeout_s=0.5, min_keys=None, max_pending=30,
                 clock=time.monotonic, reset_after_ns=1_000_000_000, reorder_ns=0,
                 history=64):
        self.keys = tuple(keys)
        if not self.keys or len(set(self.keys)) != len(self.keys):
            raise ValueError(f'keys must be unique and non-empty, got {list(keys)}')
        if not (slop_ns >= 0 and timeout_s >= 0 and reorder_ns >= 0 and max_pending >= 1
                and history >= 1):
            raise ValueError('slop_ns, timeout_s and reorder_ns must be >= 0, max_pending '
                             'and history >= 1')
        self.slop_ns = int(slop_ns)
        self.timeout_s = float(timeout_s)
        self.min_keys = len(self.keys) if min_keys is None else int(min_keys)
        if not 1 <= self.min_keys <= len(self.keys):
            raise ValueError(f'min_keys must be in 1..{len(self.keys)}, got {min_keys}')
        self.max_pending = int(max_pending)
        self.clock = clock
        self.reset_after_ns = int(reset_after_ns)
        self.reorder_ns = int(reorder_ns)
        self.history = int(history)
        self.expected = set(self.keys)  # keys a group needs to be complete (see set_expected)
        self.pending = []          # open groups sorted by stamp
        self.last_released = None  # stamp of the most recently released group
        self.stats = SyncStats()
        self._forget()

    def _forget(self):
        self.position = {}                                        # key -> latest stamp
        self.recent = {k: deque(maxlen=self.history) for k in self.keys}
        self.released = deque(maxlen=self.history)

    def _find(self, key, stamp_ns):
        """The open group without `key` nearest to this stamp within slop, or None."""
        best, best_gap = None, None
        for group in self.pending:
            gap = abs(group.stamp_ns - stamp_ns)
            if gap <= self.slop_ns and key not in group.items and (
                    best_gap is None or gap < best_gap):
                best, best_gap = group, gap
        return best

    def add(self, key, stamp_ns, item):
        """Add one item; returns the list of groups released by it (possibly empty)."""
        if key not in self.keys:
            self.stats.unknown_key += 1
            return []
        stamp_ns = int(stamp_ns)
        released = []
        if (self.last_released is not None
                and self.last_released - stamp_ns > self.reset_after_ns):
            released = self.flush()                    # time jumped back: start afresh
            self.last_released = None
            self._forget()
            self.stats.resets += 1
        if stamp_ns in self.recent[key]:
            self.stats.repeated += 1
            self.stats.repeated_by_key[key] += 1
            return released + self._ready()
        self.recent[key].append(stamp_ns)
        self.position[key] = stamp_ns
        group = self._find(key, stamp_ns)
        if group is None:
            if any(abs(s - stamp_ns) <= self.slop_ns for s in self.released):
                self.stats.late += 1
                self.stats.late_by_key[key] += 1
                return released + self._ready()
            group = Group(stamp_ns, {}, first_arrival=self.clock())
            index = len(self.pending)
            while index > 0 and self.pending[index - 1].stamp_ns > stamp_ns:
                index -= 1
            self.pending.insert(index, group)
        group.items[key] = item
        return released + self._ready()

    def set_expected(self, keys):
        """Complete groups need only these keys from now on (e.g. drop a silent camera so
        that the others are not held back by the timeout); all keys when `keys` is empty."""
        keys = set(keys) & set(self.keys)
        self.expected = keys or set(self.keys)

    def _passed(self, group):
        """Every expected key missing from `group` has moved past it (its view is lost)."""
        limit = group.stamp_ns + self.slop_ns + self.reorder_ns
        for key in self.expected:
            if key not in group.items:
                position = self.position.get(key)
                if position is None or position <= limit:
                    return False
        return True

    def _ready(self):
        now = self.clock()
        released = []
        while self.pending:
            head = self.pending[0]
            # complete: every expected key (and at least min_keys: right after start, the
            # expected set may hold only the first streams heard from)
            complete = (self.expected.issubset(head.items)
                        and len(head.items) >= self.min_keys)
            if (complete or self._passed(head)
                    or len(self.pending) > self.max_pending
                    or (math.isfinite(self.timeout_s)
                        and now - head.first_arrival >= self.timeout_s)):
                released.extend(self._release(self.pending.pop(0)))
            else:
                break
        return released

    def open_items(self, key):
        """How many items of `key` wait in open groups."""
        return sum(key in group.items for group in self.pending)

    def poll(self):
        """Release the groups that are ready (timeouts expire with the clock)."""
        return self._ready()

    def flush(self):
        """Release every open group (end of a stream), oldest first."""
        released = []
        while self.pending:
            released.extend(self._release(self.pending.pop(0)))
        return released

    def _release(self, group):
        self.last_released = group.stamp_ns
        self.released.append(group.stamp_ns)
        group.missing = tuple(k for k in self.keys if k not in group.items)
        if len(group.items) < self.min_keys:
            self.stats.dropped += 1
            self.stats.dropped_by_key.update(group.items.keys())
            return []
        if group.missing:
            self.stats.partial += 1
        else:
            self.stats.complete += 1
        return [group]
