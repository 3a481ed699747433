"""Run-time parameters through the standard services, as ``ros2 param`` sends them (issue 22).

The ``ros2`` CLI is not installable here, so these tests drive ``SetParameters``,
``DescribeParameters``, ``GetParameters`` and ``ListParameters`` from a probe node, with the
values built the way the CLI builds them (``rclpy.parameter.get_parameter_value`` on the
command-line text): ``"[0.0, 1.5]"`` is a ``double_array_value`` (an ``array.array('d')`` once
it has crossed the service), ``"[]"`` an empty ``bool_array_value``, ``"2"`` an integer.

What each node must do: a parameter it applies at run time takes effect at the next frame
boundary; any other one is read-only, and a set is refused with the reason; a value is
validated (type, range, choices); a name the node does not have is refused with a
did-you-mean; an empty list is typed; every descriptor says unit and range, or the choices.
"""
import array
import importlib
import math
import re

import numpy as np
import pytest
import rclpy
import yaml
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import (DescribeParameters, GetParameters, ListParameters,
                                SetParameters)
from rclpy.parameter import Parameter, get_parameter_value
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import MagneticField

from adcs_msgs.msg import ActuatorCommand
from adcs_nodes.nodes.controller import ControllerNode
from adcs_nodes.msgs.fields import to_stamp, to_vec3

