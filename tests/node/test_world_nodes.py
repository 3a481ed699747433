"""environment and dynamics nodes in process: outputs, stamps, timeouts, bad input."""
import math

import numpy as np
import pytest
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from adcs_msgs.msg import ActuatorCommand, AttitudeState, Environment
from adcs_nodes.core import attitude as att
from adcs_nodes.msgs.fields import quat, stamp_ns, to_stamp, vec3
from sim_node.nodes.dynamics import DynamicsNode
from sim_node.nodes.environment import EnvironmentNode

MU = 3.986004418e14
EPOCH_NS = 1767225600 * 10**9          # 2026-01-01T00:00:00Z


def params(**kw):
    return [Parameter(k, value=v) for k, v in kw.items()]


def collector(node, msg_type, topic):
    got = []
    node.create_subscription(msg_type, topic, got.append, 100)
    return got


def test_environment_answers_each_clock_with_the_circular_orbit(ros_context, spin):
    env = EnvironmentNode(context=ros_context, parameter_overrides=params(
        **{'orbit.type': 'circular', 'orbit.altitude_km': 690.0, 'orbit.inclination_deg': 98.0,
           'orbit.raan_deg': 30.0, 'orbit.arg_latitude0_deg': 10.0, 'field.model': 'dipole'}))
    probe = rclpy_node(ros_context, 'probe')
    got = collector(probe, Environment, 'sim/environment')
    clock = probe.create_publisher(Clock, '/clock', 10)
    assert spin([env, probe], lambda: clock.get_subscription_count() > 0, timeout=30.0)
    # a duplicate tick is ignored; the answer to the last tick comes after any answer to the
    # ticks before it (one publisher, in order), so no wait for "nothing more" is needed
    for k in (0, 0, 100, 200):
        clock.publish(Clock(clock=to_stamp(EPOCH_NS + k * 10**9)))
    assert spin([env, probe], lambda: len(got) >= 3, timeout=30.0)
    stamps = [stamp_ns(m.header.stamp) - EPOCH_NS for m in got]
    assert stamps == [0, 100 * 10**9, 200 * 10**9]
    # independent truth: circular orbit in closed form, u = u0 + n t
    a = 6378137.0 + 690e3
    n = math.sqrt(MU / a**3)
    u, inc, raan = math.radians(10.0) + n * 100.0, math.radians(98.0), math.radians(30.0)
    r = a * np.array([math.cos(u) * math.cos(raan) - math.sin(u) * math.cos(inc) * math.sin(raan),
                      math.cos(u) * math.sin(raan) + math.sin(u) * math.cos(inc) * math.cos(raan),
                      math.sin(u) * math.sin(inc)])
    m = got[1]
    assert np.allclose(vec3(m.r_eci), r, rtol=0, atol=1e-3)
    assert m.argument_of_latitude == pytest.approx(u % (2 * math.pi), abs=1e-9)
    assert m.orbit_rate == pytest.approx(n, rel=1e-9)
    # orbit frame: z = zenith, y = orbit normal
    rot = att.to_matrix(quat(m.q_eci_orbit))
    assert np.allclose(rot[:, 2], r / a, atol=1e-9)
    h = np.cross(r, vec3(m.v_eci))
    assert np.allclose(rot[:, 1], h / np.linalg.norm(h), atol=1e-9)
    assert 15e-6 < np.linalg.norm(vec3(m.b_eci)) < 60e-6
    probe.destroy_node()
    env.destroy_node()


def rclpy_node(ctx, name):
    import rclpy
    return rclpy.create_node(name, context=ctx)


def test_dynamics_goes_on_when_the_environment_stops(ros_context, spin):
    """Missing input past timeout_s: counted, logged, last environment used, no hang."""
    env = EnvironmentNode(context=ros_context)
    dyn = DynamicsNode(context=ros_context, parameter_overrides=params(
        duration_s=8.0, timeout_s=0.3, substeps=2,
        **{'initial.omega_body_eci_body_deg_s': [0.6, -1.2, 1.8]}))
    probe = rclpy_node(ros_context, 'probe')
    states = collector(probe, AttitudeState, 'sim/state')
    ok = spin([env, dyn, probe], lambda: len(states) >= 3, timeout=30.0)
    assert ok, 'lockstep did not start'
    env.destroy_node()                      # the environment dies after frame 2 or so
    assert spin([dyn, probe], lambda: dyn.done, timeout=60.0), 'dynamics hung'
    # the last states are still on their way to the probe (was: a fixed 0.3 s spin)
    assert spin([probe], lambda: len(states) >= 9, timeout=30.0), len(states)
    assert dyn.missed_frames >= 4
    assert 'sim/environment' in dyn.last_missed_input
    stamps = [stamp_ns(s.header.stamp) - EPOCH_NS for s in states]
    assert stamps == [k * 10**9 for k in range(9)]      # every frame 0..8 s published
    for s in states:
        assert np.all(np.isfinite(quat(s.q_eci_body)))
    probe.destroy_node()
    dyn.destroy_node()


def test_nan_command_is_rejected_as_zero(ros_context, spin):
    env = EnvironmentNode(context=ros_context)
    # timeout_s 60: each command is sent from the spin's condition after its state came;
    # no input may time out (missed_frames 0) however slow this process is under load
    dyn = DynamicsNode(context=ros_context, parameter_overrides=params(
        duration_s=3.0, timeout_s=60.0, command_period_s=1.0,
        **{'spacecraft.magnetorquer.max_dipole_Am2': [10.0, 10.0, 10.0]}))
    probe = rclpy_node(ros_context, 'probe')
    states = collector(probe, AttitudeState, 'sim/state')
    cmd_pub = probe.create_publisher(ActuatorCommand, 'adcs/actuator_command', 10)
    sent = set()

    def answer():
        for s in states:
            t = stamp_ns(s.header.stamp)
            if t not in sent:
                sent.add(t)
                c = ActuatorCommand(source='bad')
                c.header.stamp = s.header.stamp
                c.dipole_body.x = float('nan')
                cmd_pub.publish(c)
        return dyn.done

    assert spin([env, dyn, probe], answer, timeout=60.0)
    assert dyn.rejected_commands == 3
    assert dyn.missed_frames == 0
    assert np.all(np.isfinite(dyn.state.omega_body_eci_body))
    probe.destroy_node()
    dyn.destroy_node()
    env.destroy_node()
