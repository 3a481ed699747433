"""The environment node runs one frame ahead in a launched lockstep run (issue 13): every frame
of the run is published exactly once, none past the duration, and a frame published ahead has
the same contents as the one a node without run-ahead publishes on that frame's clock."""
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from adcs_msgs.msg import Environment
from adcs_nodes.msgs.fields import stamp_ns, to_stamp
from sim_node.nodes.environment import EnvironmentNode

EPOCH_NS = 1767225600 * 10**9          # 2026-01-01T00:00:00Z
S = 10**9
ORBIT = {'orbit.type': 'circular', 'orbit.altitude_km': 690.0, 'orbit.inclination_deg': 98.0,
         'orbit.raan_deg': 30.0, 'orbit.arg_latitude0_deg': 10.0, 'field.model': 'dipole'}


def _env(ctx, name, **extra):
    return EnvironmentNode(name, context=ctx, parameter_overrides=[
        Parameter(k, value=v) for k, v in {**ORBIT, **extra}.items()])


def _fields(m):
    return (m.r_eci, m.v_eci, m.q_eci_orbit, m.omega_orbit_eci_eci, m.orbit_rate,
            m.argument_of_latitude, m.b_eci, m.b_dot_eci, m.q_eci_ecef)


def test_each_frame_once_one_ahead_never_past_the_duration(ros_context, spin):
    import rclpy
    ahead = _env(ros_context, 'environment', duration_s=3.0, frame_period_s=1.0)
    alone = _env(ros_context, 'environment_alone')
    alone_pub = alone.pub
    probe = rclpy.create_node('probe', context=ros_context)
    got, ref = [], []
    probe.create_subscription(Environment, 'sim/environment', got.append, 100)
    clock = probe.create_publisher(Clock, '/clock', 10)
    assert spin([ahead, alone, probe], lambda: clock.get_subscription_count() >= 2
                and ahead.pub.get_subscription_count() >= 1)
    # the node without run-ahead answers each tick only: keep its messages apart
    alone_pub.publish = ref.append
    expected = {0: [0, 1], 1: [0, 1, 2], 2: [0, 1, 2, 3], 3: [0, 1, 2, 3]}
    for k in range(4):
        clock.publish(Clock(clock=to_stamp(EPOCH_NS + k * S)))
        assert spin([ahead, alone, probe], lambda: len(got) >= len(expected[k])
                    and len(ref) >= k + 1)
        spin([ahead, alone, probe], lambda: False, timeout=0.2)
        assert [(stamp_ns(m.header.stamp) - EPOCH_NS) // S for m in got] == expected[k]
    assert [(stamp_ns(m.header.stamp) - EPOCH_NS) // S for m in ref] == [0, 1, 2, 3]
    for mine, theirs in zip(got, ref):
        assert _fields(mine) == _fields(theirs)      # exact equality, field by field
    for node in (probe, ahead, alone):
        node.destroy_node()
