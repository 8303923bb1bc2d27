"""The package installs into a prefix the way colcon's ament_python build does."""
import ast
from pathlib import Path
import subprocess
import sys


def declared_executables(repo_root):
    """Names in setup.py's EXECUTABLES dict, read from the source (no import side effects)."""
    tree = ast.parse((repo_root / 'setup.py').read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and node.targets[0].id == 'EXECUTABLES':
            return list(ast.literal_eval(node.value))
    raise AssertionError('setup.py declares no EXECUTABLES')


def test_install_into_prefix_has_ament_layout(repo_root, tmp_path):
    prefix = tmp_path / 'install'
    # What colcon's ament_python task runs (build + install --prefix into its install space).
    result = subprocess.run(
        [sys.executable, 'setup.py', '-q', 'egg_info', '--egg-base', str(tmp_path),
         'build', '--build-base', str(tmp_path / 'build'),
         'install', '--prefix', str(prefix), '--record', str(tmp_path / 'record.txt'),
         '--single-version-externally-managed'],
        cwd=repo_root, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr

    marker = prefix / 'share/ament_index/resource_index/packages/monet_ros'
    assert marker.is_file(), 'ament index marker missing: ros2 run would not find the package'
    assert (prefix / 'share/monet_ros/package.xml').is_file()
    for config in (repo_root / 'config').rglob('*'):
        if config.is_file():
            installed = prefix / 'share/monet_ros' / config.relative_to(repo_root)
            assert installed.is_file(), f'{installed} not installed'

    executables = declared_executables(repo_root)
    assert 'monet' in executables
    for name in executables:
        script = prefix / 'lib/monet_ros' / name
        assert script.is_file(), f'{script} missing: `ros2 run monet_ros {name}` would fail'
        assert script.stat().st_mode & 0o111, f'{script} is not executable'
    site = list(Path(prefix).glob('lib/python3*/site-packages/monet_ros/__init__.py'))
    assert site, 'monet_ros package not installed into the prefix'
