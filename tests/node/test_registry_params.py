"""Node parameters come from the registry's one spec (issue 8).

Every parameter of a registry-built node has a descriptor with a description (what
``ros2 param describe`` prints), its default is the entry's default (the same value the
scenario schema and ``docs/scenarios.md`` show), a misspelt parameter is refused at start-up
with a did-you-mean, and a bad run-time change is refused with the reason.
"""
import pytest
from rclpy.parameter import Parameter

from adcs_nodes import registry
from adcs_nodes.nodes.controller import ControllerNode
from adcs_nodes.nodes.estimator import EstimatorNode
from adcs_nodes.scenario import schema, schema_markdown


def _describe(node):
    names = sorted(node._parameters)
    return {d.name: d for d in node.describe_parameters(names)}


@pytest.mark.parametrize('name', ['magnetic', 'bdot'])
def test_controller_node_parameters_are_described_and_default_to_the_spec(ros_context, name):
    node = ControllerNode(controller=name, context=ros_context)
    try:
        entry = registry.get('controller', name)
        desc = _describe(node)
        undocumented = [n for n, d in desc.items() if not d.description
                        and n != 'use_sim_time']
        assert undocumented == []
        for p in entry.params:
            assert node.get_parameter(p.name).value == p.default
            assert p.unit in desc[p.name].description or p.unit == '-'
            section = schema()['controllers'][name]
            assert section[p.name].default == p.default          # scenario schema
            assert f'`controllers.{name}.{p.name}`' in schema_markdown()
    finally:
        node.destroy_node()


def test_estimator_node_parameters_default_to_the_spec(ros_context):
    node = EstimatorNode(context=ros_context)
    try:
        entry = registry.get('estimator', 'magnetic_filter')
        for p in entry.params:
            assert node.get_parameter(p.name).value == p.default
            keys = schema()['estimator'].keys({'algorithm': 'magnetic_filter'})
            assert keys[p.name].default == p.default
        assert all(d.description for n, d in _describe(node).items() if n != 'use_sim_time')
    finally:
        node.destroy_node()


def test_misspelt_parameter_is_refused_with_a_did_you_mean(ros_context):
    with pytest.raises(ValueError, match="'alpha_per_sec' \\(did you mean 'alpha_per_s'\\?\\)"):
        ControllerNode(controller='magnetic', context=ros_context, parameter_overrides=[
            Parameter('alpha_per_sec', value=1e-3)])


def test_out_of_range_parameter_is_refused_at_start(ros_context):
    with pytest.raises(ValueError, match='k_Nms: must be > 0'):
        ControllerNode(controller='magnetic', context=ros_context, parameter_overrides=[
            Parameter('k_Nms', value=-0.2)])


def test_run_time_changes_are_validated(ros_context):
    node = ControllerNode(controller='magnetic', context=ros_context)
    try:
        bad = node.set_parameters([Parameter('alpha_per_s', value=-1.0)])[0]
        assert not bad.successful and '> 0' in bad.reason
        choice = node.set_parameters([Parameter('mode', value='four_axis')])[0]
        assert not choice.successful and 'three_axis' in choice.reason
        ro = node.set_parameters([Parameter('controller', value='bdot')])[0]
        assert not ro.successful
        ok = node.set_parameters([Parameter('alpha_per_s', value=2e-3)])[0]
        assert ok.successful and node.get_parameter('alpha_per_s').value == 2e-3
    finally:
        node.destroy_node()


@pytest.mark.parametrize('module, cls', [
    ('sim_node.nodes.environment', 'EnvironmentNode'),
    ('sim_node.nodes.dynamics', 'DynamicsNode'),
    ('sim_node.nodes.sensor_node', 'SensorNode:magnetometer'),
    ('sim_node.nodes.sensor_node', 'SensorNode:horizon_sensor'),
    ('sim_node.nodes.sensor_node', 'SensorNode:star_tracker'),
    ('sim_node.nodes.sensor_node', 'SensorNode:gyro'),
    ('sim_node.nodes.sensor_node', 'SensorNode:wheel_tachometer'),
    ('adcs_nodes.nodes.estimator', 'EstimatorNode'),
    ('adcs_nodes.nodes.guidance', 'GuidanceNode'),
    ('adcs_nodes.nodes.controller_manager', 'ControllerManagerNode'),
])
def test_every_node_describes_every_parameter(ros_context, module, cls):
    """What ``ros2 param describe`` prints: a description for each parameter of each node."""
    import importlib
    cls, _, sensor = cls.partition(':')        # the generic sensor node: SensorNode:<sensor>
    kwargs = {'sensor': sensor} if sensor else {}
    node = getattr(importlib.import_module(module), cls)(context=ros_context, **kwargs)
    try:
        missing = [n for n, d in _describe(node).items()
                   if not d.description and n not in ('use_sim_time',
                                                      'start_type_description_service')]
        assert missing == [], f'{cls}: parameters without a description: {missing}'
    finally:
        node.destroy_node()
