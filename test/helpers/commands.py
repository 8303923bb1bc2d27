"""`monet ...` in a real process, with the checkout first on the path; setup.py's
executables."""
import ast
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


def setup_executables(repo_root):
    """setup.py's EXECUTABLES: {name: 'module:function'}, read from the source (no import
    side effects)."""
    tree = ast.parse((repo_root / 'setup.py').read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and node.targets[0].id == 'EXECUTABLES':
            return dict(ast.literal_eval(node.value))
    raise AssertionError('setup.py declares no EXECUTABLES')
