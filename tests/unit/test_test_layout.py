"""The layout of the suite: the test tiers are its folders, and what a tier may do is checked
where a reading of the source can tell.

* ``unit``: core math, behaviour on the FrameLoop; imports no rclpy and starts no process;
* ``node``: one node in process (rclpy in process, no process started);
* ``graph``: launches processes (the ROS graph, the ``adcs`` command, fresh interpreters);
* ``reproductions``: the long paper reproductions (``make reproduce``);
* ``plugins``: test-only registry plugins (no tests).

Checked by reading the files (``ast``): every test file is in a tier folder; a unit test
module imports no rclpy, directly or through the project modules it imports at module level,
nor a module that starts processes (``subprocess``, ``multiprocessing``, Dask, the graph
tests' helpers), and calls no ``os.fork``/``os.system``/``os.exec*``/``os.spawn*``/
``os.popen``; a node test launches no graph. Not seen by reading: an import inside a function
of a product module (``tests/unit/conftest.py`` makes rclpy unimportable during a unit test
when the process has not imported it yet).

The suite is collected without package ``__init__`` files (pytest's rootdir imports), so two
test files with the same basename in different folders break collection of the whole run
("import file mismatch"); this catches it by name, before a clean clone does.
"""
import ast
import collections
import functools
import os

TESTS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROOT = os.path.dirname(TESTS)
TIERS = {'unit', 'node', 'graph', 'reproductions', 'plugins', 'perf'}
#: Project packages: ``name -> source directory`` (followed through their module-level
#: imports).
PACKAGES = {'adcs_nodes': os.path.join(ROOT, 'adcs_nodes', 'adcs_nodes'),
            'sim_node': os.path.join(ROOT, 'sim_node', 'sim_node')}
#: Modules a unit test must not import: rclpy, and what starts processes.
NOT_IN_UNIT = ('rclpy', 'subprocess', 'multiprocessing', 'concurrent.futures.process',
               'distributed', 'dask', 'adcs_launch', 'domains', 'launch', 'launch_ros')
#: Calls that start a process.
PROCESS_CALLS = ('fork', 'forkpty', 'system', 'popen', 'posix_spawn', 'posix_spawnp',
                 'execv', 'execve', 'execl', 'execle', 'execlp', 'execlpe', 'execvp', 'execvpe',
                 'spawnl', 'spawnle', 'spawnlp', 'spawnlpe', 'spawnv', 'spawnve', 'spawnvp',
                 'spawnvpe')
#: Unit test files that break the rule, each with the reason it stays for now. Only a file
#: that another change in progress is editing belongs here (moving it under that change would
#: lose its edits); its test that starts a process goes to tests/graph (as
#: ``test_fresh_interpreters.py``), its rclpy test to tests/node, once that change is in.
UNIT_EXCEPTIONS = {
    'test_filter_kernels.py': 'a fresh interpreter (subprocess), being edited elsewhere',
    'test_export_report.py': 'a fresh interpreter (subprocess), being edited elsewhere',
    'test_warm_kernels.py': 'processes (the warm-up tool), being edited elsewhere',
    'test_launch_file.py': 'processes and DDS domains (the launch file), being edited elsewhere',
}


def _test_files():
    for folder, dirs, files in os.walk(TESTS):
        dirs[:] = [d for d in dirs if not d.startswith(('.', '__'))]
        for name in files:
            if name.startswith('test_') and name.endswith('.py'):
                yield os.path.join(folder, name)


def _tier_files(tier, pattern='test_'):
    folder = os.path.join(TESTS, tier)
    return sorted(os.path.join(folder, n) for n in os.listdir(folder)
                  if n.endswith('.py') and n.startswith(pattern))


@functools.lru_cache(maxsize=None)
def _imports(path, module_level_only=False):
    """Modules ``path`` imports (absolute names; ``from a import b`` gives ``a`` and ``a.b``),
    and ``pytest.importorskip('x')`` as ``x``; a frozenset."""
    with open(path, encoding='utf-8') as fh:
        tree = ast.parse(fh.read(), path)
    nodes = tree.body if module_level_only else list(ast.walk(tree))
    if module_level_only:                  # module level: also inside if/try blocks there
        todo, nodes = list(nodes), []
        while todo:
            node = todo.pop()
            nodes.append(node)
            if isinstance(node, (ast.If, ast.Try, ast.With)):
                for field in ('body', 'orelse', 'finalbody', 'handlers'):
                    todo.extend(getattr(node, field, []))
            elif isinstance(node, ast.ExceptHandler):
                todo.extend(node.body)
    names = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
            names.update(f'{node.module}.{a.name}' for a in node.names)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr == 'importorskip' and node.args
              and isinstance(node.args[0], ast.Constant)):
            names.add(str(node.args[0].value))
    return frozenset(names)