S = 10**9
#: Every node class of the graph, with the module it lives in.
NODE_CLASSES = [
    ('sim_node.nodes.environment', 'EnvironmentNode'),
    ('sim_node.nodes.dynamics', 'DynamicsNode'),
    ('sim_node.nodes.sensor_node', 'SensorNode:magnetometer'),
    ('sim_node.nodes.sensor_node', 'SensorNode:horizon_sensor'),
    ('sim_node.nodes.sensor_node', 'SensorNode:star_tracker'),
    ('sim_node.nodes.sensor_node', 'SensorNode:gyro'),
    ('sim_node.nodes.sensor_node', 'SensorNode:wheel_tachometer'),
    ('adcs_nodes.nodes.estimator', 'EstimatorNode'),
    ('adcs_nodes.nodes.guidance', 'GuidanceNode'),
    ('adcs_nodes.nodes.controller', 'ControllerNode'),
    ('adcs_nodes.nodes.controller_manager', 'ControllerManagerNode'),
    ('adcs_nodes.nodes.recorder', 'RecorderNode'),
]
#: An MPI controller needs wheels: three, one per body axis.
WHEELS = [Parameter('wheel_axes_body', value=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
          Parameter('wheel_max_torque_Nm', value=[0.1, 0.1, 0.1]),
          Parameter('wheel_max_momentum_Nms', value=[1.0, 1.0, 1.0]),
          Parameter('wheel_inertia_kgm2', value=[0.01, 0.01, 0.01])]


def _make(module, cls, ctx, tmp_path, overrides=()):
    kwargs = {'context': ctx, 'parameter_overrides': list(overrides)}
    cls, _, sensor = cls.partition(':')        # the generic sensor node: SensorNode:<sensor>
    if sensor:
        kwargs['sensor'] = sensor
    if cls == 'RecorderNode':
        names = {p.name for p in overrides}
        if 'output' not in names:
            kwargs['parameter_overrides'].append(
                Parameter('output', value=str(tmp_path / f'bag{len(list(tmp_path.iterdir()))}')))
    return getattr(importlib.import_module(module), cls)(**kwargs)


def _core(node):
    """The controller core a node steps (on its frame component, or on the node)."""
    component = getattr(node, 'component', None)
    return component.core if component is not None else node.core


class _Services:
    """The client side of a node's parameter services (what ``ros2 param`` calls)."""

    def __init__(self, ctx, spin, node):
        self.spin, self.node = spin, node
        self.probe = rclpy.create_node('param_probe', context=ctx)
        base = '/' + node.get_name()
        self.clients = {
            kind: self.probe.create_client(srv, f'{base}/{name}')
            for kind, srv, name in (('set', SetParameters, 'set_parameters'),
                                    ('describe', DescribeParameters, 'describe_parameters'),
                                    ('get', GetParameters, 'get_parameters'),
                                    ('list', ListParameters, 'list_parameters'))}
        assert spin([node, self.probe], lambda: all(
            c.service_is_ready() for c in self.clients.values()), timeout=30.0), \
            'parameter services not found'

    def _call(self, kind, request):
        future = self.clients[kind].call_async(request)
        assert self.spin([self.node, self.probe], future.done, timeout=30.0), f'no {kind} answer'
        return future.result()

    def set(self, name, text):
        """``ros2 param set <node> name text``: the result (successful, reason)."""
        request = SetParameters.Request()
        request.parameters = [ParameterMsg(name=name, value=get_parameter_value(text))]
        return self._call('set', request).results[0]

    def describe(self, names):
        request = DescribeParameters.Request()
        request.names = list(names)
        return {d.name: d for d in self._call('describe', request).descriptors}

    def get(self, names):
        request = GetParameters.Request()
        request.names = list(names)
        return self._call('get', request).values

    def names(self):
        return list(self._call('list', ListParameters.Request()).result.names)

    def close(self):
        self.probe.destroy_node()


def test_the_cli_builds_float_arrays_and_empty_lists_as_assumed():
    """The types the tests below send are the CLI's (guards the premise)."""
    assert get_parameter_value('[0.0, 1.5]').type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert get_parameter_value('[]').type == ParameterType.PARAMETER_BOOL_ARRAY
    assert get_parameter_value('2').type == ParameterType.PARAMETER_INTEGER


# ---------------------------------------------------------------------- 1: float arrays
def test_float_array_set_as_the_cli_sends_it_is_accepted_and_applied(ros_context, spin):
    """``ros2 param set /mpi_controller model_inertia_kgm2 "[...]"``: rclpy hands the
    validator an ``array.array``; it is accepted and the controller uses the new inertia from
    the next frame on (defect 1: always refused, 'expected a list')."""
    node = ControllerNode(controller='mpi', context=ros_context, parameter_overrides=[
        Parameter('period_s', value=0.1), *WHEELS])
    srv = _Services(ros_context, spin, node)
    try:
        inertia = [30.0, 1.0, 0.0, 1.0, 25.0, 0.0, 0.0, 0.0, 20.0]
        result = srv.set('model_inertia_kgm2', '[' + ', '.join(map(str, inertia)) + ']')
        assert result.successful, result.reason
        value = node.get_parameter('model_inertia_kgm2').value
        assert list(value) == inertia
        frames = node.frames
        assert spin([node, srv.probe], lambda: node.frames >= frames + 2, timeout=30.0)
        assert np.array_equal(_core(node).inertia, np.reshape(inertia, (3, 3)))
        # out of its range or of the wrong length: refused with the reason, nothing changes
        bad = srv.set('model_inertia_kgm2', '[1.0, 2.0]')
        assert not bad.successful and '9 values' in bad.reason
        assert list(node.get_parameter('model_inertia_kgm2').value) == inertia
    finally:
        srv.close()
        node.destroy_node()


# ---------------------------------------------------------------------- 2: applied or read-only
def _bdot_lockstep(ros_context, gain):
    return ControllerNode(controller='bdot', context=ros_context, parameter_overrides=[
        Parameter('timing_mode', value='lockstep'), Parameter('period_s', value=1.0),
        Parameter('magnetometer_period_s', value=1.0),
        Parameter('gain_Am2s_per_T', value=gain)])


def test_writable_gain_applies_at_the_next_frame_boundary(ros_context, spin):
    """B-dot's gain set at run time (defect 2: accepted, never applied): the frames before the
    change use the old gain, the controller is rebuilt with the new one at the next frame
    boundary (it starts from its reset state: that frame has no derivative yet, zero dipole),
    and the frame after commands twice the dipole for the same field rate."""
    node = _bdot_lockstep(ros_context, 1.0e5)
    srv = _Services(ros_context, spin, node)
    got = []
    srv.probe.create_subscription(ActuatorCommand, '/adcs/controllers/bdot/command',
                                  got.append, 100)
    mag = srv.probe.create_publisher(MagneticField, '/sensors/magnetometer', 100)
    clock = srv.probe.create_publisher(Clock, '/clock', 100)
    try:
        assert spin([node, srv.probe], lambda: mag.get_subscription_count() == 1
                    and node.pub.get_subscription_count() == 1, timeout=30.0)

        def frame(k):
            m = MagneticField()
            m.header.stamp = to_stamp(node.epoch_ns + k * S)
            m.header.frame_id = 'body'
            m.magnetic_field = to_vec3([2e-5 + 1e-6 * k, -1e-5, 3e-5 - 2e-6 * k])
            mag.publish(m)
            clock.publish(Clock(clock=to_stamp(node.epoch_ns + k * S)))
            assert spin([node, srv.probe], lambda: len(got) > k, timeout=30.0), f'frame {k}'

        frame(0)
        frame(1)
        before = np.array([got[1].dipole_body.x, got[1].dipole_body.y, got[1].dipole_body.z])
        assert np.allclose(before, -1.0e5 * np.array([1e-6, 0.0, -2e-6]))
        result = srv.set('gain_Am2s_per_T', '200000.0')
        assert result.successful, result.reason
        assert _core(node).gain == 1.0e5          # not before the frame boundary
        frame(2)
        assert _core(node).gain == 2.0e5
        assert [got[2].dipole_body.x, got[2].dipole_body.y, got[2].dipole_body.z] == [0.0] * 3
        frame(3)
        after = np.array([got[3].dipole_body.x, got[3].dipole_body.y, got[3].dipole_body.z])
        assert np.allclose(after, 2.0 * before)
        # an invalid value is refused with the reason, and nothing is rebuilt
        bad = srv.set('gain_Am2s_per_T', '-1.0')
        assert not bad.successful and '> 0' in bad.reason
        assert node.get_parameter('gain_Am2s_per_T').value == 2.0e5
    finally:
        srv.close()
        node.destroy_node()


@pytest.mark.parametrize('module, cls, name, text', [
    ('sim_node.nodes.sensor_node', 'SensorNode:magnetometer', 'period_s', '1.0'),   # the issue's
    ('sim_node.nodes.sensor_node', 'SensorNode:magnetometer', 'noise_std_T', '[1e-7, 1e-7, 1e-7]'),
    ('sim_node.nodes.dynamics', 'DynamicsNode', 'substeps', '20'),
    ('sim_node.nodes.environment', 'EnvironmentNode', 'timeout_s', '9.0'),
    ('adcs_nodes.nodes.estimator', 'EstimatorNode', 'min_field_T', '2e-6'),
    ('adcs_nodes.nodes.estimator', 'EstimatorNode', 'theta_T2', '1e-13'),
    ('adcs_nodes.nodes.guidance', 'GuidanceNode', 'period_s', '1.0'),
    ('adcs_nodes.nodes.controller_manager', 'ControllerManagerNode', 'stale_after_s', '3.0'),
    ('adcs_nodes.nodes.controller', 'ControllerNode', 'period_s', '1.0'),
    ('adcs_nodes.nodes.recorder', 'RecorderNode', 'flush_period_s', '1.0'),
])
def test_parameters_read_once_are_read_only_and_the_set_is_refused_with_the_reason(
        ros_context, spin, tmp_path, module, cls, name, text):
    """A parameter the node reads once (defect 2: the magnetometer's period_s set to 1.0 was
    accepted and it kept publishing every 10 s): read-only in its descriptor, and a set is
    refused with the reason."""
    node = _make(module, cls, ros_context, tmp_path)
    srv = _Services(ros_context, spin, node)
    try:
        before = node.get_parameter(name).value
        assert srv.describe([name])[name].read_only
        result = srv.set(name, text)
        assert not result.successful
        assert 'read-only' in result.reason and name in result.reason, result.reason
        assert node.get_parameter(name).value == before
    finally:
        srv.close()
        node.destroy_node()


# ---------------------------------------------------------------------- 3: validated specs
def test_manager_parameters_are_validated_at_run_time(ros_context, spin, tmp_path):
    """``safe:=nonexistent`` on the manager (defect 3: accepted, and the next configure
    failed): refused; the manager's parameters are typed specs, described like the
    controllers'."""
    from adcs_nodes.nodes.controller_manager import ControllerManagerNode
    node = ControllerManagerNode(context=ros_context)
    srv = _Services(ros_context, spin, node)
    try:
        result = srv.set('safe', 'nonexistent')
        assert not result.successful and 'safe' in result.reason, result.reason
        assert node.get_parameter('safe').value == 'bdot'
        wrong_type = srv.set('period_s', 'fast')
        assert not wrong_type.successful
        desc = srv.describe(['safe', 'period_s', 'controllers'])
        assert desc['safe'].type == ParameterType.PARAMETER_STRING
        assert desc['period_s'].type == ParameterType.PARAMETER_DOUBLE
        assert '[s]' in desc['period_s'].description
        assert desc['controllers'].type == ParameterType.PARAMETER_STRING_ARRAY
    finally:
        srv.close()
        node.destroy_node()


@pytest.mark.parametrize('module, cls, name, bad, why', [
    ('sim_node.nodes.dynamics', 'DynamicsNode', 'substeps', 0, '>= 1'),
    ('sim_node.nodes.dynamics', 'DynamicsNode', 'rate_factor', -1.0, '> 0'),
    ('adcs_nodes.nodes.recorder', 'RecorderNode', 'flush_period_s', 0.0, '> 0'),
    ('adcs_nodes.nodes.recorder', 'RecorderNode', 'discovery_period_s', -1.0, '> 0'),
    ('adcs_nodes.nodes.controller_manager', 'ControllerManagerNode', 'period_s', -2.0, '> 0'),
])
def test_node_parameters_outside_the_registry_are_validated_at_start(
        ros_context, tmp_path, module, cls, name, bad, why):
    """The dynamics', the manager's and the recorder's own parameters are typed specs too:
    a bad value given at start is refused naming the parameter and the rule."""
    with pytest.raises(ValueError, match=re.escape(why)):
        _make(module, cls, ros_context, tmp_path, [Parameter(name, value=bad)])


# ---------------------------------------------------------------------- 4: unknown names
def test_misspelt_name_is_refused_at_run_time_with_a_did_you_mean(ros_context, spin):
    """``ros2 param set /magnetic_controller alpha_per_sec 1e-3`` (defect 4: accepted, as
    the node allowed undeclared parameters): refused like at start-up, and not listed."""
    node = ControllerNode(controller='magnetic', context=ros_context)
    srv = _Services(ros_context, spin, node)
    try:
        result = srv.set('alpha_per_sec', '0.001')
        assert not result.successful
        assert "did you mean 'alpha_per_s'" in result.reason, result.reason
        assert 'alpha_per_sec' not in srv.names()
        assert not node.has_parameter('alpha_per_sec')
    finally:
        srv.close()
        node.destroy_node()


@pytest.mark.parametrize('module, cls', NODE_CLASSES)
def test_every_node_refuses_an_unknown_name_at_run_time(ros_context, spin, tmp_path,
                                                        module, cls):
    node = _make(module, cls, ros_context, tmp_path)
    srv = _Services(ros_context, spin, node)
    try:
        result = srv.set('no_such_parameter', '1.0')
        assert not result.successful and 'no_such_parameter' in result.reason
        assert 'no_such_parameter' not in srv.names()
    finally:
        srv.close()
        node.destroy_node()


# ---------------------------------------------------------------------- 5: empty lists
def test_empty_lists_are_typed_arrays(ros_context, spin, tmp_path):
    """``ros2 param describe`` of an empty-list parameter (defect 5: a byte array): its own
    array type, and ``ros2 param get`` gives a typed empty array."""
    node = ControllerNode(controller='magnetic', context=ros_context)
    srv = _Services(ros_context, spin, node)
    try:
        desc = srv.describe(['expected_mounts', 'wheel_axes_body', 'wheel_max_torque_Nm'])
        assert desc['expected_mounts'].type == ParameterType.PARAMETER_STRING_ARRAY
        assert desc['wheel_axes_body'].type == ParameterType.PARAMETER_DOUBLE_ARRAY
        assert desc['wheel_max_torque_Nm'].type == ParameterType.PARAMETER_DOUBLE_ARRAY
        values = srv.get(['expected_mounts', 'wheel_axes_body'])
        assert [v.type for v in values] == [ParameterType.PARAMETER_STRING_ARRAY,
                                            ParameterType.PARAMETER_DOUBLE_ARRAY]
        assert node.get_parameter('wheel_axes_body').value == []
    finally:
        srv.close()
        node.destroy_node()
    rec = _make('adcs_nodes.nodes.recorder', 'RecorderNode', ros_context, tmp_path)
    srv = _Services(ros_context, spin, rec)
    try:
        desc = srv.describe(['topics', 'expected_matches'])
        assert desc['topics'].type == ParameterType.PARAMETER_STRING_ARRAY
        assert desc['expected_matches'].type == ParameterType.PARAMETER_STRING_ARRAY
    finally:
        srv.close()
        rec.destroy_node()


def test_empty_list_set_as_the_cli_sends_it_is_typed_and_applied(ros_context, spin):
    """``ros2 param set /mpi_controller model_inertia_kgm2 "[]"`` (an empty bool array on
    the wire): accepted as the empty float array it means, and applied (the controller takes
    the onboard inertia again)."""
    node = ControllerNode(controller='mpi', context=ros_context, parameter_overrides=[
        Parameter('period_s', value=0.1),
        Parameter('model_inertia_kgm2', value=[30.0, 0.0, 0.0, 0.0, 25.0, 0.0, 0.0, 0.0, 20.0]),
        *WHEELS])
    srv = _Services(ros_context, spin, node)
    try:
        assert _core(node).inertia[0, 0] == 30.0
        result = srv.set('model_inertia_kgm2', '[]')
        assert result.successful, result.reason
        assert srv.describe(['model_inertia_kgm2'])['model_inertia_kgm2'].type == \
            ParameterType.PARAMETER_DOUBLE_ARRAY
        frames = node.frames
        assert spin([node, srv.probe], lambda: node.frames >= frames + 2, timeout=30.0)
        assert np.array_equal(_core(node).inertia, np.diag([118.0, 118.0, 19.6]))
    finally:
        srv.close()
        node.destroy_node()


# ---------------------------------------------------------------------- 6: descriptions
_UNIT = re.compile(r'\[[^\]]+\]')
_RANGE = re.compile(r'\((?:[^()]*?)(?:>|<|any |each )[^()]*\)')
_NUMBERS = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_INTEGER,
            ParameterType.PARAMETER_DOUBLE_ARRAY, ParameterType.PARAMETER_INTEGER_ARRAY)


