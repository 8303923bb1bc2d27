"""`monet ...` in a real process, with the checkout first on the path."""
import os
import subprocess
import sys


def run_monet_process(repo_root, *args, cwd=None, timeout=300):
    """subprocess.run of `python -m monet_ros.cli ARGS` (text, stdout/stderr captured),
    from `cwd` (default the checkout)."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(repo_root), env.get('PYTHONPATH')]))
    return subprocess.run([sys.executable, '-m', 'monet_ros.cli', *map(str, args)],
                          cwd=cwd or repo_root, env=env, capture_output=True, text=True,
                          timeout=timeout)
