"""Sensor nodes in process: outputs against truth, stamps, periods, frame ids, bad input.

Truth is built here independently of the nodes: attitudes with scipy's ``Rotation`` and
``attitude.from_euler_321``, the field in body axes as ``R_eci_body^T b_eci``.
"""
import functools
import math
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu, MagneticField

from adcs_msgs.msg import AttitudeState, Environment, HorizonSensor
from adcs_nodes.core import attitude as att
from adcs_nodes.core.lockstep import derive_seed
from domains import worker_domain
from adcs_nodes.tools.run.launcher import child_env
from adcs_nodes.msgs.fields import quat, stamp_ns, to_quat, to_stamp, to_vec3, vec3
from sim_node.models.sensors import StarTracker
from sim_node.nodes.sensor_node import SensorNode

#: The generic sensor node with each built-in sensor (``ros2 run sim_node gyro`` etc.).
GyroNode = functools.partial(SensorNode, sensor='gyro')
HorizonSensorNode = functools.partial(SensorNode, sensor='horizon_sensor')
MagnetometerNode = functools.partial(SensorNode, sensor='magnetometer')
StarTrackerNode = functools.partial(SensorNode, sensor='star_tracker')

EPOCH_NS = 1767225600 * 10**9          # 2026-01-01T00:00:00Z
S = 10**9
DEG = math.pi / 180.0
R_ECI_ORBIT = Rotation.from_euler('zxz', [30, 98, 10], degrees=True)   # RAAN, i, u
B_ECI = np.array([12e-6, -25e-6, 31e-6])
W_BODY = np.array([0.01, -0.02, 0.03])
EPS = np.finfo(float).eps


def params(**kw):
    return [Parameter(k, value=v) for k, v in kw.items()]


def truth(t_s, q_orbit_body=None, nan=None):
    """(state, env) messages stamped t_s with the given orbit-relative attitude."""
    if q_orbit_body is None:
        q_orbit_body = att.from_euler_321(0.1 * t_s, -0.05, 0.3 + 0.2 * t_s)
    r_eci_body = R_ECI_ORBIT * Rotation.from_quat(q_orbit_body)
    stamp = to_stamp(EPOCH_NS + int(t_s * S))
    st = AttitudeState()
    st.header.stamp, st.header.frame_id = stamp, 'body'
    st.q_eci_body = to_quat(r_eci_body.as_quat())
    st.q_orbit_body = to_quat(q_orbit_body)
    st.omega_body_eci_body = to_vec3(W_BODY)
    env = Environment()
    env.header.stamp, env.header.frame_id = stamp, 'eci'
    env.r_eci = to_vec3(7.0e6 * R_ECI_ORBIT.as_matrix()[:, 2])
    env.q_eci_orbit = to_quat(R_ECI_ORBIT.as_quat())
    env.b_eci = to_vec3(B_ECI)
    if nan == 'state':
        st.q_eci_body.x = float('nan')
        st.omega_body_eci_body.y = float('nan')
    elif nan == 'env':
        env.b_eci.x = float('nan')
        env.r_eci.z = float('nan')
    return st, env, r_eci_body


class Rig:
    """A probe node feeding sim/state + sim/environment and collecting the sensor topic."""

    def __init__(self, ctx, spin, node, msg_type, topic):
        self.node, self.spin = node, spin
        self.probe = rclpy.create_node('probe', context=ctx)
        self.got = []
        self.probe.create_subscription(msg_type, topic, self.got.append, 100)
        self.state_pub = self.probe.create_publisher(AttitudeState, 'sim/state', 100)
        self.env_pub = self.probe.create_publisher(Environment, 'sim/environment', 100)
        needs_env = 'env' in node.sync.names
        assert spin([node, self.probe], lambda: (
            node.pub.get_subscription_count() > 0 and self.state_pub.get_subscription_count() > 0
            and (not needs_env or self.env_pub.get_subscription_count() > 0)))

    def feed(self, frames, expect):
        """Publish (state, env) per frame; spin until ``expect`` outputs (then a bit more)."""
        for st, env in frames:
            self.env_pub.publish(env)
            self.state_pub.publish(st)
        ok = self.spin([self.node, self.probe], lambda: len(self.got) >= expect, timeout=30.0)
        self.spin([self.node, self.probe], lambda: False, timeout=0.3)
        return ok

    def stamps(self):
        return [(stamp_ns(m.header.stamp) - EPOCH_NS) / S for m in self.got]

    def close(self):
        self.probe.destroy_node()
        self.node.destroy_node()


def test_magnetometer_period_stamps_and_field(ros_context, spin):
    std = np.array([1e-9, 2e-9, 3e-9])
    node = MagnetometerNode(context=ros_context, parameter_overrides=params(
        period_s=2.0, noise_std_T=std.tolist(), lsb_T=0.0))
    rig = Rig(ros_context, spin, node, MagneticField, 'sensors/magnetometer')
    frames = [truth(t) for t in range(6)]
    assert rig.feed([f[:2] for f in frames], 3)
    assert rig.stamps() == [0.0, 2.0, 4.0]                 # never at 1, 3, 5
    for m, t in zip(rig.got, (0, 2, 4)):
        b_body = frames[t][2].inv().apply(B_ECI)
        assert m.header.frame_id == 'magnetometer'
        assert np.all(np.abs(vec3(m.magnetic_field) - b_body) < 6 * std)
        assert np.allclose(np.reshape(m.magnetic_field_covariance, (3, 3)), np.diag(std ** 2),
                           rtol=1e-12, atol=0)
    assert node.missed_frames == 0 and node.dropouts == 0
    rig.close()