def _undocumented(desc):
    """Names whose description lacks its unit and range, or its choices (issue 22, 6)."""
    bad = []
    for name, d in desc.items():
        if name in ('use_sim_time', 'start_type_description_service') \
                or name.startswith('qos_overrides.'):
            continue
        text = d.description
        if d.type in _NUMBERS:
            ok = bool(_UNIT.search(text)) and bool(_RANGE.search(text))
        elif d.type == ParameterType.PARAMETER_BOOL:
            ok = '(true or false)' in text
        else:
            ok = 'one of' in text or '(text' in text or '(list of text' in text
        ok = ok and 'section key' not in text
        for r in list(d.floating_point_range) + list(d.integer_range):
            ok = ok and max(abs(r.from_value), abs(r.to_value)) < 1e300 \
                and max(abs(r.from_value), abs(r.to_value)) < 2**61
            ok = ok and math.isfinite(r.from_value) and math.isfinite(r.to_value)
        if not ok:
            bad.append(f'{name}: {text!r}')
    return bad


def _graph_overrides(scenario, tmp_path):
    """``{node name: [Parameter]}`` of a scenario's graph, as the launcher passes them."""
    import os
    from adcs_nodes.tools.run.launch_graph import launch_graph
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    nodes, text = launch_graph(os.path.join(root, 'scenarios', scenario), 10.0,
                               str(tmp_path / 'bag'))
    doc = yaml.safe_load(text)

    def flat(prefix, value, out):
        if isinstance(value, dict):
            for k, v in value.items():
                flat(f'{prefix}.{k}' if prefix else k, v, out)
        else:
            out.append(Parameter(prefix, value=value))
        return out

    return [(n.module, n.cls, n.name, flat('', doc[f'/{n.name}']['ros__parameters'], []))
            for n in nodes]


