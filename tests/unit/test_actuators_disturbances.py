"""Actuator and disturbance models (sim_node.models.actuators / .disturbances).

Truth: hand-derived gravity-gradient torques for pitch and roll offsets from the orbital
frame, the principal-axis equilibria, the explicit cross product, the limits themselves, and
the statistics of a Gaussian draw.
"""
import numpy as np
import pytest

from adcs_nodes.core import attitude
from sim_node.models.actuators import Magnetorquer, WheelCluster
from sim_node.models.disturbances import (MU_EARTH, ConstantTorque, RandomTorque,
                                          gravity_gradient_torque)
from sim_node.models.dynamics import (ActuatorCommand, FrameEnvironment, Spacecraft,
                                      SpacecraftState)

I_DIAG = np.diag([118.0, 100.0, 19.6])
R_ORBIT = 7068.137e3
R_HAT = np.array([2.0, -1.0, 2.0]) / 3.0                 # an arbitrary radial direction
V_HAT = np.array([1.0, 2.0, 0.0]) / np.sqrt(5.0)         # perpendicular to R_HAT
R_ECI = R_ORBIT * R_HAT


def q_eci_orbit():
    """Orbit frame of paper 000 as columns in ECI: x along-track, y orbit normal, z zenith."""
    z = R_HAT
    y = np.cross(R_HAT, V_HAT)
    x = np.cross(y, z)
    return attitude.from_matrix(np.column_stack([x, y, z]))


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


# ----------------------------------------------------------------------- gravity gradient
@pytest.mark.parametrize('theta_deg', [-70.0, -20.0, 5.0, 30.0, 45.0, 80.0])
def test_gravity_gradient_pitch_closed_form(theta_deg):
    """Hand derivation. Body = orbit frame turned by pitch theta about the orbit normal y:
    R_orbit_body = Ry(theta), so r_hat_body = Ry^T e_z = (-sin th, 0, cos th) and
    I r_hat = (-Ix sin th, 0, Iz cos th). The y component of r_hat x I r_hat is
    r_z (I r)_x - r_x (I r)_z = -Ix s c + Iz s c, hence
    tau = (3 mu / r^3) (Iz - Ix) sin th cos th on the pitch axis, zero on x and z.
    With Iz < Ix it is restoring (negative for theta > 0)."""
    th = np.radians(theta_deg)
    q = attitude.multiply(q_eci_orbit(), attitude.from_matrix(rot_y(th)))
    tau = gravity_gradient_torque(q, R_ECI, I_DIAG)
    expected = 3 * MU_EARTH / R_ORBIT ** 3 * (19.6 - 118.0) * np.sin(th) * np.cos(th)
    np.testing.assert_allclose(tau, [0.0, expected, 0.0], rtol=0, atol=1e-12 * abs(expected)
                               + 1e-18)


@pytest.mark.parametrize('phi_deg', [-40.0, 10.0, 60.0])
def test_gravity_gradient_roll_closed_form(phi_deg):
    """Roll phi about along-track x: r_hat_body = Rx^T e_z = (0, sin phi, cos phi),
    tau_x = r_y (I r)_z - r_z (I r)_y = (Iz - Iy) sin phi cos phi."""
    ph = np.radians(phi_deg)
    q = attitude.multiply(q_eci_orbit(), attitude.from_matrix(rot_x(ph)))
    tau = gravity_gradient_torque(q, R_ECI, I_DIAG)
    expected = 3 * MU_EARTH / R_ORBIT ** 3 * (19.6 - 100.0) * np.sin(ph) * np.cos(ph)
    np.testing.assert_allclose(tau, [expected, 0.0, 0.0], rtol=0, atol=1e-12 * abs(expected))


def test_gravity_gradient_yaw_and_scaling():
    """Yaw about the zenith leaves r_hat on the body z axis: no torque. |tau| ~ 1/r^3."""
    for yaw in (0.3, 1.2, 2.5):
        q = attitude.multiply(q_eci_orbit(), attitude.from_axis_angle([0, 0, 1.0], yaw))
        assert np.linalg.norm(gravity_gradient_torque(q, R_ECI, I_DIAG)) < 1e-18
    q = attitude.multiply(q_eci_orbit(), attitude.from_matrix(rot_y(0.4)))
    near = gravity_gradient_torque(q, R_ECI, I_DIAG)
    far = gravity_gradient_torque(q, 2.0 * R_ECI, I_DIAG)
    assert near[1] / far[1] == pytest.approx(8.0, rel=1e-12)   # (pitch: y only; x, z are 0)