def test_magnetometer_nan_input_publishes_nothing(ros_context, spin):
    node = MagnetometerNode(context=ros_context, parameter_overrides=params(
        noise_std_T=[0.0, 0.0, 0.0], lsb_T=0.0, period_s=1.0,
        misalignment_deg=[0.0, 0.0, math.degrees(0.1)]))
    rig = Rig(ros_context, spin, node, MagneticField, 'sensors/magnetometer')
    frames = [truth(0), truth(1, nan='state'), truth(2, nan='env'), truth(3)]
    assert rig.feed([f[:2] for f in frames], 2)
    assert rig.stamps() == [0.0, 3.0]
    assert node.frames == 4                                # fired, skipped, no crash
    b_body = frames[3][2].inv().apply(B_ECI)
    b_sensor = Rotation.from_rotvec([0.0, 0.0, 0.1]).inv().apply(b_body)
    # two rotations here (scipy) and in the node: a few eps of |B| each way; 1e-18 T is about
    # 100 eps x |B| (4.2e-5 T), far above what another CPU's rounding can add
    assert np.allclose(vec3(rig.got[1].magnetic_field), b_sensor, rtol=0, atol=1e-18)
    rig.close()


def test_magnetometer_dropouts_are_counted_and_published_as_nan(ros_context, spin):
    node = MagnetometerNode(context=ros_context, parameter_overrides=params(
        dropout_probability=1.0, period_s=1.0))
    rig = Rig(ros_context, spin, node, MagneticField, 'sensors/magnetometer')
    rig.feed([truth(t)[:2] for t in range(3)], 0)
    assert spin([node, rig.probe], lambda: node.frames == 3 and len(rig.got) == 3)
    assert node.dropouts == 3
    assert all(np.all(np.isnan(vec3(m.magnetic_field))) for m in rig.got)
    rig.close()


def test_horizon_sensor_roll_pitch_and_validity(ros_context, spin):
    node = HorizonSensorNode(context=ros_context, parameter_overrides=params(
        noise_std_deg=[0.0, 0.0], fov_deg=30.0))
    rig = Rig(ros_context, spin, node, HorizonSensor, 'sensors/horizon')
    roll, pitch, yaw = 4 * DEG, 3 * DEG, 5 * DEG          # paper 004's attitude
    frames = [truth(0, att.from_euler_321(roll, pitch, yaw)),
              truth(1, att.from_euler_321(40 * DEG, 0.0, 1.0)),      # Earth out of view
              truth(2, nan='env'),
              truth(3, att.from_euler_321(-roll, pitch, -2.0))]
    assert rig.feed([f[:2] for f in frames], 3)
    assert rig.stamps() == [0.0, 1.0, 3.0]
    a, b, c = rig.got
    assert a.valid and a.roll == pytest.approx(roll, abs=1e-12)
    assert a.pitch == pytest.approx(pitch, abs=1e-12)
    assert not b.valid and math.isnan(b.roll) and math.isnan(b.pitch)
    assert c.valid and c.roll == pytest.approx(-roll, abs=1e-12)
    assert all(m.header.frame_id == 'horizon_sensor' for m in rig.got)
    assert (a.roll_variance, a.pitch_variance) == (0.0, 0.0)
    assert node.invalid == 1
    rig.close()


def test_star_tracker_output_matches_its_seeded_model(ros_context, spin):
    std = 1e-4
    node = StarTrackerNode(context=ros_context, parameter_overrides=params(
        seed=42, noise_std_deg=[math.degrees(std)] * 3))
    rig = Rig(ros_context, spin, node, Imu, 'sensors/star_tracker')
    frames = [truth(t) for t in range(3)]
    assert rig.feed([f[:2] for f in frames], 3)
    assert rig.stamps() == [0.0, 1.0, 2.0]
    ref = StarTracker(noise_std_rad=std, seed=derive_seed(42, 'star_tracker'))
    for m, f in zip(rig.got, frames):
        q_meas = quat(m.orientation)
        err = (f[2].inv() * Rotation.from_quat(q_meas)).as_rotvec()
        assert np.linalg.norm(err) < 6 * std * math.sqrt(3)
        assert np.array_equal(q_meas, ref.measure(quat(f[0].q_eci_body)))
        assert m.header.frame_id == 'star_tracker'
        assert np.allclose(np.reshape(m.orientation_covariance, (3, 3)), std ** 2 * np.eye(3))
        assert m.angular_velocity_covariance[0] == -1.0
        assert m.linear_acceleration_covariance[0] == -1.0
    rig.close()