@pytest.mark.parametrize('module, cls', NODE_CLASSES)
def test_every_parameter_has_its_unit_and_range_or_its_choices(ros_context, tmp_path,
                                                               module, cls):
    """What ``ros2 param describe`` prints, for a node started alone (defect 6: placeholder
    descriptions, half-open ranges printed as -1e+308)."""
    node = _make(module, cls, ros_context, tmp_path)
    try:
        desc = {d.name: d for d in node.describe_parameters(sorted(node._parameters))}
        assert _undocumented(desc) == []
    finally:
        node.destroy_node()


@pytest.mark.parametrize('scenario', ['paper000_control.yaml', 'paper001_mpi.yaml',
                                      'iss_tle_tumble.yaml'])
def test_every_parameter_of_a_launched_graph_is_described(ros_context, tmp_path, scenario):
    """The same with the launcher's parameters: the sections (``orbit.*``, ``field.*``,
    ``onboard_orbit.*``, ``spacecraft.*``, ``initial.*``) are described key by key."""
    for module, cls, name, overrides in _graph_overrides(scenario, tmp_path):
        ctor = getattr(importlib.import_module(module), cls)
        kwargs = {'context': ros_context, 'parameter_overrides': overrides}
        if cls in ('ControllerNode', 'SensorNode'):
            kwargs['name'] = name
        node = ctor(**kwargs)
        try:
            desc = {d.name: d for d in node.describe_parameters(sorted(node._parameters))}
            sections = [n for n in desc if '.' in n and not n.startswith('qos_overrides.')]
            assert _undocumented(desc) == [], (name, sections)
        finally:
            node.destroy_node()


