"""Rigid-body dynamics with wheels (sim_node.models.dynamics) against independent truth.

Truth used here: conservation laws (energy, inertial angular momentum), the closed-form
solution of the torque-free axisymmetric top and of a spin about a principal axis under a
constant torque, exactness of RK4 on cubics, and an independent right-hand side written with
``numpy.cross`` / ``attitude`` helpers integrated by scipy's DOP853 at tight tolerance.
"""
import importlib
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from adcs_nodes.core import attitude
from sim_node.models.actuators import Magnetorquer, WheelCluster
from sim_node.models.disturbances import MU_EARTH, ConstantTorque, gravity_gradient_torque
from sim_node.models.dynamics import (ActuatorCommand, FrameEnvironment, Spacecraft,
                                      SpacecraftState)
from reference_dynamics import pack_state, rk4_step, unpack_state

# Asymmetric inertia with products of inertia (paper 000's 118/100/19.6 plus products).
INERTIA = np.array([[118.0, 3.0, -2.0],
                    [3.0, 100.0, 4.0],
                    [-2.0, 4.0, 19.6]])
W0 = np.radians([-3.0, 3.0, 3.0])                       # paper 000's initial tumble, rad/s
Q0 = attitude.from_scalar_first([0.36, 0.48, -0.48, 0.64])
R_ORBIT = 7068.137e3                                     # 690 km circular orbit, m
ENV = FrameEnvironment(r_eci=np.array([R_ORBIT, 0.0, 0.0]),
                       v_eci=np.array([0.0, 1035.0, -7436.0]))
PYRAMID = np.array([[1.0, 1.0, 1.0], [-1.0, 1.0, 1.0], [-1.0, -1.0, 1.0], [1.0, -1.0, 1.0]])


def h_eci(q, inertia, w, axes=None, h_w=None):
    """Total angular momentum in ECI, R(q) (I w + A h), written independently of the model."""
    h_body = inertia @ w
    if axes is not None:
        unit = axes / np.linalg.norm(axes, axis=1, keepdims=True)
        h_body = h_body + unit.T @ h_w
    return attitude.to_matrix(q) @ h_body


def angle(q1, q2):
    """Rotation angle [rad] between two attitudes, resolving 1e-16 rad (``angle_between``'s
    arccos cannot tell angles below 3e-8 rad from zero)."""
    d = attitude.multiply(attitude.conjugate(attitude.normalize(q1)), attitude.normalize(q2))
    return 2.0 * np.arctan2(np.linalg.norm(d[:3]), abs(d[3]))


def run(sc, state, t_end, dt, substeps, env=ENV, command=None):
    command = command if command is not None else sc.zero_command()
    t = 0.0
    for k in range(int(round(t_end / dt))):
        state, _ = sc.step(state, k * dt, dt, env, command, substeps)
        t = (k + 1) * dt
    return state, t


# ---------------------------------------------------------------------------- integrator
def test_rk4_is_exact_on_cubics_and_matches_taylor_on_linear():
    # dx/dt = 4 t^3 - 3 t^2 + 1 -> x = t^4 - t^3 + t: RK4 is Simpson's rule, exact to degree 3
    # in the integrand.
    f = lambda t, x: np.array([4 * t ** 3 - 3 * t ** 2 + 1.0])   # noqa: E731
    x = rk4_step(f, 0.5, np.array([0.5 ** 4 - 0.5 ** 3 + 0.5]), 0.7)
    assert x[0] == pytest.approx(1.2 ** 4 - 1.2 ** 3 + 1.2, rel=1e-14)
    # dx/dt = a x: one step multiplies by the 4th-order Taylor polynomial of exp(a h).
    a, h = -1.3, 0.4
    z = a * h
    x = rk4_step(lambda t, x: a * x, 0.0, np.array([2.0]), h)
    assert x[0] == pytest.approx(2.0 * (1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24), rel=1e-14)


def test_pack_unpack_round_trip():
    s = SpacecraftState(Q0, W0, np.array([1.0, -2.0]))
    x = pack_state(s)
    assert x.shape == (9,)
    back = unpack_state(x)
    np.testing.assert_array_equal(back.q_eci_body, Q0)
    np.testing.assert_array_equal(back.omega_body_eci_body, W0)
    np.testing.assert_array_equal(back.h_wheels, [1.0, -2.0])