def _process_calls(path):
    """``os.<call>`` calls in ``path`` that start a process."""
    with open(path, encoding='utf-8') as fh:
        tree = ast.parse(fh.read(), path)
    return sorted(node.func.attr for node in ast.walk(tree)
                  if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and isinstance(node.func.value, ast.Name) and node.func.value.id == 'os'
                  and node.func.attr in PROCESS_CALLS)


def _source_of(module, test_dir):
    """The source file of a project module or a test helper module, or None."""
    parts = module.split('.')
    if parts[0] in PACKAGES:
        base = os.path.join(PACKAGES[parts[0]], *parts[1:])
    elif len(parts) == 1:
        for folder in (test_dir, TESTS):
            if os.path.isfile(os.path.join(folder, f'{module}.py')):
                return os.path.join(folder, f'{module}.py')
        return None
    else:
        return None
    for candidate in (base + '.py', os.path.join(base, '__init__.py')):
        if os.path.isfile(candidate):
            return candidate
    return None


def _forbidden(name):
    return next((f for f in NOT_IN_UNIT if name == f or name.startswith(f + '.')), None)


def _unit_violations(path):
    """What the unit test module ``path`` imports or calls that the unit tier must not:
    ``[(what, through which module)]``."""
    found = []
    for name in sorted(_imports(path)):
        if _forbidden(name):
            found.append((name, os.path.basename(path)))
    found += [(f'os.{c}', os.path.basename(path)) for c in _process_calls(path)]
    # rclpy through the project modules and helpers imported at module level (transitively)
    seen, todo = set(), []
    for name in _imports(path):
        parts = name.split('.')
        todo += ['.'.join(parts[:k]) for k in range(1, len(parts) + 1)]   # parents first
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        src = _source_of(name, os.path.dirname(path))
        if src is None or src == path:
            continue
        for sub in _imports(src, module_level_only=True):
            if sub == 'rclpy' or sub.startswith('rclpy.'):
                found.append((sub, name))
            parts = sub.split('.')
            todo += ['.'.join(parts[:k]) for k in range(1, len(parts) + 1)]
    return found


def test_test_file_basenames_are_unique():
    where = collections.defaultdict(list)
    for path in _test_files():
        where[os.path.basename(path)].append(os.path.relpath(path, TESTS))
    dups = {name: paths for name, paths in where.items() if len(paths) > 1}
    assert not dups, f'test files with the same basename: {dups}'


def test_the_tiers_are_the_folders():
    folders = {d for d in os.listdir(TESTS) if os.path.isdir(os.path.join(TESTS, d))
               and not d.startswith(('.', '__'))}
    assert folders == TIERS, f'tests/ folders {sorted(folders)}, tiers {sorted(TIERS)}'
    misplaced = [os.path.relpath(p, TESTS) for p in _test_files()
                 if os.path.relpath(p, TESTS).split(os.sep)[0] not in TIERS - {'plugins', 'perf'}]
    assert not misplaced, f'test files outside a tier folder: {misplaced}'


def test_unit_tests_import_no_rclpy_and_start_no_process():
    bad = {}
    for path in _tier_files('unit', pattern=''):
        name = os.path.basename(path)
        if name in UNIT_EXCEPTIONS:
            continue
        found = _unit_violations(path)
        if found:
            bad[name] = found
    assert not bad, ('unit tests that import rclpy or start processes (they belong in '
                     f'tests/node or tests/graph): {bad}')


def test_the_unit_exceptions_still_need_to_be_exceptions():
    for name in UNIT_EXCEPTIONS:
        path = os.path.join(TESTS, 'unit', name)
        assert os.path.isfile(path) and _unit_violations(path), \
            f'{name} is no exception any more: remove it from UNIT_EXCEPTIONS'


def test_node_tests_launch_no_graph():
    bad = {os.path.basename(p): sorted(n for n in _imports(p) if n in ('adcs_launch',))
           for p in _tier_files('node')}
    bad = {k: v for k, v in bad.items() if v}
    assert not bad, f'node tests that launch the graph (they belong in tests/graph): {bad}'


def test_graph_tests_start_processes():
    """A launched-graph test starts processes: the ``adcs`` command or a node (through
    ``subprocess`` or the graph tests' helpers)."""
    quiet = [os.path.basename(p) for p in _tier_files('graph')
             if not _imports(p) & {'subprocess', 'adcs_launch', 'multiprocessing'}]
    assert not quiet, f'graph tests that start no process (they belong in unit or node): {quiet}'
