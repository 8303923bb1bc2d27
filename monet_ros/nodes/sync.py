"""Group messages of several streams by stamp (message_filters is not in the pip wheels).

Pure Python (no rclpy), so the fusion node and its tests share one implementation.
A group completes when every key has an item whose stamp matches (exactly, or within
`slop_ns` of the group's first stamp). A group still incomplete `timeout_s` after its first
item arrived is released with what it has if at least `min_keys` keys are present (a silent
camera -> fewer views), else dropped. Groups are released in stamp order; an item older
than the last released stamp is late and dropped.
"""
from dataclasses import dataclass, field
import time


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
    late: int = 0           # items older than the last released group
    duplicate: int = 0      # second item of one key for one stamp
    unknown_key: int = 0
    resets: int = 0         # time jumped back (e.g. a looped recording)


class StampSynchronizer:
    """Match items of `keys` by stamp; `add` and `poll` return the groups ready, oldest first.

    keys: stream names (e.g. camera names); slop_ns: stamp tolerance (0 = exact);
    timeout_s: how long to wait for the missing keys of a group after its first item;
    min_keys: fewest keys a partial group must have to be released (default: all);
    max_pending: bound on open groups (the oldest is released/dropped beyond it);
    clock: monotonic seconds (injectable for tests); reset_after_ns: a stamp this much older
    than the last released group means time jumped back (a looped recording, a restarted
    source): the synchroniser starts afresh instead of calling everything late.
    """

    def __init__(self, keys, slop_ns=0, timeout_s=0.5, min_keys=None, max_pending=30,
                 clock=time.monotonic, reset_after_ns=1_000_000_000):
        self.keys = tuple(keys)
        if not self.keys or len(set(self.keys)) != len(self.keys):
            raise ValueError(f'keys must be unique and non-empty, got {list(keys)}')
        if slop_ns < 0 or timeout_s < 0 or max_pending < 1:
            raise ValueError('slop_ns and timeout_s must be >= 0, max_pending >= 1')
        self.slop_ns = int(slop_ns)
        self.timeout_s = float(timeout_s)
        self.min_keys = len(self.keys) if min_keys is None else int(min_keys)
        if not 1 <= self.min_keys <= len(self.keys):
            raise ValueError(f'min_keys must be in 1..{len(self.keys)}, got {min_keys}')
        self.max_pending = int(max_pending)
        self.clock = clock
        self.reset_after_ns = int(reset_after_ns)
        self.expected = set(self.keys)  # keys a group needs to be complete (see set_expected)
        self.pending = []          # open groups sorted by stamp
        self.last_released = None  # stamp of the newest released group
        self.stats = SyncStats()

    def _find(self, stamp_ns):
        """The open group this stamp belongs to (nearest within slop), or None."""
        best, best_gap = None, None
        for group in self.pending:
            gap = abs(group.stamp_ns - stamp_ns)
            if gap <= self.slop_ns and (best_gap is None or gap < best_gap):
                best, best_gap = group, gap
        return best

    def add(self, key, stamp_ns, item):
        """Add one item; returns the list of groups released by it (possibly empty)."""
        if key not in self.keys:
            self.stats.unknown_key += 1
            return []
        stamp_ns = int(stamp_ns)
        if self.last_released is not None and stamp_ns <= self.last_released:
            if self.last_released - stamp_ns < self.reset_after_ns:
                self.stats.late += 1
                return []
            self.pending, self.last_released = [], None     # time jumped back
            self.stats.resets += 1
        group = self._find(stamp_ns)
        if group is None:
            group = Group(stamp_ns, {}, first_arrival=self.clock())
            self.pending.append(group)
            self.pending.sort(key=lambda g: g.stamp_ns)
        if key in group.items:
            self.stats.duplicate += 1
            group.items[key] = item  # keep the newest
        else:
            group.items[key] = item
        released = []
        if self.expected.issubset(group.items):
            # A complete group releases it and every older open group.
            index = self.pending.index(group)
            for older in self.pending[:index + 1]:
                released.extend(self._release(older))
            del self.pending[:index + 1]
        while len(self.pending) > self.max_pending:
            released.extend(self._release(self.pending.pop(0)))
        return released + self.poll()

    def set_expected(self, keys):
        """Complete groups need only these keys from now on (e.g. drop a silent camera so
        that the others are not held back by the timeout); all keys when `keys` is empty."""
        keys = set(keys) & set(self.keys)
        self.expected = keys or set(self.keys)

    def poll(self):
        """Release the open groups whose timeout expired (and everything older)."""
        now = self.clock()
        expired = [i for i, g in enumerate(self.pending)
                   if now - g.first_arrival >= self.timeout_s]
        if not expired:
            return []
        last = expired[-1]
        released = []
        for group in self.pending[:last + 1]:
            released.extend(self._release(group))
        del self.pending[:last + 1]
        return released

    def _release(self, group):
        self.last_released = max(group.stamp_ns, self.last_released or group.stamp_ns)
        group.missing = tuple(k for k in self.keys if k not in group.items)
        if len(group.items) < self.min_keys:
            self.stats.dropped += 1
            return []
        if group.missing:
            self.stats.partial += 1
        else:
            self.stats.complete += 1
        return [group]