# ---------------------------------------------------------------------- conservation laws
def test_torque_free_body_conserves_energy_and_momentum_over_one_orbit():
    """5914 s (one 690 km orbit) at 0.1 s: measured drift ~1e-11 (energy), ~1e-11 (H)."""
    sc = Spacecraft(INERTIA, gravity_gradient=False)
    s0 = SpacecraftState(Q0, W0)
    s1, t = run(sc, s0, 5914.0, 1.0, 10)
    assert t == pytest.approx(5914.0)
    e0 = 0.5 * W0 @ INERTIA @ W0
    e1 = 0.5 * s1.omega_body_eci_body @ INERTIA @ s1.omega_body_eci_body
    h0 = h_eci(Q0, INERTIA, W0)
    h1 = h_eci(s1.q_eci_body, INERTIA, s1.omega_body_eci_body)
    drift_e = abs(e1 - e0) / e0
    drift_h = np.linalg.norm(h1 - h0) / np.linalg.norm(h0)
    print(f'one-orbit relative drift: energy {drift_e:.2e}, momentum {drift_h:.2e}')
    assert drift_e < 1e-9
    assert drift_h < 1e-9
    # The motion is not trivial: the body rate has moved a lot in body axes.
    assert np.linalg.norm(s1.omega_body_eci_body - W0) > 0.1 * np.linalg.norm(W0)
    assert abs(np.linalg.norm(s1.q_eci_body) - 1.0) < 1e-14


def test_spinning_wheels_conserve_total_momentum():
    """Wheels at constant momentum (no motor torque) make a gyrostat: R(q)(I w + A h) and
    1/2 w.I w (w . (w x H) = 0) are conserved, h stays put. Measured at 0.1 s over half an
    orbit: ~2e-10. The drift is RK4 truncation: it falls 16x when the step is halved, and it
    reaches 1e-9 with wheel momenta 3x larger (nutation at 0.15 rad/s)."""
    wheels = WheelCluster(PYRAMID, max_torque=0.1, max_momentum=5.0, inertia=0.01)
    sc = Spacecraft(INERTIA, wheels=wheels, gravity_gradient=False)
    h_w = np.array([0.3, -0.2, 0.1, 0.4])
    s0 = SpacecraftState(Q0, W0, h_w)
    s1, _ = run(sc, s0, 2957.0, 1.0, 10)                 # half an orbit at 0.1 s
    h0 = h_eci(Q0, INERTIA, W0, PYRAMID, h_w)
    h1 = h_eci(s1.q_eci_body, INERTIA, s1.omega_body_eci_body, PYRAMID, s1.h_wheels)
    drift_h = np.linalg.norm(h1 - h0) / np.linalg.norm(h0)
    e0 = 0.5 * W0 @ INERTIA @ W0
    drift_e = abs(0.5 * s1.omega_body_eci_body @ INERTIA @ s1.omega_body_eci_body - e0) / e0
    print(f'gyrostat half-orbit relative drift: momentum {drift_h:.2e}, energy {drift_e:.2e}')
    assert drift_h < 1e-9
    assert drift_e < 1e-9
    np.testing.assert_array_equal(s1.h_wheels, h_w)
    # The wheels matter: without them the body would move differently.
    s_free, _ = run(Spacecraft(INERTIA, gravity_gradient=False), SpacecraftState(Q0, W0),
                    100.0, 1.0, 10)
    s_gyro, _ = run(sc, s0, 100.0, 1.0, 10)
    assert np.linalg.norm(s_free.omega_body_eci_body - s_gyro.omega_body_eci_body) > 1e-4


