"""The node tests' ROS_DOMAIN_ID: one test's claim is never another's while held (two
suites side by side on one machine must not meet on a domain)."""
from helpers.domain import claim_domain_id


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
