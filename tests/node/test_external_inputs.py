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
import time

import numpy as np
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import MagneticField

from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.core import handshake
from adcs_nodes.msgs.fields import to_stamp, to_vec3
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.nodes.estimator import EstimatorNode

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
    node.timing.on_clock_tick(c)


def test_external_samples_are_used_once_at_their_own_stamps(ros_context):
    est = []
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('timing_mode', value='lockstep'), Parameter('period_s', value=2.0),
        Parameter('magnetometer_period_s', value=10.0),
        Parameter('external_inputs', value=['mag'])])
    node.est_pub.publish = est.append                      # what the node publishes
    assert set(node.external) == {'mag'}
    sub = node._subs['/sensors/magnetometer']
    assert sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    ref = make_onboard_reference(ORBIT.defaults(), FIELD.defaults(), node.epoch)
    cb = node.timing.external_cb('mag')
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
    assert node.counts.rejected['late'] == 1
    cb(_sample(ref, node.epoch_ns, stamps[3]))              # taken at 7.3 s, sent at once
    _clock(node, 8 * S)
    assert node.update_count == 3                           # 7.3 s is not covered yet
    _clock(node, 10 * S)
    assert node.update_count == 4            # each sample once, the late one never
    assert [m.header.stamp.sec - node.epoch_ns // S for m in est] == [0, 2, 4, 6, 8, 10]
    summary = node.run_summary()             # what the launcher prints for this node
    assert summary['samples_used'] == {'/sensors/magnetometer': 4}
    assert summary['rejected'] == {'late': 1} and summary['superseded'] == 0
    assert summary['resets'] == 0 and summary['starved'] == {}
    q = [np.array([m.q_orbit_body.x, m.q_orbit_body.y, m.q_orbit_body.z, m.q_orbit_body.w])
         for m in est]
    assert all(np.all(np.isfinite(v)) for v in q)
    node.destroy_node()


def test_bad_external_samples_are_rejected_by_reason(ros_context):
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('timing_mode', value='lockstep'), Parameter('period_s', value=2.0),
        Parameter('external_inputs', value=['mag'])])
    ref = make_onboard_reference(ORBIT.defaults(), FIELD.defaults(), node.epoch)
    cb = node.timing.external_cb('mag')
    _clock(node, 100 * S)
    cb(_sample(ref, 0, 0))                                  # zero stamp
    cb(_sample(ref, node.epoch_ns, 200 * S))                # 100 s in the future
    cb(_sample(ref, node.epoch_ns, 99 * S))
    cb(_sample(ref, node.epoch_ns, 98 * S))                 # older than the one before
    r = node.counts.rejected
    assert (r['zero_stamp'], r['future'], r['out_of_order']) == (1, 1, 1)
    node.destroy_node()


def test_a_starved_external_input_is_named_and_recovers(ros_context):
    """Nothing usable for dead_after_frames (3) periods of the input (10 s declared, longer
    than the node's 2 s): starved, with the topic; a NaN sample is not usable; a good one
    ends the episode."""
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('timing_mode', value='lockstep'), Parameter('period_s', value=2.0),
        Parameter('magnetometer_period_s', value=10.0),
        Parameter('external_inputs', value=['mag'])])
    ref = make_onboard_reference(ORBIT.defaults(), FIELD.defaults(), node.epoch)
    cb = node.timing.external_cb('mag')
    for k in range(16):                                     # 0 .. 30 s: not yet
        _clock(node, 2 * k * S)
    assert node.external.starved == {}
    _clock(node, 32 * S)                                    # 32 s > 3 x 10 s
    assert node.run_summary()['starved'] == {'/sensors/magnetometer': {'since_s': 0.0,
                                                                       'frames': 1}}
    assert node.timing_diagnostics()['starved_inputs'] == '/sensors/magnetometer'
    nan = _sample(ref, node.epoch_ns, 33 * S)
    nan.magnetic_field.x = float('nan')
    cb(nan)
    _clock(node, 34 * S)
    _clock(node, 36 * S)                                    # the NaN taken: not usable
    assert node.external.starved['mag']['frames'] == 3
    assert node.run_summary()['rejected'].get('check') == 1
    cb(_sample(ref, node.epoch_ns, 37 * S))
    _clock(node, 38 * S)
    _clock(node, 40 * S)                                    # used at 40 s: over
    assert node.timing_diagnostics()['starved_inputs'] == ''
    assert node.run_summary()['starved']['/sensors/magnetometer']['frames'] == 4
    assert node.run_summary()['samples_used'] == {'/sensors/magnetometer': 1}
    node.destroy_node()


def test_the_handshake_waits_for_the_external_publisher(ros_context, monkeypatch):
    """Not ready while no publisher is matched on the external topic (best effort or
    reliable, any QoS); ready once one is; after EXTERNAL_WAIT_S it starts without it."""
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('timing_mode', value='lockstep'), Parameter('period_s', value=2.0),
        Parameter('external_inputs', value=['mag'])])
    assert node.handshake.external_unmatched() == ['/sensors/magnetometer']
    assert node.unmatched() == []          # not an endpoint the self-healing restarts for
    driver = rclpy.create_node('a_driver', context=ros_context)
    driver.create_publisher(MagneticField, 'sensors/magnetometer', 10)      # reliable
    deadline = time.monotonic() + 30.0
    while node.handshake.external_unmatched() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert node.handshake.external_unmatched() == []
    driver.destroy_node()
    deadline = time.monotonic() + 30.0
    while not node.handshake.external_unmatched() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert node.handshake.external_unmatched() == ['/sensors/magnetometer']          # gone again
    monkeypatch.setattr(handshake, 'EXTERNAL_WAIT_S', 0.0)
    deadline = time.monotonic() + 30.0
    while node.handshake.external_unmatched() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert node.handshake.driver_wait.gave_up and node.handshake.external_unmatched() == []
    node.destroy_node()


def test_a_live_sample_replaced_before_a_tick_is_superseded(ros_context):
    """Live mode uses the newest sample per tick: one replaced before any tick read it is
    superseded (counted), one a tick read is not."""
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('period_s', value=1.0), Parameter('max_sample_age_s', value=1e9),
        Parameter('max_future_s', value=1e9)])
    assert node.timing_mode == 'live'
    ref = make_onboard_reference(ORBIT.defaults(), FIELD.defaults(), node.epoch)
    cb = node.timing.live_cb('mag')
    now = node.get_clock().now().nanoseconds
    cb(_sample(ref, node.epoch_ns, now - 3 * S - node.epoch_ns))
    cb(_sample(ref, node.epoch_ns, now - 2 * S - node.epoch_ns))   # replaces the first
    assert node.counts.superseded == 1
    node.timing.live_tick()                                              # reads the second
    cb(_sample(ref, node.epoch_ns, now - 1 * S - node.epoch_ns))   # the second was read
    assert node.counts.superseded == 1
    assert node.run_summary()['superseded'] == 1
    node.destroy_node()
