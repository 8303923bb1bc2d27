"""Reliability suite fixtures and the per-entry-point case counts (helpers.reliability)."""
from collections import Counter
import json

from helpers.reliability import COUNTS, run_monet
import pytest


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not COUNTS:
        return
    terminalreporter.section('reliability cases per entry point')
    total = Counter()
    for entry in sorted(COUNTS):
        counts = COUNTS[entry]
        total.update(counts)
        parts = ', '.join(f'{n} {k}' for k, n in sorted(counts.items()))
        terminalreporter.write_line(f'{entry:<28} {sum(counts.values()):>4} cases: {parts}')
    terminalreporter.write_line(f'{"total":<28} {sum(total.values()):>4} cases: ' +
                                ', '.join(f'{n} {k}' for k, n in sorted(total.items())))
    path = config.rootpath / '.pytest_cache' / 'monet' / 'reliability_counts.json'
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({k: dict(v) for k, v in sorted(COUNTS.items())}, indent=1))
        terminalreporter.write_line(f'written: {path}')
    except OSError:
        pass


@pytest.fixture(autouse=True)
def _no_progress_bars(monkeypatch):
    monkeypatch.setenv('TQDM_DISABLE', '1')


@pytest.fixture(scope='session')
def synth_folder(tmp_path_factory):
    """A tiny `monet synth` folder (3 cameras, 6 instants, every instant labelled)."""
    path = tmp_path_factory.mktemp('synth') / 'data'
    code, _, err = run_monet(['synth', '--out', path, '--cameras', '3', '--frames', '6',
                              '--width', '64', '--height', '48', '--label-fraction', '1',
                              '--quiet'])
    assert code == 0, err
    return path


@pytest.fixture(scope='session')
def process_inputs(tmp_path_factory):
    """(recording folder, checkpoint): 3 cameras x 4 instants of noise, a small human14 net."""
    from helpers.recordings import noise_recording, small_checkpoint

    root = tmp_path_factory.mktemp('process')
    noise_recording(root / 'rec', cameras=3, frames=4, width=96, height=64)
    return root / 'rec', small_checkpoint(root / 'model.pt', input_size=(64, 64))