def _q_taking(a_body, b_eci):
    """A rotation q_eci_body with R(q) a_body = b_eci (both unit)."""
    axis = np.cross(a_body, b_eci)
    if np.linalg.norm(axis) < 1e-12:
        axis = np.cross(a_body, [1.0, 0.0, 0.0] if abs(a_body[0]) < 0.9 else [0, 1.0, 0])
    return attitude.from_axis_angle(axis, np.arccos(np.clip(a_body @ b_eci, -1.0, 1.0)))


def test_gravity_gradient_vanishes_at_principal_equilibria():
    """Zero torque whenever a principal axis points along r, also for an inertia with
    products of inertia (principal axes not the body axes); non-zero 10 deg away."""
    p = attitude.to_matrix(attitude.from_rotation_vector([0.3, -0.5, 0.2]))
    inertia = p @ np.diag([118.0, 100.0, 19.6]) @ p.T
    for k in range(3):
        for sign in (1.0, -1.0):
            axis = sign * p[:, k]
            q = _q_taking(axis, R_HAT)
            np.testing.assert_allclose(attitude.to_matrix(q) @ axis, R_HAT, atol=1e-12)
            assert np.linalg.norm(gravity_gradient_torque(q, R_ECI, inertia)) < 1e-16
            tilted = attitude.multiply(q, attitude.from_axis_angle(p[:, (k + 1) % 3],
                                                                   np.radians(10)))
            assert np.linalg.norm(gravity_gradient_torque(tilted, R_ECI, inertia)) > 1e-6


