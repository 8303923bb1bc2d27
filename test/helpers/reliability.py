"""Reliability suite: generated bad inputs per entry point, and the class of each outcome.

Every case ends in one of three classes, never a traceback, hang, crash or silent loss:
  'right result'         exit 0 (or a loaded object) checked against what the input holds;
  'clear error'          exit 2 and ONE stderr line that names the file / field / option
                         (or a ValueError subclass whose message names it, for the loaders);
  'skipped and counted'  exit 0 with the skipped views / messages counted in the output.
`outcome(...)` records each case; the counts per entry point are printed at the end of the
run and written to .pytest_cache/monet/reliability_counts.json (the lead reports them).
"""
from collections import Counter, defaultdict
from contextlib import redirect_stderr, redirect_stdout
import io

from hypothesis import HealthCheck, settings

from monet_ros.cli import main

COUNTS = defaultdict(Counter)        # entry point -> outcome class -> cases

# Bounded and reproducible: the same examples every run (CI), no deadline (2 busy cores).
settings.register_profile(
    'reliability', derandomize=True, deadline=None, database=None, print_blob=False,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                           HealthCheck.data_too_large, HealthCheck.filter_too_much])
RELIABILITY = settings.get_profile('reliability')


def record(entry, kind):
    COUNTS[entry][kind] += 1


def run_monet(argv):
    """`monet ARGV` in this process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def assert_clear_error(code, err, names=()):
    """Exit 2, one stderr line saying 'error', naming one of `names`, no traceback."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert 'Traceback' not in err, err
    assert code == 2, f'exit {code}, stderr: {err}'
    assert len(lines) == 1, f'expected one line, got: {err}'
    assert 'error' in lines[0], lines[0]
    if names:
        assert any(str(n) in lines[0] for n in names), f'{lines[0]!r} names none of {names}'


def outcome(entry, argv, names=(), check=None, expect=None):
    """Run `monet ARGV` and assert its class: 'clear error' (exit 2 naming one of `names`)
    or 'right result' / 'skipped and counted' (exit 0; `check(stdout, stderr)` verifies
    the result and returns the class). expect: the class required, or None for either.
    Returns (class, stdout, stderr)."""
    code, out, err = run_monet(argv)
    assert 'Traceback' not in err, err
    assert code in (0, 2), f'monet {argv[0]}: exit {code} (internal error?): {err}'
    if code == 2:
        assert_clear_error(code, err, names)
        kind = 'clear error'
    else:
        kind = check(out, err) if check is not None else 'right result'
    if expect is not None:
        assert kind == expect, f'{kind} instead of {expect}: {out} {err}'
    record(f'monet {argv[0]}', kind)
    return kind, out, err
