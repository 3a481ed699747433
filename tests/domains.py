"""The ``ROS_DOMAIN_ID`` of a test: its own, also when pytest-xdist runs tests side by side.

``make test`` runs two pytest-xdist workers. A test that starts ROS 2 participants takes a
domain from :func:`worker_domain`: worker k of K only uses the ids ``id % K == k`` of the
test's range (two workers never meet on a domain), and the id is claimed with the launcher's
lock file (:func:`adcs_nodes.tools.run.launcher.acquire_domain`), so a bench ring or another tool
claiming domains with the same lock files never takes it either. The claim lasts until the
same process claims its next domain (one test runs at a time in a worker).
"""
import os

from adcs_nodes.tools.run.launcher import LaunchError, acquire_domain

_held = []      # the lock file of this process's current domain


def worker_domain(first: int, count: int, n: int = 0) -> int:
    """A free domain of ``first .. first + count - 1`` that belongs to this pytest worker.

    ``n`` moves the start through the range (the tests use a counter, so consecutive tests
    of a process do not reuse a domain whose participants DDS may still list)."""
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    k = int(worker[2:]) if worker.startswith('gw') and worker[2:].isdigit() else 0
    total = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1') or 1)
    ids = [d for d in range(first, first + count) if d % total == k % total]
    if not ids:
        raise ValueError(f'no domain of {first}..{first + count - 1} for worker {k} of {total}')
    while _held:
        _held.pop().close()
    start = (os.getpid() + n) % len(ids)
    for dom in ids[start:] + ids[:start]:
        try:
            dom, handle = acquire_domain([dom])
        except LaunchError:
            continue                   # claimed by another process (a bench ring, a run)
        _held.append(handle)
        return dom
    raise RuntimeError(f'every domain of {first}..{first + count - 1} for worker {k} is taken')
