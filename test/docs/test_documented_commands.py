"""Every shell block of README.md and docs/*.md runs (helpers/doc_blocks.py says how):
runnable blocks run in order, per page, from a linked copy of the checkout with the real
data at ../shared/data; blocks marked flags-only have every option of their `monet`
commands in that command's --help and every ROS parameter / launch argument declared; a
block marked not-run says why. A command whose flags no longer exist fails here."""
import contextlib
from functools import lru_cache
import io
import os
from pathlib import Path
import re
import subprocess
import sys

from helpers import doc_blocks
import pytest

REPO = Path(__file__).resolve().parents[2]
PAGES = ['README.md'] + sorted(f'docs/{p.name}' for p in (REPO / 'docs').glob('*.md'))
BLOCKS = {page: doc_blocks.shell_blocks(REPO / page, page) for page in PAGES}
RUN_PAGES = [page for page, blocks in BLOCKS.items() if any(b.kind == 'run' for b in blocks)]
FLAG_BLOCKS = [b for blocks in BLOCKS.values() for b in blocks if b.kind == 'flags-only']
# what the documented commands read from the checkout; never a folder they write into
LINKED = ('bench', 'config', 'docs', 'launch', 'monet_ros', 'resource', 'test', 'tools',
          'Makefile', 'README.md', 'mkdocs.yml', 'package.xml', 'requirements.txt',
          'setup.cfg', 'setup.py')


def shared_root():
    return Path(os.environ.get('MONET_SHARED_DATA', REPO.parent / 'shared' / 'data'))


def environment(tmp_path, domain):
    """A `monet` on PATH that runs this checkout; DDS isolated as in the node tests: on
    ROS_DOMAIN_ID `domain`, the test's claimed one (the ros_domain_id fixture)."""
    bin_dir = tmp_path / 'bin'
    bin_dir.mkdir()
    shim = bin_dir / 'monet'
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m monet_ros.cli "$@"\n')
    shim.chmod(0o755)
    env = dict(os.environ)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    env['PATH'] = f'{bin_dir}{os.pathsep}{env["PATH"]}'
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(REPO), env.get('PYTHONPATH')]))
    env['ROS_DOMAIN_ID'] = str(domain)
    env['ROS_LOG_DIR'] = str(tmp_path / 'ros_log')
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return env


def sandbox(tmp_path):
    """tmp/checkout: the checkout's sources linked (outputs land beside them, never in the
    checkout); tmp/shared/data: the real data, so `../shared/data` works as documented."""
    root = tmp_path / 'checkout'
    root.mkdir()
    for name in LINKED:
        if (REPO / name).exists():
            (root / name).symlink_to(REPO / name)
    if shared_root().is_dir():
        (tmp_path / 'shared').mkdir()
        (tmp_path / 'shared' / 'data').symlink_to(shared_root())
    return root


@pytest.mark.slow
@pytest.mark.parametrize('page', RUN_PAGES)
def test_runnable_blocks_run(page, tmp_path, ros_domain_id):
    blocks = [b for b in BLOCKS[page] if b.kind == 'run']
    if any('../shared/data' in b.text for b in blocks) and not shared_root().is_dir():
        pytest.skip(f'{page}: real data not found at {shared_root()} (set MONET_SHARED_DATA)')
    root, env = sandbox(tmp_path), environment(tmp_path, ros_domain_id)
    for block in blocks:
        result = subprocess.run(['bash', '-e', '-o', 'pipefail', '-c', block.text], cwd=root,
                                env=env, capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, (
            f'{block.where()} exited {result.returncode}:\n{block.text}\n'
            f'stdout (end):\n{result.stdout[-3000:]}\nstderr (end):\n{result.stderr[-3000:]}')


@lru_cache(maxsize=None)
def monet_help(subcommand):
    """`monet SUBCOMMAND --help` as the command prints it (its own parser, in process)."""
    from monet_ros.cli import build_parser
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as stopped:
        build_parser().parse_args([*subcommand, '--help'])
    assert stopped.value.code == 0, f'monet {" ".join(subcommand)} --help failed'
    return out.getvalue()


def declared(kind, name, parameters):
    """The names among `parameters` that the node's config YAML or the launch file lacks."""
    if kind == 'node':
        text = (REPO / 'config' / f'{name}.yaml').read_text()
        return [p for p in parameters if not re.search(rf'^\s+{re.escape(p)}:', text, re.M)]
    text = (REPO / 'launch' / name).read_text()
    return [p for p in parameters if f"'{p}'" not in text]


@pytest.mark.parametrize('block', FLAG_BLOCKS, ids=lambda b: b.where())
def test_flags_only_blocks_name_existing_options(block):
    checked = 0
    for words in doc_blocks.commands(block.text):
        found = doc_blocks.monet_invocation(words)
        if found is not None:
            subcommand, rest = found
            text = monet_help(tuple(subcommand))
            for option in doc_blocks.option_words(rest):
                assert re.search(rf'(?<![\w-]){re.escape(option)}(?![\w-])', text), (
                    f'{block.where()}: monet {" ".join(subcommand)} has no option {option}')
                checked += 1
            checked += 1
        ros = doc_blocks.ros_parameters(words)
        if ros is not None:
            missing = declared(*ros)
            assert not missing, f'{block.where()}: {ros[1]} does not declare {missing}'
            checked += 1
    assert checked, f'{block.where()}: flags-only block without a monet / ros2 command'


def test_every_block_outside_a_run_says_why():
    for blocks in BLOCKS.values():
        for block in blocks:
            assert block.kind == 'run' or len(block.reason) > 3, block.where()


def test_the_lab_path_runs_on_real_data():
    """The README's promise: the real Pose2Sim and sleap-anipose sessions reach 3D with
    documented commands that this suite runs (not only checks)."""
    runnable = ''.join(b.text for blocks in BLOCKS.values() for b in blocks if b.kind == 'run')
    assert 'pose2sim_demo_balancing' in runnable
    assert 'sleap_anipose_minimal_session' in runnable
