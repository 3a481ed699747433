"""The layering of the packages (DESIGN section 2), read from the imports of every module.

Layers, lowest first; a module may import its own layer and the layers below it, never a layer
above it nor a sibling of the same rank (the engine and the nodes are both adapters of the
components: neither imports the other). Every import counts, at module level or inside a
function. Also: no import cycle between modules; no message type in the core, the components
or the engine (they work on core types); the tools reach the simulated world only through the
engine and the registered fault kinds, never its models, components or nodes; the flight
software never imports the simulator; the message layer and the specs use no rclpy.
"""
import ast
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SOURCES = {'adcs_nodes': os.path.join(ROOT, 'adcs_nodes', 'adcs_nodes'),
           'sim_node': os.path.join(ROOT, 'sim_node', 'sim_node')}

#: (rank, layer, module prefixes), lowest first.
LAYERS = (
    (0, 'core', ('adcs_nodes.core', 'sim_node.models')),
    (1, 'msgs', ('adcs_nodes.msgs', 'adcs_nodes.bag', 'adcs_nodes.distro')),
    (2, 'spec', ('adcs_nodes.spec', 'adcs_nodes.registry', 'adcs_nodes.inputs',
                 'adcs_nodes.entries', 'adcs_nodes.scenario', 'adcs_nodes.graph',
                 'sim_node.entries', 'sim_node.faults')),
    (3, 'components', ('adcs_nodes.components', 'sim_node.components')),
    (4, 'engine', ('sim_node.engine',)),
    (4, 'nodes', ('adcs_nodes.nodes', 'sim_node.nodes')),
    (5, 'tools', ('adcs_nodes.tools', 'sim_node.tools')),
)
#: Top-level packages of ROS messages (a message type is not a core type).
MESSAGE_PACKAGES = ('adcs_msgs', 'builtin_interfaces', 'diagnostic_msgs', 'geometry_msgs',
                    'rosgraph_msgs', 'sensor_msgs', 'std_msgs', 'tf2_msgs', 'rcl_interfaces')
#: What the project's tools (``adcs_nodes.tools``) may import of the simulator.
WORLD_FOR_TOOLS = ('sim_node.engine', 'sim_node.faults', 'sim_node.entries')
#: Imports that break the rules today, each to be removed as the layers are cut (the test fails
#: on any other, and on one of these that is gone but still listed).
KNOWN: set = set()


def _modules():
    out = {}
    for top, src in SOURCES.items():
        for dirpath, _, files in os.walk(src):
            for f in files:
                if f.endswith('.py'):
                    rel = os.path.relpath(os.path.join(dirpath, f), src)[:-3].split(os.sep)
                    if rel[-1] == '__init__':
                        rel = rel[:-1]
                    out['.'.join([top] + rel)] = os.path.join(dirpath, f)
    return out


MODULES = _modules()


def _imports(name, path):
    """Every module ``name`` imports (absolute names; ``from x import y`` gives ``x.y`` when
    ``x.y`` is a module of the project, else ``x``)."""
    tree = ast.parse(open(path, encoding='utf-8').read(), path)
    package = name if path.endswith('__init__.py') else name.rpartition('.')[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parts = package.split('.')
                base = '.'.join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
            for a in node.names:
                full = f'{base}.{a.name}'
                out.add(full if full in MODULES else base)
    return out


IMPORTS = {name: _imports(name, path) for name, path in MODULES.items()}


def layer(module):
    """``(rank, layer)`` of a project module, or None for the package roots."""
    best = None
    for rank, name, prefixes in LAYERS:
        for p in prefixes:
            inside = module == p or module.startswith(p + '.')
            if inside and (best is None or len(p) > best[2]):
                best = (rank, name, len(p))
    return None if best is None else best[:2]


def _project(module):
    return module.split('.')[0] in SOURCES


def violations():
    out = set()
    for name, imported in IMPORTS.items():
        mine = layer(name)
        for mod in imported:
            top = mod.split('.')[0]
            if mine is None:
                continue
            if mine[1] in ('core', 'components', 'engine') and top in MESSAGE_PACKAGES + (
                    'rclpy',):
                out.add(f'{name} -> {mod} (a {mine[1]} module imports ROS)')
            if mine[1] in ('msgs', 'spec') and top == 'rclpy':
                out.add(f'{name} -> {mod} (a {mine[1]} module imports rclpy)')
            if not _project(mod):
                continue
            theirs = layer(mod)
            if theirs is None:
                continue
            if theirs[0] > mine[0] or (theirs[0] == mine[0] and theirs[1] != mine[1]):
                out.add(f'{name} -> {mod} ({mine[1]} imports {theirs[1]})')
            if name.startswith('adcs_nodes.tools') and top == 'sim_node' \
                    and not mod.startswith(WORLD_FOR_TOOLS):
                out.add(f'{name} -> {mod} (a tool reaches the world past the engine)')
            if name.startswith('adcs_nodes.') and mine[1] != 'tools' and top == 'sim_node':
                out.add(f'{name} -> {mod} (the flight software imports the simulator)')
    return out


def _cycles():
    """Strongly connected components of more than one module (Tarjan)."""
    graph = {n: sorted(m for m in imps if m in MODULES and m != n)
             for n, imps in IMPORTS.items()}
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_every_module_has_a_layer():
    loose = sorted(n for n in MODULES if layer(n) is None and n not in SOURCES)
    assert not loose, f'modules outside every layer (add them to LAYERS): {loose}'


def test_no_import_climbs_up_or_sideways():
    found = violations()
    new = sorted(v for v in found if v.split(' (')[0] not in KNOWN)
    gone = sorted(KNOWN - {v.split(' (')[0] for v in found})
    assert not new, 'imports that break the layering:\n' + '\n'.join(new)
    assert not gone, 'fixed, remove them from KNOWN:\n' + '\n'.join(gone)


def test_no_import_cycle():
    assert _cycles() == []


@pytest.mark.parametrize('module', ['adcs_nodes.components.x', 'sim_node.engine'])
def test_the_rule_sees_an_upward_import(module, monkeypatch):
    """The check can fail: a component or the engine importing a node is reported."""
    monkeypatch.setitem(IMPORTS, module, {'adcs_nodes.nodes.lockstep_node', 'std_msgs.msg'})
    monkeypatch.setitem(MODULES, module, '')
    found = violations()
    assert any(v.startswith(module + ' -> adcs_nodes.nodes.lockstep_node') for v in found)
    assert any(v.startswith(module + ' -> std_msgs.msg') for v in found)


def test_the_rule_sees_rclpy_in_the_message_layer(monkeypatch):
    """The message layer converts and encodes without rclpy (the plain engine's bags)."""
    monkeypatch.setitem(IMPORTS, 'adcs_nodes.msgs.x', {'rclpy.serialization', 'std_msgs.msg'})
    monkeypatch.setitem(MODULES, 'adcs_nodes.msgs.x', '')
    found = {v.split(' (')[0] for v in violations()}
    assert 'adcs_nodes.msgs.x -> rclpy.serialization' in found
    assert 'adcs_nodes.msgs.x -> std_msgs.msg' not in found       # message types: its job
