"""StageTimer: per-stage totals and counts, reported as mean ms per call."""
import time

from monet_ros.timing import NO_TIMER, StageTimer


def test_stage_timer_means_and_counts():
    timer = StageTimer()
    outer = 0.0
    for _ in range(3):
        start = time.perf_counter()
        with timer('sleep'):
            time.sleep(0.01)
        outer += time.perf_counter() - start
    timer.add('batch', 0.006, count=2)
    summary = timer.summary()
    assert list(summary) == ['sleep_ms_mean', 'sleep_calls', 'batch_ms_mean', 'batch_calls']
    assert summary['sleep_calls'] == '3' and summary['batch_calls'] == '2'
    # the timed interval lies inside the one measured around it, and a sleep lasts at least
    # its time: bounds that hold however loaded the machine is
    assert 10.0 <= float(summary['sleep_ms_mean']) <= 1e3 * outer / 3 + 0.0005
    assert float(summary['batch_ms_mean']) == 3.0


def test_stage_timer_counts_a_stage_that_raised():
    timer = StageTimer()
    try:
        with timer('fails'):
            raise KeyError('x')
    except KeyError:
        pass
    assert timer.summary()['fails_calls'] == '1'
    with NO_TIMER('anything'):
        NO_TIMER.add('anything', 1.0)
