"""A file from ``ros2 param dump`` works as ``--params-file`` (issue 37, item 6).

Every node of a scenario's graph is started with the launcher's parameters, dumped as
``ros2param``'s dump verb writes it (the ``get_parameters`` values, nested at each ``.``,
``yaml.dump`` of ``{/node: {ros__parameters: ...}}``), and started again from that file with
``--params-file``: it starts, with every parameter as before. A ``[]`` in the file arrives
untyped (it was a node exit 2 with an error naming no parameter); an ``epoch`` written as a
YAML timestamp loads.
"""
import array
import importlib
import os

import pytest
import yaml
from rclpy.parameter import Parameter

from adcs_nodes.graph import build_graph
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
EPOCH = '2026-01-01T00:00:00Z'


def _graph(name):
    sc = load_scenario(os.path.join(ROOT, 'scenarios', f'{name}.yaml'))
    return build_graph(sc, 10.0)


def _start(ros_context, spec, **kwargs):
    ctor = getattr(importlib.import_module(spec.module), spec.cls)
    return ctor(name=spec.name, context=ros_context, **kwargs)


def _values(node):
    return {name: list(v) if isinstance(v, (array.array, tuple)) else v
            for name, v in ((n, node.get_parameter(n).value) for n in sorted(node._parameters))}


def _dump(node):
    """The text ``ros2 param dump`` writes for ``node``."""
    params = {}
    for name, value in _values(node).items():
        where, *path, leaf = [params] + name.split('.')
        for part in path:
            where = where.setdefault(part, {})
        where[leaf] = value
    return yaml.dump({f'/{node.get_name()}': {'ros__parameters': params}},
                     default_flow_style=False)


@pytest.mark.parametrize('scenario', ['demo_mission', 'paper001_mpi'])
def test_a_dump_is_a_params_file_for_every_node(ros_context, tmp_path, scenario):
    empty = 0
    for spec in _graph(scenario):
        overrides = [Parameter(k, value=v) for k, v in spec.params.items()]
        node = _start(ros_context, spec, parameter_overrides=overrides)
        before, text = _values(node), _dump(node)
        node.destroy_node()
        empty += text.count(': []')
        path = tmp_path / f'{spec.name}.yaml'
        path.write_text(text)
        again = _start(ros_context, spec, cli_args=['--ros-args', '--params-file', str(path)])
        try:
            assert _values(again) == before, spec.name
        finally:
            again.destroy_node()
    assert empty > 0, 'no empty list in the dumps: the case is not exercised'


def test_an_epoch_written_as_a_yaml_timestamp_loads(ros_context, tmp_path):
    spec = next(n for n in _graph('free_tumble') if n.name == 'environment')
    node = _start(ros_context, spec, parameter_overrides=[
        Parameter(k, value=v) for k, v in spec.params.items()])
    text = _dump(node).replace(f"epoch: '{EPOCH}'", f'epoch: {EPOCH}')
    node.destroy_node()
    assert hasattr(yaml.safe_load(text)['/environment']['ros__parameters']['epoch'], 'year')
    path = tmp_path / 'environment.yaml'
    path.write_text(text)
    again = _start(ros_context, spec, cli_args=['--ros-args', '--params-file', str(path)])
    try:
        assert again.get_parameter('epoch').value == EPOCH
        assert again.epoch.isoformat() == '2026-01-01T00:00:00+00:00'
    finally:
        again.destroy_node()


def test_an_empty_list_for_an_array_is_the_empty_list(ros_context, tmp_path):
    """A ``[]`` the user writes (not only a dump's): an array parameter's empty value, and
    a misspelt one is refused naming it."""
    spec = next(n for n in _graph('paper000_control') if n.name == 'magnetic_controller')
    path = tmp_path / 'p.yaml'
    path.write_text(yaml.dump({'/magnetic_controller': {'ros__parameters': {
        'expected_mounts': [], 'wheel_axes_body': [], 'period_s': 2.0}}}))
    node = _start(ros_context, spec, cli_args=['--ros-args', '--params-file', str(path)])
    try:
        assert node.get_parameter('expected_mounts').value == []
        assert node.get_parameter('expected_mounts').type_ == Parameter.Type.STRING_ARRAY
    finally:
        node.destroy_node()
    path.write_text(yaml.dump({'/magnetic_controller': {'ros__parameters': {
        'expected_mount': []}}}))
    with pytest.raises(ValueError, match=r"'expected_mount' \(did you mean 'expected_mounts'"):
        _start(ros_context, spec, cli_args=['--ros-args', '--params-file', str(path)])