def test_gyro_rate_and_covariances(ros_context, spin):
    bias = [1e-4, -2e-4, 3e-4]
    node = GyroNode(context=ros_context, parameter_overrides=params(
        noise_std_deg_s=[0.0, 0.0, 0.0], bias_walk_deg_h_sqrt_h=[0.0, 0.0, 0.0],
        bias_initial_deg_h=[math.degrees(b) * 3600.0 for b in bias], period_s=2.0))
    rig = Rig(ros_context, spin, node, Imu, 'sensors/gyro')
    frames = [truth(0), truth(1), truth(2, nan='state'), truth(3), truth(4)]
    assert rig.feed([f[:2] for f in frames], 2)
    assert rig.stamps() == [0.0, 4.0]                      # 2 s had a NaN rate
    for m in rig.got:
        # the bias goes rad/s -> deg/h -> rad/s and is added: a few eps of |w + b| (1e-18 was
        # under one unit in the last place of 0.03 rad/s: bit-for-bit, one machine's claim)
        assert np.allclose(vec3(m.angular_velocity), W_BODY + bias, rtol=0,
                           atol=4 * EPS * np.abs(W_BODY + bias).max())
        assert m.header.frame_id == 'gyro'
        assert np.array_equal(m.angular_velocity_covariance, np.zeros(9))
        assert m.orientation_covariance[0] == -1.0
        assert m.linear_acceleration_covariance[0] == -1.0
    rig.close()


def test_every_sensor_passes_the_launcher_handshake(ros_context, spin):
    """With the graph's expected_matches (state + environment in, topic out) each gets ready."""
    specs = [(MagnetometerNode, MagneticField, 'sensors/magnetometer'),
             (HorizonSensorNode, HorizonSensor, 'sensors/horizon'),
             (StarTrackerNode, Imu, 'sensors/star_tracker'),
             (GyroNode, Imu, 'sensors/gyro')]
    nodes = [cls(context=ros_context, parameter_overrides=params(expected_matches=[
        f'pub:{topic}=1', 'sub:sim/state=1', 'sub:sim/environment=1'])) for cls, _, topic in specs]
    probe = rclpy.create_node('probe', context=ros_context)
    probe.create_publisher(AttitudeState, 'sim/state', 10)
    probe.create_publisher(Environment, 'sim/environment', 10)
    spin(nodes + [probe], lambda: False, timeout=0.3)
    assert not any(n._ready_sent for n in nodes)           # outputs not matched yet
    for _, msg_type, topic in specs:
        probe.create_subscription(msg_type, topic, lambda m: None, 10)
    assert spin(nodes + [probe], lambda: all(n._ready_sent for n in nodes))
    probe.destroy_node()
    for n in nodes:
        n.destroy_node()


@pytest.mark.parametrize('bad', [dict(period_s=1.5), dict(noise_std_T=[-1.0, 0.0, 0.0])])
def test_bad_parameters_raise(ros_context, bad):
    with pytest.raises(ValueError):
        MagnetometerNode(context=ros_context, parameter_overrides=params(
            frame_period_s=1.0, **bad))


def _wait_for_nodes(domain_id, names, procs, timeout=120.0):
    """Until every node name is in the ROS graph of ``domain_id`` (a started node's
    executor spins, so SIGINT then reaches the node, not the import of numpy)."""
    import rclpy
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    probe = rclpy.create_node('probe_alone', context=ctx)
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if set(names) <= set(probe.get_node_names()):
                return
            if any(p.poll() is not None for p in procs):
                return          # one died: the caller's assertion shows its output
            time.sleep(0.1)
        raise AssertionError(f'nodes not up after {timeout} s: {probe.get_node_names()}')
    finally:
        probe.destroy_node()
        rclpy.shutdown(context=ctx)


def test_each_node_runs_alone_with_defaults():
    """The generic sensor node started alone, the sensor chosen by the node's name (as the
    launcher starts it) or by ``-p sensor:=`` (``ros2 run sim_node sensor_node``) or by the
    alias (``ros2 run sim_node gyro``), starts, spins and stops cleanly on SIGINT."""
    env = child_env(worker_domain(100, 50))
    names = ('magnetometer', 'horizon_sensor', 'star_tracker', 'gyro')
    node = [sys.executable, '-m', 'sim_node.nodes.sensor_node', '--ros-args']
    commands = [node + ['-r', '__node:=magnetometer'], node + ['-r', '__node:=horizon_sensor'],
                node + ['-r', '__node:=star_tracker', '-p', 'sensor:=star_tracker'],
                [sys.executable, '-c', 'from sim_node.nodes.sensor_node import main_gyro; '
                 'raise SystemExit(main_gyro())']]
    procs = [subprocess.Popen(c, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for c in commands]
    try:
        _wait_for_nodes(int(env['ROS_DOMAIN_ID']), names, procs)   # readiness, no fixed sleep
        assert [p.poll() for p in procs] == [None] * 4, [p.communicate() for p in procs]
        for p in procs:
            p.send_signal(signal.SIGINT)
        for p in procs:
            _, err = p.communicate(timeout=60)     # (rclpy's shutdown is slow under load)
            assert p.returncode == 0, err
            assert 'Traceback' not in err
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
