"""Shared pytest set-up: make the source packages importable without an install step."""
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for pkg in ('adcs_nodes', 'sim_node'):
    path = os.path.join(ROOT, pkg)
    if path not in sys.path:
        sys.path.insert(0, path)


def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (``make test``: 2 workers, ``--dist loadgroup``) the launched-graph
    tests of ``tests/integration`` run one after the other on one worker, as before; the
    unit and node tests share the other worker and fill the CPU time the graph tests spend
    waiting (start-up, discovery, deadlines). Each test's ROS domain is its own
    (``tests/domains.py``)."""
    import pytest
    integration = os.path.join(ROOT, 'tests', 'integration') + os.sep
    for item in items:
        if str(item.fspath).startswith(integration):
            item.add_marker(pytest.mark.xdist_group('integration'))