# ------------------------------------------------------------------- analytic solutions
def test_axisymmetric_torque_free_body_matches_closed_form():
    """I = diag(I1, I1, I3): w3 constant; (w1, w2) rotates at lam = (I3 - I1)/I1 w3;
    attitude R(t) = exp(Wp t [hI x]) R0 exp(-lam t [e3 x]) with Wp = |H|/I1, hI = H_eci/|H|
    (check: dR/dt = R [(Wp h_body - lam e3) x] and w = I^-1 H_body = Wp h_body - lam e3)."""
    i1, i3 = 90.0, 35.0
    inertia = np.diag([i1, i1, i3])
    w0 = np.array([0.03, -0.02, 0.05])
    sc = Spacecraft(inertia, gravity_gradient=False)
    lam = (i3 - i1) / i1 * w0[2]
    h_i = attitude.to_matrix(Q0) @ (inertia @ w0)
    wp = np.linalg.norm(h_i) / i1
    state, t = SpacecraftState(Q0, w0), 0.0
    for t_check in (7.3, 60.0, 250.0, 600.0):
        n = int(round((t_check - t) / 0.1))
        state, _ = sc.step(state, t, t_check - t, ENV, sc.zero_command(), n)
        t = t_check
        c, s = np.cos(lam * t), np.sin(lam * t)
        w_true = np.array([w0[0] * c - w0[1] * s, w0[0] * s + w0[1] * c, w0[2]])
        np.testing.assert_allclose(state.omega_body_eci_body, w_true, rtol=0, atol=1e-8)
        q_true = attitude.multiply(attitude.multiply(attitude.from_axis_angle(h_i, wp * t), Q0),
                                   attitude.from_axis_angle([0.0, 0.0, 1.0], -lam * t))
        assert angle(state.q_eci_body, q_true) < 1e-8


def test_constant_torque_about_principal_axis_matches_closed_form():
    """Spin about principal z with a constant torque on z: w_z = w0 + tau/Iz t and the
    rotation angle about z is w0 t + tau/(2 Iz) t^2 (w x I w = 0 all along)."""
    inertia = np.diag([60.0, 50.0, 30.0])
    sc = Spacecraft(inertia, disturbances=[ConstantTorque([0.0, 0.0, 0.002])],
                    gravity_gradient=False)
    cmd = ActuatorCommand(torque_body=np.array([0.0, 0.0, 0.001]))
    w0, tau, t_end = 0.01, 0.003, 200.0
    state, _ = run(sc, SpacecraftState(Q0, [0.0, 0.0, w0]), t_end, 2.0, 20, command=cmd)
    assert state.omega_body_eci_body[2] == pytest.approx(w0 + tau / 30.0 * t_end, rel=1e-12)
    q_true = attitude.multiply(Q0, attitude.from_axis_angle(
        [0.0, 0.0, 1.0], w0 * t_end + tau / 60.0 * t_end ** 2))
    assert angle(state.q_eci_body, q_true) < 1e-9


# ---------------------------------------------------------------------- actuators in the loop
def _rate_after(sc, env, command, dt=1e-4):
    """The rate after a short frame from rest, and what acted: ``I dw/dt = tau`` to O(dt)."""
    s1, applied = sc.step(SpacecraftState(Q0, np.zeros(3)), 0.0, dt, env, command)
    return s1.omega_body_eci_body / dt, applied


