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
    import pathlib
    root = pathlib.Path(adcs_nodes.core.__file__).parents[1]
    offenders = [str(p) for p in root.rglob('*.py') if _imports_sim(p)]
    assert offenders == []


def _imports_sim(path):
    for line in path.read_text().splitlines():
        s = line.strip()
        if s.startswith(('import sim_node', 'from sim_node')):
            return True
    return False
