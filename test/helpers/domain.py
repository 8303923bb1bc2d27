"""A ROS_DOMAIN_ID for one test, held on this machine while the test runs: the one way
every test (the `ros_domain_id` / `ros_env` fixtures of test/conftest.py) and bench script
that starts ROS processes picks its domain."""
from contextlib import contextmanager
import fcntl
import os
from pathlib import Path
import random


def claim_domain_id():
    """(id, open lock file): a random ROS_DOMAIN_ID in 1..101 that no other test session
    on this machine holds (an flock on a file per id in the temp folder, released when the
    file closes), so two suites run side by side never meet on one domain; any id if all
    are held."""
    ids = random.sample(range(1, 102), 101)
    folder = Path(os.environ.get('TMPDIR', '/tmp'))
    for domain in ids:
        lock = open(folder / f'monet_ros_test_domain_{domain}.lock', 'a')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return domain, lock
        except OSError:
            lock.close()
    return ids[0], None


@contextmanager
def held_domain_id():
    """`with held_domain_id() as domain:` a ROS_DOMAIN_ID (int, 1..101) claimed by
    claim_domain_id for the block, released when it ends (also on an exception)."""
    domain, lock = claim_domain_id()
    try:
        yield domain
    finally:
        if lock is not None:
            lock.close()