def test_magnetorquer_torque_in_the_equations_is_m_cross_b():
    mtq = Magnetorquer([30.0, 30.0, 30.0])
    sc = Spacecraft(INERTIA, magnetorquer=mtq, gravity_gradient=False)
    b_eci = np.array([1.2e-5, -2.5e-5, 3.1e-5])
    m = np.array([12.0, -7.0, 25.0])
    env = FrameEnvironment(ENV.r_eci, ENV.v_eci, b_eci, np.zeros(3))
    w_dot, applied = _rate_after(sc, env, ActuatorCommand(dipole_body=m))
    b = attitude.to_matrix(Q0).T @ b_eci
    tau = np.array([m[1] * b[2] - m[2] * b[1], m[2] * b[0] - m[0] * b[2],
                    m[0] * b[1] - m[1] * b[0]])
    np.testing.assert_allclose(applied['torque_magnetic_body'], tau, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(INERTIA @ w_dot, tau, rtol=1e-6)


def test_gravity_gradient_in_the_equations_at_rest():
    sc = Spacecraft(INERTIA)
    w_dot, applied = _rate_after(sc, ENV, sc.zero_command())
    tau = gravity_gradient_torque(Q0, ENV.r_eci, INERTIA)
    np.testing.assert_allclose(applied['torque_gg_body'], tau, rtol=1e-12)
    np.testing.assert_allclose(INERTIA @ w_dot, tau, rtol=1e-6)


def test_wheel_torque_exchanges_momentum_with_the_body():
    wheels = WheelCluster(PYRAMID, max_torque=0.2, max_momentum=4.0, inertia=0.02)
    sc = Spacecraft(INERTIA, wheels=wheels, gravity_gradient=False)
    tau_w = np.array([0.1, -0.05, 0.02, 0.0])
    dt = 1.0
    s1, applied = sc.step(SpacecraftState(Q0, np.zeros(3), np.zeros(4)), 0.0, dt, ENV,
                          ActuatorCommand(wheel_torque=tau_w), substeps=10)
    np.testing.assert_array_equal(applied['wheel_torque'], tau_w)
    # wheel momentum: +tau dt, exactly (dh/dt = tau is constant over the frame)
    np.testing.assert_allclose(s1.h_wheels, tau_w * dt, rtol=1e-15, atol=1e-17)
    # total momentum stays zero; the body got -A tau dt (to first order in its small rotation)
    total = h_eci(s1.q_eci_body, INERTIA, s1.omega_body_eci_body, PYRAMID, s1.h_wheels)
    assert np.linalg.norm(total) < 1e-15
    a = PYRAMID / np.linalg.norm(PYRAMID, axis=1, keepdims=True)
    np.testing.assert_allclose(INERTIA @ s1.omega_body_eci_body, -a.T @ tau_w * dt, rtol=1e-3)
    np.testing.assert_allclose(applied['torque_wheels_body'], -a.T @ tau_w, rtol=1e-14)


def test_wheel_momentum_limit_in_step():
    wheels = WheelCluster([[0.0, 0.0, 1.0]], max_torque=0.1, max_momentum=1.0, inertia=0.01)
    sc = Spacecraft(np.diag([10.0, 10.0, 5.0]), wheels=wheels, gravity_gradient=False)
    push = ActuatorCommand(wheel_torque=np.array([0.5]))        # clipped to 0.1 N m
    state = SpacecraftState(Q0, np.zeros(3), np.array([0.95]))
    state, applied = sc.step(state, 0.0, 1.0, ENV, push)
    assert applied['wheel_torque'][0] == pytest.approx(0.05)    # lands on the limit
    assert state.h_wheels[0] == pytest.approx(1.0, abs=1e-15)
    state, applied = sc.step(state, 1.0, 1.0, ENV, push)
    assert applied['wheel_torque'][0] == 0.0                    # at the limit: blocked
    assert state.h_wheels[0] == pytest.approx(1.0, abs=1e-15)
    state, applied = sc.step(state, 2.0, 1.0, ENV, ActuatorCommand(wheel_torque=[-0.5]))
    assert applied['wheel_torque'][0] == pytest.approx(-0.1)    # back off: torque limit only
    assert state.h_wheels[0] == pytest.approx(0.9)


def test_magnetorquer_saturates_per_axis_in_step():
    sc = Spacecraft(INERTIA, magnetorquer=Magnetorquer([10.0, 20.0, 30.0]))
    env = FrameEnvironment(ENV.r_eci, ENV.v_eci, np.array([2e-5, 1e-5, -3e-5]), np.zeros(3))
    _, applied = sc.step(SpacecraftState(Q0, W0), 0.0, 0.5, env,
                         ActuatorCommand(dipole_body=np.array([50.0, -5.0, -40.0])))
    np.testing.assert_array_equal(applied['dipole_body'], [10.0, -5.0, -30.0])
    b_body = attitude.to_matrix(Q0).T @ env.b_eci
    np.testing.assert_allclose(applied['torque_magnetic_body'],
                               np.cross([10.0, -5.0, -30.0], b_body), rtol=1e-12)


def test_no_magnetorquer_means_no_magnetic_torque():
    sc = Spacecraft(INERTIA, gravity_gradient=False)
    env = FrameEnvironment(ENV.r_eci, ENV.v_eci, np.array([2e-5, 1e-5, -3e-5]), np.zeros(3))
    s1, applied = sc.step(SpacecraftState(Q0, np.zeros(3)), 0.0, 1.0, env,
                          ActuatorCommand(dipole_body=np.array([5.0, 5.0, 5.0])))
    np.testing.assert_array_equal(applied['dipole_body'], np.zeros(3))
    np.testing.assert_array_equal(s1.omega_body_eci_body, np.zeros(3))


# --------------------------------------------------- whole model vs independent reference
def _hermite_cubic(b0, d0, b1, d1, tau):
    """Coefficients (4, 3) of p(s) = sum a_j s^j with p, p' = b0, d0 at s = -tau and b1, d1 at
    s = 0, by solving the 4x4 interpolation system (not the model's closed form)."""
    m = np.array([[1.0, -tau, tau ** 2, -tau ** 3], [0.0, 1.0, -2.0 * tau, 3.0 * tau ** 2],
                  [1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
    return np.linalg.solve(m, np.vstack([b0, d0, b1, d1]))


def _reference_rhs(inertia, axes, t0, b_poly, dipole, tau_w, tau_ext):
    """(E1)-(E4), (E6) re-written with numpy.cross / attitude helpers for solve_ivp; state
    [q, w, h, r, v]; field b(s) = sum_j b_poly[j] s^j."""
    a = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    n = axes.shape[0]

    def f(t, x):
        q, w, h, r, v = x[:4], x[4:7], x[7:7 + n], x[7 + n:10 + n], x[10 + n:]
        s = t - t0
        c = attitude.to_matrix(q).T                       # ECI -> body
        r_b = c @ r
        b_b = c @ sum(b_poly[j] * s ** j for j in range(4))
        rn = np.linalg.norm(r_b)
        tau = (3 * MU_EARTH / rn ** 3 * np.cross(r_b / rn, inertia @ (r_b / rn))
               + np.cross(dipole, b_b) + tau_ext - a.T @ tau_w)
        w_dot = np.linalg.solve(inertia, tau - np.cross(w, inertia @ w + a.T @ h))
        return np.concatenate([attitude.derivative(q, w), w_dot, tau_w, v,
                               -MU_EARTH * r / np.linalg.norm(r) ** 3])
    return f


def test_full_model_matches_independent_reference():
    """GG on the two-body orbit (E6), magnetorquer in the field (E7): the line in the first
    frame, the cubic Hermite through both frames' (b, b_dot) in the second (E8); wheels, ideal
    torque and a constant disturbance; two 20 s frames against DOP853 at rtol 1e-12."""
    inertia = np.array([[1200.0, -800.0, -10.0], [-800.0, 2500.0, -25.0],
                        [-10.0, -25.0, 2800.0]])          # paper 001's plant, eq. (30)
    wheels = WheelCluster(PYRAMID, max_torque=1.0, max_momentum=55.0, inertia=0.1)
    mtq = Magnetorquer([30.0, 30.0, 30.0])
    dist = ConstantTorque([1e-4, -2e-4, 5e-5])
    envs = [FrameEnvironment(np.array([R_ORBIT, 0.0, 0.0]), np.array([0.0, 1035.0, 7436.0]),
                             np.array([1.5e-5, -2.0e-5, 3.5e-5]),
                             np.array([4e-8, 2e-8, -5e-8])),
            FrameEnvironment(np.array([R_ORBIT * 0.99985, 20.7e3, 148.7e3]),
                             np.array([-157.0, 1035.0, 7434.0]),
                             np.array([1.6e-5, -1.9e-5, 3.4e-5]),
                             np.array([3e-8, 3e-8, -4e-8]))]
    dt = 20.0
    b_polys = [np.vstack([envs[0].b_eci, envs[0].b_dot_eci, np.zeros((2, 3))]),
               _hermite_cubic(envs[0].b_eci, envs[0].b_dot_eci, envs[1].b_eci,
                              envs[1].b_dot_eci, dt)]
    cmds = [ActuatorCommand(np.array([20.0, -15.0, 45.0]), np.array([0.3, -0.2, 0.1, 0.05]),
                            np.array([0.01, 0.0, -0.02])),
            ActuatorCommand(np.array([-5.0, 25.0, 10.0]), np.array([-0.4, 0.0, 0.2, 0.3]),
                            np.zeros(3))]
    applied_dipoles = [np.array([20.0, -15.0, 30.0]), np.array([-5.0, 25.0, 10.0])]  # by hand
    h0 = np.array([5.0, -3.0, 2.0, 10.0])
    s0 = SpacecraftState(Q0, np.array([0.01, -0.02, 0.015]), h0)
    x_ref = pack_state(s0)
    for k, (env, cmd, m, poly) in enumerate(zip(envs, cmds, applied_dipoles, b_polys)):
        t0 = k * dt
        f = _reference_rhs(inertia, PYRAMID, t0, poly, m, cmd.wheel_torque,
                           cmd.torque_body + dist.torque_body)
        sol = solve_ivp(f, (t0, t0 + dt), np.concatenate([x_ref, env.r_eci, env.v_eci]),
                        method='DOP853', rtol=1e-12, atol=1e-14)
        x_ref = sol.y[:11, -1]

    def model(field_history):
        sc = Spacecraft(inertia, magnetorquer=mtq, wheels=wheels, disturbances=[dist],
                        field_history=field_history)
        state = s0
        for k, (env, cmd, m) in enumerate(zip(envs, cmds, applied_dipoles)):
            state, applied = sc.step(state, k * dt, dt, env, cmd, substeps=200)
            np.testing.assert_array_equal(applied['dipole_body'], m)
        return state

    state = model(True)
    assert angle(state.q_eci_body, x_ref[:4]) < 1e-9
    np.testing.assert_allclose(state.omega_body_eci_body, x_ref[4:7], rtol=0, atol=1e-11)
    np.testing.assert_allclose(state.h_wheels, x_ref[7:], rtol=0, atol=1e-12)
    # the comparison is sharp: the straight-line field in frame 2 is far outside it
    line = model(False)
    assert np.linalg.norm(line.omega_body_eci_body - x_ref[4:7]) > 1e-9


def test_applied_telemetry_is_consistent():
    wheels = WheelCluster(PYRAMID, max_torque=1.0, max_momentum=55.0, inertia=0.1)
    sc = Spacecraft(INERTIA, magnetorquer=Magnetorquer(30.0), wheels=wheels,
                    disturbances=[ConstantTorque([1e-5, 0.0, 0.0])])
    env = FrameEnvironment(ENV.r_eci, ENV.v_eci, np.array([2e-5, 1e-5, -3e-5]), np.zeros(3))
    cmd = ActuatorCommand(np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.0, 0.0, 0.0]),
                          np.array([0.0, 1e-3, 0.0]))
    _, ap = sc.step(SpacecraftState(Q0, W0, np.zeros(4)), 0.0, 1.0, env, cmd)
    np.testing.assert_allclose(ap['torque_gg_body'],
                               gravity_gradient_torque(Q0, env.r_eci, INERTIA), rtol=1e-12)
    np.testing.assert_allclose(ap['torque_disturbance_body'], [1e-5, 0.0, 0.0])
    np.testing.assert_allclose(ap['torque_ideal_body'], [0.0, 1e-3, 0.0])
    total = (ap['torque_gg_body'] + ap['torque_magnetic_body'] + ap['torque_disturbance_body']
             + ap['torque_ideal_body'] + ap['torque_wheels_body'])
    # the model and this test sum the 5 terms in their own orders, each within 4 eps sum|term|
    # (wheels ~0.06 N m, external ~1e-4: total - wheels cancels, so 1e-14 relative to it is
    # below this test's own rounding; it reached 0.81 of it): 8 eps max sum|term|
    tol = 8 * np.finfo(float).eps * sum(np.abs(ap[k]) for k in (
        'torque_gg_body', 'torque_magnetic_body', 'torque_disturbance_body',
        'torque_ideal_body', 'torque_wheels_body')).max()
    np.testing.assert_allclose(ap['torque_body'], total, rtol=0, atol=tol)
    np.testing.assert_allclose(ap['torque_external_body'], total - ap['torque_wheels_body'],
                               rtol=0, atol=tol)


# ----------------------------------------------------------------------------- bad inputs
@pytest.mark.parametrize('inertia', [
    [[10.0, 1.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]],      # not symmetric
    np.diag([10.0, -1.0, 10.0]),                                 # not positive definite
    np.diag([1.0, 1.0, 5.0]),                                    # breaks I1 + I2 >= I3
    np.diag([10.0, np.nan, 10.0]),                               # NaN
    np.eye(2),                                                   # wrong shape
])
def test_bad_inertia_raises(inertia):
    with pytest.raises(ValueError):
        Spacecraft(inertia)


def test_bad_constructor_arguments_raise():
    with pytest.raises(ValueError):
        Spacecraft(INERTIA, magnetorquer='mtq')
    with pytest.raises(ValueError):
        Spacecraft(INERTIA, wheels=[1, 2, 3])
    with pytest.raises(ValueError):
        Spacecraft(INERTIA, disturbances=[object()])
    with pytest.raises(ValueError):
        Spacecraft(INERTIA, mu=-1.0)


def test_bad_step_inputs_raise():
    wheels = WheelCluster(PYRAMID[:3], max_torque=1.0, max_momentum=5.0, inertia=0.1)
    sc = Spacecraft(INERTIA, wheels=wheels)
    good = SpacecraftState(Q0, W0, np.zeros(3))
    cmd = sc.zero_command()
    sc.step(good, 0.0, 0.1, ENV, cmd)                            # the baseline works
    bad_calls = [
        lambda: sc.step(good, 0.0, 0.0, ENV, cmd),
        lambda: sc.step(good, 0.0, -0.1, ENV, cmd),
        lambda: sc.step(good, np.nan, 0.1, ENV, cmd),
        lambda: sc.step(good, 0.0, 0.1, ENV, cmd, substeps=0),
        lambda: sc.step(good, 0.0, 0.1, ENV, cmd, substeps=2.5),
        lambda: sc.step(SpacecraftState(Q0, [np.nan, 0, 0], np.zeros(3)), 0.0, 0.1, ENV, cmd),
        lambda: sc.step(SpacecraftState(np.zeros(4), W0, np.zeros(3)), 0.0, 0.1, ENV, cmd),
        lambda: sc.step(SpacecraftState(Q0, W0, np.zeros(4)), 0.0, 0.1, ENV, cmd),
        lambda: sc.step(SpacecraftState(Q0, W0), 0.0, 0.1, ENV, cmd),
        lambda: sc.step(good, 0.0, 0.1, ENV, ActuatorCommand(wheel_torque=np.zeros(4))),
        lambda: sc.step(good, 0.0, 0.1, ENV, ActuatorCommand(torque_body=[np.inf, 0, 0])),
        lambda: sc.step(good, 0.0, 0.1, ENV, ActuatorCommand(dipole_body=[np.nan, 0, 0])),
        lambda: sc.step(good, 0.0, 0.1, FrameEnvironment(np.zeros(3)), cmd),
        lambda: sc.step(good, 0.0, 0.1, FrameEnvironment(ENV.r_eci, b_eci=[1.0, 2.0]), cmd),
    ]
    for call in bad_calls:
        with pytest.raises(ValueError):
            call()


def test_models_import_without_rclpy(monkeypatch):
    """models/ must not import rclpy or any *_msgs (DESIGN section 2)."""
    import sim_node
    monkeypatch.setattr(sim_node, 'models', sim_node.models)     # restored afterwards
    for name in ('rclpy', 'adcs_msgs', 'std_msgs', 'geometry_msgs', 'sensor_msgs',
                 'rosgraph_msgs', 'builtin_interfaces'):
        monkeypatch.setitem(sys.modules, name, None)
    for name in [m for m in sys.modules if m.startswith('sim_node.models')]:
        monkeypatch.delitem(sys.modules, name)
    for name in ('dynamics', 'actuators', 'disturbances'):
        module = importlib.import_module(f'sim_node.models.{name}')
        assert module.__name__ == f'sim_node.models.{name}'
