"""Stamp synchroniser: exact and slop matching, partial groups on timeout, order, late items."""
from hypothesis import given, settings
from hypothesis import strategies as st
import pytest

from monet_ros.sync import StampSynchronizer, newest_common_instant


class FakeClock:
    """A hand-advanced monotonic clock (time is an input of the synchroniser)."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def test_exact_match_releases_complete_groups_in_order():
    sync = StampSynchronizer(['a', 'b', 'c'], clock=FakeClock())
    assert sync.add('a', 100, 'a1') == []
    assert sync.add('b', 200, 'b2') == []
    assert sync.add('b', 100, 'b1') == []
    [group] = sync.add('c', 100, 'c1')
    assert group.stamp_ns == 100 and group.items == {'a': 'a1', 'b': 'b1', 'c': 'c1'}
    assert group.missing == ()
    # 200 is still open; 'a' repeating stamp 100 is a repeat (dropped, counted).
    assert sync.add('a', 100, 'again') == [] and sync.stats.repeated_by_key == {'a': 1}
    assert [len(p.items) for p in sync.pending] == [1]


def test_slop_matches_nearest_and_rejects_beyond():
    sync = StampSynchronizer(['a', 'b'], slop_ns=5, clock=FakeClock())
    sync.add('a', 1000, 'a0')
    sync.add('a', 1020, 'a1')
    [group] = sync.add('b', 1018, 'b1')     # nearest within 5 ns: 1020, releasing 1000 too
    assert group.stamp_ns == 1020 and group.items == {'a': 'a1', 'b': 'b1'}
    assert sync.stats.dropped == 1         # the 1000 group had 1 of 2 keys (min_keys = all)
    sync.add('a', 2000, 'a2')
    assert sync.add('b', 2006, 'b2') == []  # 6 ns apart > slop: a new group; b moved past
    assert [g.stamp_ns for g in sync.pending] == [2006]   # 2000 + slop: 2000 lost its b view
    assert sync.stats.dropped == 2


def test_timeout_releases_partial_group_when_a_key_is_silent():
    clock = FakeClock()
    sync = StampSynchronizer(['a', 'b', 'c'], timeout_s=0.2, min_keys=2, clock=clock)
    sync.add('a', 10, 'a')
    sync.add('b', 10, 'b')
    assert sync.poll() == []
    clock.now = 0.25
    [group] = sync.poll()
    assert group.missing == ('c',) and set(group.items) == {'a', 'b'}
    assert sync.stats.partial == 1
    # A lone item times out and is dropped (fewer than min_keys).
    sync.add('a', 20, 'a')
    clock.now = 1.0
    assert sync.poll() == [] and sync.stats.dropped == 1


def test_pending_is_bounded():
    sync = StampSynchronizer(['a', 'b'], max_pending=3, clock=FakeClock())
    for stamp in range(10):
        sync.add('a', stamp, stamp)
    assert len(sync.pending) == 3 and sync.stats.dropped == 7
    sync.add('z', 1, 1)
    assert sync.stats.unknown_key == 1


def test_expected_subset_completes_without_waiting_for_a_silent_key():
    sync = StampSynchronizer(['a', 'b', 'c'], min_keys=2, timeout_s=10, clock=FakeClock())
    sync.set_expected(['a', 'b'])
    sync.add('a', 5, 'a')
    [group] = sync.add('b', 5, 'b')
    assert group.missing == ('c',) and sync.stats.partial == 1
    sync.set_expected([])                   # back to all keys
    sync.add('a', 6, 'a')
    assert sync.add('b', 6, 'b') == []


def test_time_jumping_back_restarts_instead_of_dropping_everything():
    sync = StampSynchronizer(['a', 'b'], clock=FakeClock(), reset_after_ns=1000)
    sync.add('a', 5000, 1)
    assert len(sync.add('b', 5000, 1)) == 1
    # 500 ns back: an older instant (not late), but b already moved past it: dropped
    assert sync.add('a', 4500, 2) == [] and sync.stats.late == 0 and sync.stats.dropped == 1
    sync.add('a', 100, 3)                                           # 4900 ns back: a reset
    [group] = sync.add('b', 100, 3)
    assert group.stamp_ns == 100 and sync.stats.resets == 1


def test_every_item_is_counted_once_per_key():
    """released + dropped + late + repeated + open = added, per key (the fusion node's
    per-camera outcomes)."""
    clock = FakeClock()
    sync = StampSynchronizer(['a', 'b', 'c'], timeout_s=0.2, min_keys=2, clock=clock)
    released = []
    for key, stamp in [('a', 10), ('b', 10), ('a', 10), ('c', 20), ('a', 30)]:
        released += sync.add(key, stamp, stamp)
    clock.now = 0.3
    released += sync.poll()                 # 10 (a, b) released; 20 (c alone) dropped
    released += sync.add('b', 10, 10)       # b repeats its 10
    released += sync.add('c', 10, 10)       # c's 10 comes after 10 was released: late
    released += sync.add('b', 40, 40)       # opens 40, which waits
    counts = {k: sum(k in g.items for g in released) for k in 'abc'}
    assert counts == {'a': 1, 'b': 1, 'c': 0}
    assert sync.stats.repeated_by_key == {'a': 1, 'b': 1}
    assert sync.stats.late_by_key == {'c': 1}
    assert sync.stats.dropped_by_key == {'c': 1, 'a': 1}   # 20 (c) and 30 (a) timed out
    assert {k: sync.open_items(k) for k in 'abc'} == {'a': 0, 'b': 1, 'c': 0}


# ------------------------------------------------------------- newest_common_instant
def brute_force_instant(stamps, slop):
    """The rule written out: every candidate stamp, newest first; each stream's last item
    within slop."""
    for t in sorted({s for stream in stamps for s in stream}, reverse=True):
        near = [[k for k, s in enumerate(stream) if abs(s - t) <= slop] for stream in stamps]
        if all(near):
            return [ks[-1] for ks in near]
    return None


def test_newest_common_instant_cases():
    # one camera a frame ahead: the instant both have, not the newest frame of each
    assert newest_common_instant([[100, 133], [100]]) == [0, 0]
    assert newest_common_instant([[100, 133], [100, 133]]) == [1, 1]
    assert newest_common_instant([[100], [133]]) is None          # never mixed
    assert newest_common_instant([[100], [103]], slop_ns=3) == [0, 0]
    assert newest_common_instant([[100], [104]], slop_ns=3) is None
    assert newest_common_instant([[100], []]) is None             # a camera without a frame
    assert newest_common_instant([]) is None
    assert newest_common_instant([[0, 0, 0], [0]]) == [2, 0]      # repeats: the newest arrival
    assert newest_common_instant([[200, 100], [100, 200]]) == [0, 1]   # arrival order free
    big = 1_700_000_000_123_456_789                                # ns stay exact (int64)
    assert newest_common_instant([[big, big + 1], [big + 1]]) == [1, 0]
    with pytest.raises(ValueError, match='slop_ns'):
        newest_common_instant([[1]], slop_ns=-1)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.lists(st.integers(0, 40), max_size=4), min_size=1, max_size=5),
       st.integers(0, 6))
def test_newest_common_instant_equals_the_rule_written_out(stamps, slop):
    assert newest_common_instant(stamps, slop) == brute_force_instant(stamps, slop)
