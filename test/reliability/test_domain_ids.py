"""The node tests' ROS_DOMAIN_ID: one test's claim is never another's while held (two
suites side by side on one machine must not meet on a domain)."""
import fcntl
import os
from pathlib import Path

from helpers.domain import claim_domain_id, held_domain_id


def free(domain):
    """Whether another holder (a new open file, as another process would have) could lock
    `domain` now (flock locks belong to an open file, so this sees this process's too)."""
    path = Path(os.environ.get('TMPDIR', '/tmp')) / f'monet_ros_test_domain_{domain}.lock'
    with open(path, 'a') as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except OSError:
            return False


def test_held_domain_ids_are_never_given_twice():
    held = [claim_domain_id() for _ in range(8)]
    ids = [d for d, _ in held]
    assert all(lock is not None for _, lock in held) and len(set(ids)) == 8
    assert all(1 <= d <= 101 for d in ids)
    for _ in range(20):                   # held ones are never given again
        domain, lock = claim_domain_id()
        assert domain not in ids
        lock.close()
    for _, lock in held:
        lock.close()


def test_a_block_holds_its_id_until_it_ends():
    with held_domain_id() as domain:
        assert 1 <= domain <= 101 and not free(domain)
    assert free(domain)
    try:
        with held_domain_id() as domain:
            raise RuntimeError('a failing test')
    except RuntimeError:
        pass
    assert free(domain)


def test_the_fixtures_hold_the_id_the_environment_names(ros_env, ros_domain_id):
    # what test_documented_commands and test_state_and_signals take, as the node tests
    assert ros_env['ROS_DOMAIN_ID'] == str(ros_domain_id) and not free(ros_domain_id)