def test_array_parameter_values_keep_their_length_rule(ros_context, spin):
    """A float array with a length rule, set as the CLI sends it with the wrong length, is
    refused with the reason (the validator sees the ``array.array``)."""
    node = ControllerNode(controller='fuzzy', context=ros_context, parameter_overrides=[
        Parameter('period_s', value=0.1)])
    srv = _Services(ros_context, spin, node)
    try:
        ok = srv.set('phi_peaks_deg', '[0.0, 3.0, 12.0, 35.0, 90.0]')
        assert ok.successful, ok.reason
        assert isinstance(node.get_parameter('phi_peaks_deg').value, (list, array.array))
        bad = srv.set('phi_peaks_deg', '[0.0, 3.0]')
        assert not bad.successful and '5 values' in bad.reason
    finally:
        srv.close()
        node.destroy_node()


def test_docs_list_the_parameters_writable_at_run_time():
    """docs/topics.md, section 'Run-time parameters': the table generated from the specs."""
    import os
    from adcs_nodes.nodes.params import writable_markdown
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(root, 'docs', 'topics.md'), encoding='utf-8') as fh:
        assert writable_markdown() in fh.read(), \
            'regenerate the table: ros2_ws/run.sh python -m adcs_nodes.nodes.params'


def test_misspelt_section_key_is_refused_at_start_with_a_did_you_mean(ros_context):
    """Section keys (here the manager's automatic sequence, ``auto.*``) are spec'd too."""
    from adcs_nodes.nodes.controller_manager import ControllerManagerNode
    with pytest.raises(ValueError, match=re.escape("(did you mean 'auto.rate_enter_deg_s'?)")):
        ControllerManagerNode(context=ros_context, parameter_overrides=[
            Parameter('auto.rate_entr_deg_s', value=0.5)])
