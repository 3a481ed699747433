"""Shared pytest set-up: make the source packages importable without an install step, keep the
runs' directories inside the test run, and group the launched-graph tests for pytest-xdist."""
import os
import shutil
import sys
import tempfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for pkg in ('adcs_nodes', 'sim_node'):
    path = os.path.join(ROOT, pkg)
    if path not in sys.path:
        sys.path.insert(0, path)

#: The runs directory this pytest process created (removed at its end), or None.
_OWN_RUNS_DIR = None


def pytest_configure(config):
    """Run directories (node logs, parameter files, active-run manifests) go to a temporary
    directory of this test run, not the user's ``~/.cache/adcs/runs``: ``ADCS_RUNS_DIR``, set
    here before any test module imports the launcher. pytest-xdist workers are started after
    this hook and inherit the variable (the same directory for the whole session); a value
    already set (by the caller) is kept."""
    global _OWN_RUNS_DIR
    if not os.environ.get('ADCS_RUNS_DIR'):
        _OWN_RUNS_DIR = tempfile.mkdtemp(prefix='adcs-test-runs-')
        os.environ['ADCS_RUNS_DIR'] = _OWN_RUNS_DIR
    worker = os.environ.get('PYTEST_XDIST_WORKER')
    if worker:     # a worker's own subdirectory: "the latest run" is this worker's
        os.environ['ADCS_RUNS_DIR'] = os.path.join(os.environ['ADCS_RUNS_DIR'], worker)


def pytest_unconfigure(config):
    if _OWN_RUNS_DIR is not None:
        shutil.rmtree(_OWN_RUNS_DIR, ignore_errors=True)


#: Launched-graph test files with CPU burners or wall-clock bounds: one after the other on one
#: worker (group ``graph``), never beside each other.
SERIAL = frozenset({'test_determinism_control.py', 'test_external_driver.py',
                    'test_free_tumble.py', 'test_real_time.py', 'test_replay_live.py',
                    'test_slew_action_graph.py', 'test_status_watch.py',
                    'test_stress_loss.py'})


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (``make test``: 2 workers, ``--dist loadgroup``) the launched-graph
    tests of ``tests/graph`` with CPU burners or wall-clock bounds (:data:`SERIAL`) run one
    after the other on one worker (group ``graph``); each other launched-graph file is a group
    of its own (one worker for the file; it may run beside another graph: each worker has its
    own runs directory, each test its own ROS domain, ``tests/domains.py``). The unit and node
    tests, and the ``tests/graph`` tests marked ``parallel``, fill both workers."""
    graph = os.path.join(ROOT, 'tests', 'graph') + os.sep
    for item in items:
        if str(item.fspath).startswith(graph) and item.get_closest_marker('parallel') is None:
            name = os.path.basename(str(item.fspath))
            group = 'graph' if name in SERIAL else 'graph:' + name
            item.add_marker(pytest.mark.xdist_group(group))
        elif _uses_a_module_fixture(item):
            # one worker for the file: its module-scoped fixture (a FrameLoop run, a bag) is
            # made once, not once per worker that gets one of its tests
            item.add_marker(pytest.mark.xdist_group('module:' + item.module.__name__))
    if getattr(config.option, 'loadgroup', False):     # an xdist worker with loadgroup
        _group_node_ids(items)


def _group_node_ids(items):
    """pytest-xdist 3.8 schedules ``--dist loadgroup`` by an ``@group`` suffix of each node
    id, which it writes to ``item._nodeid``; pytest 9 takes the node id from ``item._id``, so
    the suffix was lost and every group was spread over the workers (the launched-graph tests
    ran side by side, each module fixture was made once per worker). The suffix is written
    here, as xdist does under pytest 8."""
    try:
        from _pytest.nodeid import NodeId
    except ImportError:           # pytest < 9: xdist's own suffix works
        return
    for item in items:
        names = sorted({str(m.args[0] if m.args else m.kwargs.get('name', 'default'))
                        for m in item.iter_markers('xdist_group')})
        if names and '@' not in item.nodeid.rsplit(']', 1)[-1]:
            item._id = NodeId.parse(f"{item.nodeid}@{'_'.join(names)}")


def _uses_a_module_fixture(item):
    """Whether ``item`` uses a module-scoped fixture defined in its own module."""
    info = getattr(item, '_fixtureinfo', None)
    if info is None or getattr(item, 'module', None) is None:
        return False
    module_id = item.nodeid.split('::')[0]
    return any(d.scope == 'module' and d.baseid == module_id
               for defs in info.name2fixturedefs.values() for d in defs)
