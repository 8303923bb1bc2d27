"""Lint runs inside the test suite (ruff: 99 columns, single quotes), as ament packages do."""
import subprocess
import sys


def test_ruff_clean(repo_root):
    result = subprocess.run(
        [sys.executable, '-m', 'ruff', 'check', '--no-cache', '.'],
        cwd=repo_root, capture_output=True, text=True)
    assert result.returncode == 0, f'ruff found problems:\n{result.stdout}{result.stderr}'
