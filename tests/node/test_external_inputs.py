"""Sample timing for an external sensor in a lockstep graph (issue 23, defects 2 and 3): the
estimator started by the launcher with ``external_inputs: [mag]`` (what the graph builder
gives it for ``sensors.magnetometer.external: true``, or for every sensor with
``--real-time``) uses every good sample once, at its own off-grid stamp, in stamp order (a
frame takes the samples up to one period before it, so a sample in transit when its frame
fires is not lost); a sample that arrives after the frame that took its interval is rejected
as late and never used; estimates stay on the frame grid.

Driven through the node's own callbacks (``/clock`` ticks and the driver's samples), so the
logic is tested without transport timing; the subscription's QoS accepts a best-effort
driver (checked on the endpoint).
"""
import numpy as np
from rclpy.parameter import Parameter
from rclpy.qos import ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import MagneticField

from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.nodes.convert import to_stamp, to_vec3
from adcs_nodes.nodes.estimator import DEFAULT_FIELD, DEFAULT_ORBIT, EstimatorNode

S = 10**9


def _sample(ref, epoch_ns, t_ns):
    m = MagneticField()
    m.header.stamp = to_stamp(epoch_ns + t_ns)
    m.header.frame_id = 'body'
    m.magnetic_field = to_vec3(ref.at(t_ns / S).b_orbit)
    return m


def _clock(node, t_ns):
    c = Clock()
    c.clock = to_stamp(node.epoch_ns + t_ns)
    node._on_clock_tick(c)


def test_external_samples_are_used_once_at_their_own_stamps(ros_context):
    est = []
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('timing_mode', value='lockstep'), Parameter('period_s', value=2.0),
        Parameter('magnetometer_period_s', value=10.0),
        Parameter('external_inputs', value=['mag'])])
    node.est_pub.publish = est.append                      # what the node publishes
    assert node.external == {'mag'}
    sub = node._subs['/sensors/magnetometer']
    assert sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    ref = make_onboard_reference(DEFAULT_ORBIT, DEFAULT_FIELD, node.epoch)
    cb = node._external_cb('mag')
    _clock(node, 0)                                         # frame 0: initialisation
    stamps = [int(1.3 * S), int(2.9 * S), int(3.4 * S), int(7.3 * S)]   # off the 2 s grid
    cb(_sample(ref, node.epoch_ns, stamps[0]))
    _clock(node, 2 * S)            # a frame takes the samples up to one period before it
    assert node.update_count == 0
    _clock(node, 4 * S)                                     # ... so 1.3 s comes here
    assert node.update_count == 1
    cb(_sample(ref, node.epoch_ns, stamps[1]))
    cb(_sample(ref, node.epoch_ns, stamps[2]))
    _clock(node, 6 * S)                                     # 2.9 and 3.4 s, in order
    assert node.update_count == 3
    late = _sample(ref, node.epoch_ns, int(3.9 * S))        # its interval was taken at 6 s:
    cb(late)                                                # late
    assert node.rejected_samples['late'] == 1
    cb(_sample(ref, node.epoch_ns, stamps[3]))              # taken at 7.3 s, sent at once
    _clock(node, 8 * S)
    assert node.update_count == 3                           # 7.3 s is not covered yet
    _clock(node, 10 * S)
    assert node.update_count == 4            # each sample once, the late one never
    assert [m.header.stamp.sec - node.epoch_ns // S for m in est] == [0, 2, 4, 6, 8, 10]
    q = [np.array([m.q_orbit_body.x, m.q_orbit_body.y, m.q_orbit_body.z, m.q_orbit_body.w])
         for m in est]
    assert all(np.all(np.isfinite(v)) for v in q)
    node.destroy_node()


def test_bad_external_samples_are_rejected_by_reason(ros_context):
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('timing_mode', value='lockstep'), Parameter('period_s', value=2.0),
        Parameter('external_inputs', value=['mag'])])
    ref = make_onboard_reference(DEFAULT_ORBIT, DEFAULT_FIELD, node.epoch)
    cb = node._external_cb('mag')
    _clock(node, 100 * S)
    cb(_sample(ref, 0, 0))                                  # zero stamp
    cb(_sample(ref, node.epoch_ns, 200 * S))                # 100 s in the future
    cb(_sample(ref, node.epoch_ns, 99 * S))
    cb(_sample(ref, node.epoch_ns, 98 * S))                 # older than the one before
    r = node.rejected_samples
    assert (r['zero_stamp'], r['future'], r['out_of_order']) == (1, 1, 1)
    node.destroy_node()
