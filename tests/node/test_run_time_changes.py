"""Run-time changes as ``ros2 param set`` / ``ros2 param load`` send them (issue 37, item 7).

* Setting a controller parameter to the value it has, or loading a dump of the node's own
  parameters, changes nothing: B-dot keeps its field history, so the next frame's dipole is
  still ``m = -k dB/dt`` from the last two samples (before, the controller was rebuilt from its
  reset state and commanded zero).
* ``use_sim_time`` switched at run time is refused with the reason (before, the node's clock
  moved from wall time to ``/clock`` without a word).

The services are the standard ones (``SetParameters``), called from a probe node with the
values built as the CLI builds them; waits are deadlines.
"""
import numpy as np
import rclpy
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.srv import DescribeParameters, ListParameters, SetParameters
from rclpy.parameter import Parameter, get_parameter_value
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import MagneticField

from adcs_msgs.msg import ActuatorCommand
from adcs_nodes.nodes.controller import ControllerNode
from adcs_nodes.msgs.fields import to_stamp, to_vec3

S = 10**9
GAIN = 1.0e5                                    # B-dot gain k [A m^2 s / T]


def _field(k):
    """The body field at frame k [T]: dB/dt = (1e-6, 0, -2e-6) T/s."""
    return np.array([2e-5 + 1e-6 * k, -1e-5, 3e-5 - 2e-6 * k])


class _Rig:
    """A lockstep B-dot node, a probe with its parameter clients, a magnetometer and a clock."""

    def __init__(self, ctx, spin):
        self.spin = spin
        self.node = ControllerNode(controller='bdot', context=ctx, parameter_overrides=[
            Parameter('timing_mode', value='lockstep'), Parameter('period_s', value=1.0),
            Parameter('magnetometer_period_s', value=1.0),
            Parameter('gain_Am2s_per_T', value=GAIN)])
        self.probe = rclpy.create_node('param_cli', context=ctx)
        base = '/' + self.node.get_name()
        self.clients = {n: self.probe.create_client(t, f'{base}/{n}') for n, t in (
            ('set_parameters', SetParameters), ('list_parameters', ListParameters),
            ('describe_parameters', DescribeParameters))}
        self.got = []
        self.probe.create_subscription(ActuatorCommand, '/adcs/controllers/bdot/command',
                                       self.got.append, 100)
        self.mag = self.probe.create_publisher(MagneticField, '/sensors/magnetometer', 100)
        self.clock = self.probe.create_publisher(Clock, '/clock', 100)
        assert spin([self.node, self.probe], lambda: all(
            c.service_is_ready() for c in self.clients.values())
            and self.mag.get_subscription_count() == 1
            and self.node.pub.get_subscription_count() == 1), 'not matched'

    def call(self, name, request):
        future = self.clients[name].call_async(request)
        assert self.spin([self.node, self.probe], future.done), f'no {name} answer'
        return future.result()

    def set(self, pairs):
        """``ros2 param set`` (one pair) or ``ros2 param load`` (all): the results."""
        request = SetParameters.Request()
        request.parameters = [ParameterMsg(name=n, value=get_parameter_value(t))
                              for n, t in pairs]
        return self.call('set_parameters', request).results

    def frame(self, k):
        m = MagneticField()
        m.header.stamp = to_stamp(self.node.epoch_ns + k * S)
        m.header.frame_id = 'body'
        m.magnetic_field = to_vec3(_field(k))
        self.mag.publish(m)
        self.clock.publish(Clock(clock=to_stamp(self.node.epoch_ns + k * S)))
        assert self.spin([self.node, self.probe], lambda: len(self.got) > k), f'frame {k}'
        d = self.got[k].dipole_body
        return np.array([d.x, d.y, d.z])

    def close(self):
        self.probe.destroy_node()
        self.node.destroy_node()


def test_setting_or_loading_the_current_values_does_not_reset_the_controller(ros_context, spin):
    rig = _Rig(ros_context, spin)
    try:
        want = -GAIN * (_field(1) - _field(0))          # m = -k dB/dt, dt = 1 s
        rig.frame(0)
        assert np.allclose(rig.frame(1), want, rtol=1e-9, atol=0.0)
        (result,) = rig.set([('gain_Am2s_per_T', repr(GAIN))])     # ros2 param set, same
        assert result.successful, result.reason
        assert np.allclose(rig.frame(2), want, rtol=1e-9, atol=0.0)    # not reset: not zero
        # ros2 param load of the node's own dump: every writable parameter, as it is
        names = rig.call('list_parameters', ListParameters.Request()).result.names
        request = DescribeParameters.Request()
        request.names = list(names)
        writable = [d.name for d in rig.call('describe_parameters', request).descriptors
                    if not d.read_only and d.name != 'use_sim_time']
        assert 'gain_Am2s_per_T' in writable
        results = rig.set([(n, repr(rig.node.get_parameter(n).value)) for n in writable])
        assert all(r.successful for r in results), [r.reason for r in results]
        assert np.allclose(rig.frame(3), want, rtol=1e-9, atol=0.0)
        # a changed value is applied, from its reset state (the documented behaviour)
        (result,) = rig.set([('gain_Am2s_per_T', repr(2 * GAIN))])
        assert result.successful, result.reason
        assert np.array_equal(rig.frame(4), np.zeros(3))
        assert np.allclose(rig.frame(5), 2 * want, rtol=1e-9, atol=0.0)
    finally:
        rig.close()


def test_use_sim_time_switched_at_run_time_is_refused_with_the_reason(ros_context, spin):
    rig = _Rig(ros_context, spin)
    try:
        (result,) = rig.set([('use_sim_time', 'true')])
        assert not result.successful
        assert 'use_sim_time' in result.reason and 'start-up' in result.reason, result.reason
        assert rig.node.get_parameter('use_sim_time').value is False
        assert not rig.node.get_clock().ros_time_is_active
        (result,) = rig.set([('use_sim_time', 'false')])      # as it is: nothing to refuse
        assert result.successful, result.reason
    finally:
        rig.close()
