"""estimator node in process: fed synthetic magnetometer samples and /clock, it publishes
one estimate per period at exactly the frame stamps, rejects bad samples, never NaN."""
import numpy as np
import rclpy
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import MagneticField

from adcs_msgs.msg import AttitudeState, FilterDiagnostics
from adcs_nodes.core import attitude as att
from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.msgs.fields import stamp_ns, to_stamp, to_vec3
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.nodes.estimator import EstimatorNode
from adcs_nodes.nodes.lockstep_node import parse_epoch

EPOCH_NS = 1767225600 * 10**9
S = 10**9


def test_estimates_at_the_frame_stamps_and_bad_samples_rejected(ros_context, spin):
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('period_s', value=2.0), Parameter('magnetometer_period_s', value=4.0),
        Parameter('frame_period_s', value=2.0), Parameter('timeout_s', value=5.0)])
    probe = rclpy.create_node('probe', context=ros_context)
    est, diag = [], []
    probe.create_subscription(AttitudeState, 'adcs/attitude_estimate', est.append, 100)
    probe.create_subscription(FilterDiagnostics, 'adcs/estimator/diagnostics', diag.append,
                              100)
    clock = probe.create_publisher(Clock, '/clock', 100)
    mag = probe.create_publisher(MagneticField, 'sensors/magnetometer', 100)
    assert spin([node, probe], lambda: clock.get_subscription_count()
                and mag.get_subscription_count())
    # the truth: the body sits on the orbit frame; field from the node's own reference model
    ref = make_onboard_reference(ORBIT.defaults(), FIELD.defaults(),
                                 parse_epoch('2026-01-01T00:00:00Z'))
    for k in range(6):                               # frames 0, 2, ..., 10 s
        t = 2 * k
        clock.publish(Clock(clock=to_stamp(EPOCH_NS + t * S)))
        if t % 4 == 0:
            m = MagneticField()
            m.header.stamp = to_stamp(EPOCH_NS + t * S)
            b = ref.at(float(t)).b_orbit
            if t == 8:
                b = np.array([np.nan, 0.0, 0.0])     # a bad sample
            m.magnetic_field = to_vec3(b)
            mag.publish(m)
    assert spin([node, probe], lambda: len(est) >= 6, timeout=30.0)
    stamps = [(stamp_ns(m.header.stamp) - EPOCH_NS) / S for m in est]
    assert stamps == [0, 2, 4, 6, 8, 10]
    for m in est:
        q = [m.q_orbit_body.x, m.q_orbit_body.y, m.q_orbit_body.z, m.q_orbit_body.w]
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(m.covariance))
        q_eci_orbit = ref.at((stamp_ns(m.header.stamp) - EPOCH_NS) / S).q_eci_orbit
        q_eci = [m.q_eci_body.x, m.q_eci_body.y, m.q_eci_body.z, m.q_eci_body.w]
        assert att.angle_between(att.multiply(q_eci_orbit, q), q_eci) < 1e-9
    assert diag[-1].update_count == 2 and diag[-1].rejected_count == 1
    assert 'not finite' in diag[-1].last_rejection
    probe.destroy_node()
    node.destroy_node()