def test_gravity_gradient_bad_inputs():
    with pytest.raises(ValueError):
        gravity_gradient_torque(attitude.identity(), np.zeros(3), I_DIAG)
    with pytest.raises(ValueError):
        gravity_gradient_torque(attitude.identity(), R_ECI, np.diag([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError):
        gravity_gradient_torque([np.nan, 0, 0, 1.0], R_ECI, I_DIAG)
    with pytest.raises(ValueError):
        gravity_gradient_torque(attitude.identity(), [1.0, 2.0], I_DIAG)


# --------------------------------------------------------------------------- magnetorquer
def test_magnetorquer_torque_is_m_cross_b_and_perpendicular_to_b():
    rng = np.random.default_rng(1)
    for _ in range(50):
        m = rng.uniform(-40, 40, 3)
        b = rng.normal(0, 3e-5, 3)
        tau = Magnetorquer.torque(m, b)
        explicit = np.array([m[1] * b[2] - m[2] * b[1], m[2] * b[0] - m[0] * b[2],
                             m[0] * b[1] - m[1] * b[0]])
        np.testing.assert_array_equal(tau, explicit)
        assert abs(tau @ b) <= 1e-12 * np.linalg.norm(tau) * np.linalg.norm(b)
        assert abs(tau @ m) <= 1e-12 * np.linalg.norm(tau) * np.linalg.norm(m)


def test_magnetorquer_saturation_per_axis():
    limit = np.array([10.0, 20.0, 40.0])
    mtq = Magnetorquer(limit)
    rng = np.random.default_rng(2)
    for _ in range(200):
        cmd = rng.uniform(-100, 100, 3)
        out = mtq.apply(cmd)
        assert np.all(np.abs(out) <= limit)
        for i in range(3):   # each axis on its own: inside -> unchanged, outside -> on the limit
            if abs(cmd[i]) <= limit[i]:
                assert out[i] == cmd[i]
            else:
                assert out[i] == np.sign(cmd[i]) * limit[i]
    np.testing.assert_array_equal(mtq.apply([1.0, -2.0, 3.0]), [1.0, -2.0, 3.0])


def test_magnetorquer_bad_inputs():
    for bad in ([-1.0, 1.0, 1.0], [np.nan, 1.0, 1.0], [1.0, 1.0]):
        with pytest.raises(ValueError):
            Magnetorquer(bad)
    with pytest.raises(ValueError):
        Magnetorquer(10.0).apply([np.inf, 0.0, 0.0])
    with pytest.raises(ValueError):
        Magnetorquer(10.0).apply([1.0, 0.0])


# ------------------------------------------------------------------------- reaction wheels
def test_wheel_cluster_geometry():
    wheels = WheelCluster([[2.0, 0, 0], [0, 0, -5.0], [1.0, 1.0, 0]], max_torque=0.1,
                          max_momentum=[1.0, 2.0, 3.0], inertia=[0.01, 0.02, 0.04])
    assert wheels.n == 3
    s = 1 / np.sqrt(2)
    np.testing.assert_allclose(wheels.axes_body, [[1, 0, 0], [0, 0, -1], [s, s, 0]])
    h = np.array([0.5, 1.0, -2.0])
    np.testing.assert_allclose(wheels.h_body(h), [0.5 - 2 * s, -2 * s, -1.0])
    np.testing.assert_allclose(wheels.torque_body([0.1, 0.0, 0.0]), [-0.1, 0.0, 0.0])
    np.testing.assert_allclose(wheels.speed(h), [50.0, 50.0, -50.0])
    np.testing.assert_allclose(wheels.speed(h, [0.1, 0.2, 0.3]),
                               [50.0 - 0.1, 50.0 + 0.3, -50.0 - s * 0.3])


def test_wheel_torque_and_momentum_limits():
    wheels = WheelCluster(np.eye(3), max_torque=[0.1, 0.2, 0.3], max_momentum=2.0,
                          inertia=0.01)
    # torque limit only
    np.testing.assert_allclose(wheels.apply([1.0, -1.0, 0.05], [0.0, 0.0, 0.0]),
                               [0.1, -0.2, 0.05])
    # at the limit: pushing further is blocked, pulling back is allowed
    np.testing.assert_allclose(wheels.apply([0.1, -0.1, -0.1], [2.0, -2.0, 2.0]),
                               [0.0, 0.0, -0.1])
    # with the hold time: the wheel lands on the limit at the end of it
    tau = wheels.apply([0.1, -0.2, 0.3], [1.95, -1.9, 0.0], dt=1.0)
    np.testing.assert_allclose(tau, [0.05, -0.1, 0.3])
    # past the limit (initial condition): no push, pull back freely
    np.testing.assert_allclose(wheels.apply([0.1, -0.1, 0.0], [2.5, 2.5, 0.0], dt=1.0),
                               [0.0, -0.1, 0.0])
    # unlimited momentum
    free = WheelCluster([[0, 0, 1.0]], max_torque=0.1, max_momentum=np.inf, inertia=0.01)
    np.testing.assert_allclose(free.apply([0.5], [1e6], dt=1.0), [0.1])


def test_wheel_cluster_bad_inputs():
    ok = dict(max_torque=0.1, max_momentum=1.0, inertia=0.01)
    with pytest.raises(ValueError, match='zero length'):
        WheelCluster([[1.0, 0, 0], [0, 0, 0]], **ok)
    with pytest.raises(ValueError):
        WheelCluster(np.zeros((0, 3)), **ok)
    with pytest.raises(ValueError):
        WheelCluster([[1.0, 0, 0, 0]], **ok)
    with pytest.raises(ValueError):
        WheelCluster([[np.nan, 0, 1.0]], **ok)
    with pytest.raises(ValueError):
        WheelCluster(np.eye(3), max_torque=[0.1, -0.1, 0.1], max_momentum=1.0, inertia=0.01)
    with pytest.raises(ValueError):
        WheelCluster(np.eye(3), max_torque=0.1, max_momentum=-1.0, inertia=0.01)
    with pytest.raises(ValueError):
        WheelCluster(np.eye(3), max_torque=0.1, max_momentum=[1.0, 1.0], inertia=0.01)
    with pytest.raises(ValueError):
        WheelCluster(np.eye(3), max_torque=0.1, max_momentum=1.0, inertia=0.0)
    wheels = WheelCluster(np.eye(3), **ok)
    with pytest.raises(ValueError):
        wheels.apply([0.1, 0.1], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        wheels.apply([0.1, 0.1, np.nan], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        wheels.apply([0.1, 0.1, 0.1], [0.0, 0.0, 0.0], dt=0.0)


# ---------------------------------------------------------------------------- disturbances
def test_constant_torque():
    d = ConstantTorque([1e-6, -2e-6, 3e-6])
    np.testing.assert_array_equal(d.torque(0.0), [1e-6, -2e-6, 3e-6])
    np.testing.assert_array_equal(d.torque(1e5), [1e-6, -2e-6, 3e-6])
    d.torque(0.0)[0] = 5.0                                    # callers cannot corrupt it
    np.testing.assert_array_equal(d.torque(1.0), [1e-6, -2e-6, 3e-6])
    with pytest.raises(ValueError):
        ConstantTorque([np.nan, 0.0, 0.0])


def test_random_torque_is_a_function_of_seed_and_period_only():
    times = np.arange(0.0, 40.0, 0.1)                         # t_k = k dt, as the sim does
    forward = RandomTorque(1e-5, 2.0, seed=42)
    a = np.array([forward.torque(t) for t in times])
    backward = RandomTorque(1e-5, 2.0, seed=42)
    b = np.array([backward.torque(t) for t in times[::-1]])[::-1]
    shuffled = RandomTorque(1e-5, 2.0, seed=42)
    order = np.random.default_rng(0).permutation(len(times))
    c = np.empty_like(a)
    for i in order:
        c[i] = shuffled.torque(times[i])
        shuffled.torque(37.3)                                 # extra calls change nothing
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
    # held over each 2 s period (20 samples of 0.1 s), redrawn at the next one
    blocks = a.reshape(20, 20, 3)
    assert np.all(blocks == blocks[:, :1, :])
    assert np.all(np.abs(np.diff(blocks[:, 0, :], axis=0)) > 0)
    # t = 20 * 0.1 computed by repeated addition still falls in period 1
    t = 0.0
    for _ in range(20):
        t += 0.1
    np.testing.assert_array_equal(forward.torque(t), forward.torque(2.0))
    other = RandomTorque(1e-5, 2.0, seed=43)
    assert not np.allclose(other.torque(0.0), a[0])


def test_random_torque_statistics():
    std = np.array([1e-5, 2e-5, 5e-6])
    d = RandomTorque(std, 1.0, seed=7)
    n = 6000
    samples = np.array([d.torque(j + 0.5) for j in range(n)]) / std
    # unit normal per axis: mean within 4 sigma/sqrt(n), std within 4 * 1/sqrt(2n)
    assert np.all(np.abs(samples.mean(axis=0)) < 4 / np.sqrt(n))
    assert np.all(np.abs(samples.std(axis=0) - 1.0) < 4 / np.sqrt(2 * n))
    # axes and consecutive periods uncorrelated
    corr = np.corrcoef(samples.T)
    assert np.all(np.abs(corr[np.triu_indices(3, 1)]) < 4 / np.sqrt(n))
    lag = np.corrcoef(samples[:-1, 0], samples[1:, 0])[0, 1]
    assert abs(lag) < 4 / np.sqrt(n)


def test_random_torque_trajectory_does_not_depend_on_substeps():
    """1 and 10 RK4 substeps per frame see the same draws: the trajectories differ only by
    integration error, far below what one different draw does."""
    inertia = np.diag([118.0, 100.0, 19.6])
    env = FrameEnvironment(np.array([R_ORBIT, 0.0, 0.0]), np.array([0.0, 1035.0, 7436.0]))
    q0 = attitude.from_scalar_first([0.36, 0.48, -0.48, 0.64])

    def final(seed, substeps):
        sc = Spacecraft(inertia, disturbances=[RandomTorque(1e-3, 2.0, seed)])
        s = SpacecraftState(q0, [0.002, -0.001, 0.003])
        for k in range(400):
            s, _ = sc.step(s, k * 0.5, 0.5, env, ActuatorCommand(), substeps)
        return s.omega_body_eci_body

    w1, w10, w_other = final(5, 1), final(5, 10), final(6, 1)
    assert np.linalg.norm(w1 - w10) < 1e-10
    assert np.linalg.norm(w1 - w_other) > 1e-5


def test_random_torque_bad_inputs():
    for kwargs in (dict(std_Nm=-1.0, period_s=1.0, seed=0),
                   dict(std_Nm=[1.0, 1.0], period_s=1.0, seed=0),
                   dict(std_Nm=np.nan, period_s=1.0, seed=0),
                   dict(std_Nm=1.0, period_s=0.0, seed=0),
                   dict(std_Nm=1.0, period_s=np.inf, seed=0),
                   dict(std_Nm=1.0, period_s=1.0, seed=-1),
                   dict(std_Nm=1.0, period_s=1.0, seed=1.5)):
        with pytest.raises(ValueError):
            RandomTorque(**kwargs)
