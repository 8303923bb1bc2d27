"""Shared fixtures: the real data in ../shared/data and per-test ROS isolation."""
import os
from pathlib import Path
import signal
import sys

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
# test/helpers is importable as `helpers` from every test module.
sys.path.insert(0, str(Path(__file__).resolve().parent))
from helpers.domain import held_domain_id  # noqa: E402

# A shell's background job (`cmd &`, nohup) starts with SIGINT ignored, and an ignored signal
# stays ignored across exec: the commands and nodes the tests interrupt would never see it.
# Python's own handler here makes every child start with the default disposition, so the
# suite does not depend on how it was launched.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def shared_data_root():
    """../shared/data beside the checkout, or $MONET_SHARED_DATA."""
    return Path(os.environ.get('MONET_SHARED_DATA', REPO_ROOT.parent / 'shared' / 'data'))


@pytest.fixture(scope='session')
def repo_root():
    return REPO_ROOT


@pytest.fixture(scope='session')
def shared_data():
    """Path to ../shared/data; skips the test with a clear message when it is absent."""
    root = shared_data_root()
    if not root.is_dir():
        pytest.skip(f'real test data not found at {root} (set MONET_SHARED_DATA)')
    return root


@pytest.fixture
def ros_domain_id():
    """A random ROS_DOMAIN_ID (int, 1..101) held by this test alone on this machine until
    it ends (helpers.domain), for every test that starts ROS processes or nodes."""
    with held_domain_id() as domain:
        yield domain


@pytest.fixture
def ros_env(tmp_path, ros_domain_id):
    """Environment for node processes: the test's ROS_DOMAIN_ID (ros_domain_id), logs in
    tmp."""
    env = dict(os.environ)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    env['ROS_DOMAIN_ID'] = str(ros_domain_id)
    env['ROS_LOG_DIR'] = str(tmp_path / 'ros_log')
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(REPO_ROOT), env.get('PYTHONPATH')]))
    profile = REPO_ROOT / 'config' / 'fastdds_profile.xml'
    if profile.is_file():
        env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(profile)
    return env
