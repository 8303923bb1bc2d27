"""`make docs`: the MkDocs site builds in --strict mode (a broken link, a missing page or
anchor, a missing snippet file is an error), and the README's relative links and images
point at files of the checkout."""
from pathlib import Path
import re
import subprocess
import sys

REPO = Path(__file__).resolve().parents[2]


def test_site_builds_strict(tmp_path):
    result = subprocess.run([sys.executable, '-m', 'mkdocs', 'build', '--strict',
                             '--site-dir', str(tmp_path / 'site')],
                            cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'WARNING' not in result.stderr, result.stderr
    for page in (REPO / 'docs').glob('*.md'):
        built = tmp_path / 'site' / ('' if page.stem == 'index' else page.stem) / 'index.html'
        assert built.is_file(), f'{page.name} was not built (missing from the nav?)'


def test_readme_links_exist():
    text = (REPO / 'README.md').read_text()
    targets = re.findall(r'\]\(([^)#\s]+)(?:#[^)]*)?\)', text)
    assert targets, 'README.md links nothing'
    missing = [t for t in targets if '://' not in t and not (REPO / t).exists()]
    assert not missing, f'README.md links missing files: {missing}'


def test_snippets_name_files_the_benchmarks_write():
    """Quoted figures come from bench/results (pymdownx.snippets), never typed by hand."""
    included = []
    for page in (REPO / 'docs').glob('*.md'):
        included += re.findall(r'--8<-- "([^"]+)"', page.read_text())
    assert included, 'no page includes measured results'
    for name in included:
        path = name.split(':', 1)[0]
        assert path.startswith('bench/results/') and (REPO / path).is_file(), name
