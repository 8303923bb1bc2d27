"""The page of `monet label` ships in the package: an install (colcon's ament_python build
steps) holds every asset the page loads, and the page loads nothing from elsewhere."""
from pathlib import Path
import re
import subprocess
import sys

STATIC = Path(__file__).resolve().parents[2] / 'monet_ros' / 'label_app' / 'static'


def test_page_references_only_packaged_assets():
    html = (STATIC / 'index.html').read_text()
    refs = re.findall(r'(?:src|href)="([^"]+)"', html)
    assert refs, 'the page loads no asset?'
    for ref in refs:
        assert ref.startswith('/static/'), f'{ref}: not served from the package (no CDN)'
        assert (STATIC / ref[len('/static/'):]).is_file(), ref
    for path in STATIC.iterdir():
        text = path.read_text()
        assert not re.search(r'https?://', text), f'{path.name} refers to a remote URL'


def test_install_holds_the_static_assets(repo_root, tmp_path):
    result = subprocess.run(
        [sys.executable, 'setup.py', '-q', 'egg_info', '--egg-base', str(tmp_path),
         'build', '--build-base', str(tmp_path / 'build'),
         'install', '--prefix', str(tmp_path / 'install'),
         '--single-version-externally-managed', '--record', str(tmp_path / 'record.txt')],
        cwd=repo_root, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    installed = list((tmp_path / 'install').glob('lib/python3*/site-packages/monet_ros/'
                                                 'label_app/static'))
    assert installed, 'monet_ros/label_app/static not installed'
    names = sorted(p.name for p in installed[0].iterdir())
    assert names == sorted(p.name for p in STATIC.iterdir())
