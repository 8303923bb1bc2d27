"""A ROS_DOMAIN_ID for one test, held on this machine while the test runs."""
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
