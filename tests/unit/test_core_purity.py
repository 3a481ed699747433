"""core/ and models/ must import neither rclpy nor any *_msgs package (DESIGN section 2)."""
import importlib
import pkgutil
import sys

import adcs_nodes.core
import sim_node.models


def _modules(pkg):
    return [f'{pkg.__name__}.{m.name}' for m in pkgutil.iter_modules(pkg.__path__)]


def test_core_and_models_import_without_ros(monkeypatch):
    blocked = ['rclpy', 'adcs_msgs', 'std_msgs', 'geometry_msgs', 'sensor_msgs',
               'rosgraph_msgs', 'builtin_interfaces']
    for name in list(sys.modules):
        pure = name.startswith(('adcs_nodes.core', 'sim_node.models'))
        if name.split('.')[0] in blocked or pure:
            monkeypatch.delitem(sys.modules, name)
    for name in blocked:
        monkeypatch.setitem(sys.modules, name, None)   # any import of them now fails
    mods = _modules(adcs_nodes.core) + _modules(sim_node.models)
    assert 'adcs_nodes.core.attitude' in mods and 'sim_node.models.dynamics' in mods
    for mod in mods:
        importlib.import_module(mod)


def test_flight_software_never_imports_the_simulator():
    """The flight software (core, components, nodes, the registry) never imports sim_node; the
    tools that orchestrate runs reach the simulator only through its public interfaces, the
    FrameLoop (``sim_node.engine``) and the fault kinds a scenario declares
    (``sim_node.faults``: validation, the launcher's node kills), never through its models
    (DESIGN section 2)."""
    import pathlib
    root = pathlib.Path(adcs_nodes.core.__file__).parents[1]
    offenders = []
    for p in root.rglob('*.py'):
        tool = 'tools' in p.relative_to(root).parts
        for module in _sim_imports(p):
            if not (tool and module in ('sim_node.engine', 'sim_node.faults')):
                offenders.append(f'{p.relative_to(root)}: {module}')
    assert offenders == []


def _sim_imports(path):
    """The sim_node modules a file imports (``import sim_node.x`` / ``from sim_node.x ...``)."""
    out = []
    for line in path.read_text().splitlines():
        s = line.strip()
        if s.startswith(('import sim_node', 'from sim_node')):
            out.append(s.split()[1])
    return out


def test_components_and_the_frameloop_import_without_rclpy(monkeypatch):
    """The components and the FrameLoop use the generated message classes but no rclpy: the
    plain engine runs where ROS does not (issue 19)."""
    for name in list(sys.modules):
        if name.split('.')[0] == 'rclpy' or name.startswith(
                ('adcs_nodes.components', 'sim_node.components', 'sim_node.engine',
                 'adcs_nodes.nodes', 'adcs_nodes.tools')):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, 'rclpy', None)      # any import of it now fails
    import adcs_nodes.components
    import sim_node.components
    mods = _modules(adcs_nodes.components) + _modules(sim_node.components)
    assert 'adcs_nodes.components.estimator' in mods and 'sim_node.components.dynamics' in mods
    for mod in mods + ['sim_node.engine']:
        importlib.import_module(mod)
