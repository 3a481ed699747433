"""MPI controller of paper 001 (adcs_nodes.core.control.mpi).

Truth: scipy's matrix exponential (Van Loan's augmented matrix for the integral) with the
analytic bound of the series tail; the rigid-body equation (6) with (5) substituted, evaluated
directly; DCM kinematics ``dC/dt = -[w x] C`` by finite differences; geometric facts of the
LVLH frame; hand-computed values of (27) and of the per-axis gains (digest 3.6).
"""
import math
import sys

import numpy as np
import pytest
from scipy.linalg import expm

sys.modules.setdefault('rclpy', None)

from adcs_nodes.core import attitude as att  # noqa: E402
from adcs_nodes.core.control import ControlInputs, Estimate, Target  # noqa: E402
from adcs_nodes.core.control import mpi  # noqa: E402

IB = np.array([[1200.0, -800.0, -10.0], [-800.0, 2500.0, -25.0], [-10.0, -25.0, 2800.0]])
IC = np.array([[1260.0, -840.0, -9.5], [-840.0, 2375.0, -26.2], [-9.5, -26.2, 2660.0]])
W0 = 1.0831e-3


def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


# ----------------------------------------------------------------------- Euler 3-1-2
def test_euler312_round_trip_and_elementary_rotations():
    rng = np.random.default_rng(1)
    for _ in range(50):
        e = rng.uniform([-1.4, -3.0, -3.0], [1.4, 3.0, 3.0])
        np.testing.assert_allclose(mpi.dcm_to_euler312(mpi.euler312_to_dcm(e)), e, atol=1e-12)
    # a pure yaw psi (passive about z): body x seen in the reference frame is (cos, sin, 0)
    c = mpi.euler312_to_dcm([0.0, 0.0, 0.3])
    np.testing.assert_allclose(c.T @ [1, 0, 0], [math.cos(0.3), math.sin(0.3), 0], atol=1e-15)


def test_forward_kinematics_matches_dcm_derivative_and_eq3_inverts_it():
    """dC/dt = -[w x] C for C = R_o2b(e(t)); w from the forward kinematics; (3) inverts it."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        e = rng.uniform(-1.2, 1.2, 3)
        de = rng.uniform(-0.1, 0.1, 3)
        h = 1e-6
        c_dot = (mpi.euler312_to_dcm(e + h * de) - mpi.euler312_to_dcm(e - h * de)) / (2 * h)
        w_fd = -c_dot @ mpi.euler312_to_dcm(e).T
        w = mpi.body_rate_from_euler312(e, de)
        np.testing.assert_allclose(w_fd, skew(w), atol=1e-9)
        np.testing.assert_allclose(mpi.euler312_rates_from_body_rate(e, w), de, atol=1e-14)


def test_body_acceleration_is_the_derivative_of_the_body_rate():
    rng = np.random.default_rng(3)
    e, de, dde = rng.uniform(-1, 1, 3), rng.uniform(-0.1, 0.1, 3), rng.uniform(-0.01, 0.01, 3)
    h = 1e-5

    def w(s):
        return mpi.body_rate_from_euler312(e + de * s + 0.5 * dde * s * s, de + dde * s)
    np.testing.assert_allclose(mpi.body_accel_from_euler312(e, de, dde),
                               (w(h) - w(-h)) / (2 * h), atol=1e-10)


# ----------------------------------------------------------------------- frame boundary
def test_boundary_zero_paper_attitude_points_body_z_to_nadir():
    """Paper's zero attitude: body z on nadir (-z orbit), body y on -orbit normal."""
    r = att.to_matrix(mpi.q_orbit_body_of_lvlh_euler312([0.0, 0.0, 0.0]))
    np.testing.assert_allclose(r, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    # a yaw about nadir: body x in the project's orbit frame is (cos psi, -sin psi, 0)
    psi = 0.4
    r = att.to_matrix(mpi.q_orbit_body_of_lvlh_euler312([0.0, 0.0, psi]))
    np.testing.assert_allclose(r @ [1, 0, 0], [math.cos(psi), -math.sin(psi), 0], atol=1e-15)


def test_boundary_round_trip_and_rates():
    rng = np.random.default_rng(4)
    for _ in range(20):
        q = att.normalize(rng.normal(size=4))
        w = rng.normal(size=3) * 0.01
        c, w_p = mpi.paper_state_from_project(q, w)
        q2, w2 = mpi.project_state_from_paper(c, w_p)
        assert att.angle_between(q, q2) < 1e-12
        np.testing.assert_allclose(w2, w)
        # the same physical body vector: LVLH z (nadir) in body = -(orbit z in body)
        np.testing.assert_allclose(c @ [0, 0, 1], -att.to_matrix(q).T @ [0, 0, 1], atol=1e-14)


# ----------------------------------------------------------------------- model (8)-(16)
@pytest.mark.parametrize('literal', [False, True])
def test_model_equals_equation_6_with_5_substituted(literal):
    """x_ddot of (8) = A x + B u with u of (12) against (6) evaluated directly; the literal
    model differs exactly by I^-1 c, c = [w0 hz, 0, -w0 hx]."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        rot = att.to_matrix(att.normalize(rng.normal(size=4)))
        inertia = rot.T @ IB @ rot
        h = rng.uniform(-30, 30, 3)
        x = np.concatenate([rng.uniform(-0.2, 0.2, 3), rng.uniform(-0.01, 0.01, 3)])
        h_dot = rng.uniform(-1, 1, 3)
        phi, th, psi, dphi, dth, dpsi = x
        omega = np.array([dphi - W0 * psi, dth - W0, dpsi + W0 * phi])                  # (5)
        w_dot = np.linalg.solve(inertia, -np.cross(omega, inertia @ omega + h) - h_dot)  # (6)
        x_ddot = np.array([w_dot[0] + W0 * dpsi, w_dot[1], w_dot[2] - W0 * dphi])
        u = np.linalg.solve(inertia, -h_dot + mpi.feedforward(x, inertia, h, W0, literal))
        model = (mpi.model(inertia, h, W0) @ x)[3:] + u
        c = np.linalg.solve(inertia, [W0 * h[2], 0.0, -W0 * h[0]])
        expected = x_ddot - c if literal else x_ddot
        np.testing.assert_allclose(model, expected, rtol=0, atol=1e-15 + 1e-10 * np.max(
            np.abs(x_ddot)))


# ----------------------------------------------------------------------- Phi, Q (19)-(21)
def _exact(a, tau):
    aug = np.zeros((9, 9))
    aug[:6, :6] = a
    aug[:6, 6:] = mpi.B_MATRIX
    m = expm(aug * tau)
    return m[:6, :6], m[:6, 6:]


@pytest.mark.parametrize('tau', [0.2, 5.0, 50.0, 200.0])
@pytest.mark.parametrize('h', [(0.0, 0.0, 0.0), (10.0, 20.0, 20.0)])
def test_series_against_expm_within_the_truncation_bound(tau, h):
    """||Phi_5 - expm|| <= sum_{k>5} (|A| tau)^k / k!,  ||Q_5 - Q|| <= tau sum_{k>5}
    (|A| tau)^(k-1) / k! (2-norms; B has norm 1)."""
    a = mpi.model(IC, np.array(h), W0)
    phi, q = mpi.transition(a, tau, 5)
    phi_x, q_x = _exact(a, tau)
    s = np.linalg.norm(a, 2) * tau
    tail = sum(s ** k / math.factorial(k) for k in range(6, 80))
    tail_q = tau * sum(s ** (k - 1) / math.factorial(k) for k in range(6, 80))
    assert np.linalg.norm(phi - phi_x, 2) <= tail * (1 + 1e-9) + 1e-13
    assert np.linalg.norm(q - q_x, 2) <= tail_q * (1 + 1e-9) + 1e-13 * tau
    # the exact option is the same expm
    phi_e, q_e = mpi.transition_exact(a, tau)
    np.testing.assert_allclose(phi_e, phi_x, atol=1e-12)
    np.testing.assert_allclose(q_e, q_x, atol=1e-12 * max(1.0, tau))
    if tau == 0.2:
        assert np.linalg.norm(phi - phi_x, 2) < 1e-12 and np.linalg.norm(q - q_x, 2) < 1e-12


def test_series_is_exact_for_the_double_integrator_and_hand_gains():
    """w0 = 0, h = 0: A nilpotent, Phi = [[E, tau E], [0, E]], Q = [tau^2/2 E; tau E]; the
    per-axis law u = -(0.495 angle + 5.05 rate) at tau = 0.2 s (digest 3.6)."""
    a = mpi.model(IC, np.zeros(3), 0.0)
    tau = 0.2
    phi, q = mpi.transition(a, tau, 5)
    np.testing.assert_allclose(phi, np.block([[np.eye(3), tau * np.eye(3)],
                                              [np.zeros((3, 3)), np.eye(3)]]), atol=1e-15)
    np.testing.assert_allclose(q, np.vstack([tau ** 2 / 2 * np.eye(3), tau * np.eye(3)]),
                               atol=1e-15)
    gain = np.linalg.pinv(q) @ phi
    d = tau ** 4 / 4 + tau ** 2
    np.testing.assert_allclose(gain[0, [0, 3]], [tau ** 2 / 2 / d, (tau ** 3 / 2 + tau) / d])
    np.testing.assert_allclose(gain[0, [0, 3]], [0.495, 5.05], atol=1e-3)


def test_u_reaches_a_reachable_target_exactly_and_is_least_squares_otherwise():
    rng = np.random.default_rng(6)
    a = mpi.model(IC, np.array([10.0, -20.0, 15.0]), W0)
    tau = 0.2
    phi, q = mpi.transition(a, tau, 5)
    x0 = np.concatenate([rng.uniform(-0.05, 0.05, 3), rng.uniform(-0.005, 0.005, 3)])
    u_true = rng.uniform(-1e-3, 1e-3, 3)
    x_star = phi @ x0 + q @ u_true
    u = mpi.solve_u(q, x_star - phi @ x0)
    np.testing.assert_allclose(u, u_true, rtol=1e-9)
    phi_x, q_x = _exact(a, tau)       # the linear model integrated exactly
    np.testing.assert_allclose(phi_x @ x0 + q_x @ u, x_star, atol=1e-12)
    # an unreachable dx: the residual is orthogonal to range(Q) (normal equations)
    dx = rng.normal(size=6) * 1e-3
    u = mpi.solve_u(q, dx)
    np.testing.assert_allclose(q.T @ (q @ u - dx), 0.0, atol=1e-15)
    for _ in range(10):
        du = rng.normal(size=3) * 1e-4
        assert np.linalg.norm(q @ (u + du) - dx) > np.linalg.norm(q @ u - dx)


def test_singular_q_gives_none():
    assert mpi.solve_u(np.zeros((6, 3)), np.ones(6)) is None
    q = np.zeros((6, 3))
    q[3, 0] = q[4, 1] = 1.0          # rank 2
    assert mpi.solve_u(q, np.ones(6)) is None
    assert mpi.solve_u(np.full((6, 3), np.nan), np.ones(6)) is None


# ----------------------------------------------------------------------- inversion (27)
def test_inversion_27_hand_values():
    """I = diag(100, 200, 300): v1 = [-100, -100, 200], v2 = 0; p = 0.01, theta_dot = 0.02,
    r = 0.03 (zero angles): K1 v1 = [r th (Iy-Iz), r p (Iz-Ix), p th (Ix-Iy)]
    = [-0.06, 0.06, -0.02]; -I u = [-0.1, -0.4, -0.9] for u = [1, 2, 3] e-3;
    c = [w0 hz, 0, -w0 hx] = [0.03, 0, -0.01] for w0 = 1e-3, h = [10, 20, 30]."""
    inertia = np.diag([100.0, 200.0, 300.0])
    x = np.array([0.0, 0.0, 0.0, 0.01, 0.02, 0.03])
    u = np.array([1e-3, 2e-3, 3e-3])
    h = np.array([10.0, 20.0, 30.0])
    np.testing.assert_allclose(mpi.wheel_momentum_rate(u, x, inertia, h, 1e-3, True),
                               [-0.16, -0.34, -0.92], atol=1e-15)
    np.testing.assert_allclose(mpi.wheel_momentum_rate(u, x, inertia, h, 1e-3, False),
                               [-0.13, -0.34, -0.93], atol=1e-15)
    # a product of inertia Ixy = 10 (I[0,1] = -10): K2 v2 = 10 [-p r, th r, p^2 - th^2 - w0^2]
    inertia2 = inertia.copy()
    inertia2[0, 1] = inertia2[1, 0] = -10.0
    x0 = np.array([0.0, 0.0, 0.0, 0.01, 0.02, 0.03])
    k2v2 = 10 * np.array([-0.01 * 0.03, 0.02 * 0.03, 0.01 ** 2 - 0.02 ** 2 - 1e-6])
    np.testing.assert_allclose(mpi.feedforward(x0, inertia2, np.zeros(3), 1e-3, True),
                               [-0.06, 0.06, -0.02] + k2v2, atol=1e-15)


# ----------------------------------------------------------------------- the controller
def _controller(**kw):
    args = dict(inertia_kgm2=IC, wheel_axes_body=np.eye(3), wheel_max_torque_Nm=[1.0] * 3,
                wheel_max_momentum_Nms=[55.0] * 3, period_s=0.2)
    args.update(kw)
    return mpi.MPIController(**args)


def _inputs(q_ob, w_bo, target=None, h=(0.0, 0.0, 0.0)):
    w = np.asarray(w_bo) + att.to_matrix(q_ob).T @ [0.0, W0, 0.0]
    return ControlInputs(Estimate(q_ob, w, W0), target, wheel_momentum_Nms=np.array(h))


def test_bad_configuration_raises():
    with pytest.raises(ValueError, match='wheels'):
        _controller(wheel_axes_body=np.zeros((0, 3)), wheel_max_torque_Nm=[],
                    wheel_max_momentum_Nms=[])
    with pytest.raises(ValueError, match='span'):
        _controller(wheel_axes_body=[[1, 0, 0], [0, 1, 0]], wheel_max_torque_Nm=[1, 1],
                    wheel_max_momentum_Nms=[55, 55])
    with pytest.raises(ValueError, match='positive definite'):
        _controller(inertia_kgm2=-IC)
    with pytest.raises(ValueError, match='period_s'):
        _controller(period_s=0.0)
    with pytest.raises(ValueError, match='saturation'):
        _controller(saturation='nope')


def test_torque_limit_keeps_direction_and_momentum_stop():
    c = _controller()
    q_ob = mpi.q_orbit_body_of_lvlh_euler312(np.radians([3.0, -3.0, 3.0]))
    q_ref = mpi.q_orbit_body_of_lvlh_euler312(np.radians([40.0, -40.0, 20.0]))
    cmd = c.update(_inputs(q_ob, [0.005, -0.004, 0.003], Target(q_ref)), 0.0, 0.2)
    demand = cmd.info['h_dot_body_demand']
    assert np.max(np.abs(demand)) > 1.0 and cmd.info['saturated']
    assert np.max(np.abs(cmd.wheel_torque)) == pytest.approx(1.0)
    np.testing.assert_allclose(cmd.wheel_torque / np.linalg.norm(cmd.wheel_torque),
                               demand / np.linalg.norm(demand), atol=1e-12)
    # a wheel at its momentum limit gets no torque pushing it further
    h = 55.0 * np.sign(demand)
    cmd = c.update(_inputs(q_ob, [0.005, -0.004, 0.003], Target(q_ref), h), 0.0, 0.2)
    assert np.all(cmd.wheel_torque * np.sign(demand) <= 0.0)
    clip = _controller(saturation='clip').update(
        _inputs(q_ob, [0.005, -0.004, 0.003], Target(q_ref)), 0.0, 0.2)
    np.testing.assert_allclose(clip.wheel_torque, np.clip(demand, -1, 1))


def test_horizon_is_time_to_go_in_a_maneuver_else_one_period():
    c = _controller()
    assert c.horizon(Target(time_to_go_s=150.0)) == 150.0
    assert c.horizon(Target(time_to_go_s=0.05)) == 0.2      # floor: one control period
    assert c.horizon(Target()) == 0.2
    assert c.horizon(Target(time_to_go_s=float('nan'))) == 0.2
    assert _controller(hold_horizon_s=1.0).horizon(Target()) == 1.0


def test_singular_q_falls_back_with_a_reason_never_nan(monkeypatch):
    c = _controller()
    q_ob = mpi.q_orbit_body_of_lvlh_euler312(np.radians([1.0, 2.0, -1.0]))
    monkeypatch.setattr(c, 'horizon', lambda target: 0.0)         # zero horizon: Q = 0
    cmd = c.update(_inputs(q_ob, [1e-3, 0, 0]), 0.0, 0.2)
    assert 'singular Q' in cmd.reason and cmd.is_finite()
    assert np.any(cmd.wheel_torque != 0.0)                          # the one-period command
    monkeypatch.setattr(c, 'period', 0.0)                           # and that one too
    cmd = c.update(_inputs(q_ob, [1e-3, 0, 0]), 0.0, 0.2)
    assert 'singular Q' in cmd.reason and cmd.is_finite()
    np.testing.assert_array_equal(cmd.wheel_torque, 0.0)


def test_bad_data_gives_finite_commands_with_reasons():
    c = _controller()
    q = att.identity()
    cmd = c.update(ControlInputs(Estimate(q, [np.nan, 0, 0], W0)), 0.0, 0.2)
    assert cmd.reason and cmd.is_finite() and cmd.wheel_torque.shape == (3,)
    cmd = c.update(_inputs(q, [0, 0, 0], h=(np.nan, 0, 0)), 0.0, 0.2)
    assert 'wheel momentum' in cmd.reason and cmd.is_finite()
    cmd = c.update(_inputs(q, [0, 0, 0], Target(frame='eci')), 0.0, 0.2)   # no q_eci_body
    assert 'target' in cmd.reason and cmd.is_finite()


def test_at_the_target_only_the_feedforward_remains():
    """x = x*: Q^+ (x* - Phi x) with x = 0 at rest in LVLH gives a tiny u; the command is the
    gyroscopic feed-forward of the orbit rate (order w0^2 I ~ 1e-3 N m at most)."""
    c = _controller()
    q_ref = mpi.q_orbit_body_of_lvlh_euler312(np.radians([40.0, -40.0, 20.0]))
    cmd = c.update(_inputs(q_ref, [0.0, 0.0, 0.0], Target(q_ref)), 0.0, 0.2)
    assert cmd.reason == '' and np.max(np.abs(cmd.wheel_torque)) < 1e-2


def test_closed_loop_rigid_stabilisation_from_the_paper_initial_state():
    """Rigid plant (30), controller inertia (31), 0.2 s control, 0.05 s RK4: the paper's
    initial state [3, -3, 3 deg, 0.3, -0.3, 0.3 deg/s] settles below 0.01 deg in 120 s."""
    c = _controller()
    e0, de0 = np.radians([3.0, -3.0, 3.0]), np.radians([0.3, -0.3, 0.3])
    q = mpi.q_orbit_body_of_lvlh_euler312(e0)
    w = mpi.body_rate_from_euler312(e0, de0)     # rate w.r.t. LVLH = w.r.t. orbit, body axes
    w = w + att.to_matrix(q).T @ [0.0, W0, 0.0]
    h = np.zeros(3)
    q_ref = mpi.q_orbit_body_of_lvlh_euler312(np.zeros(3))

    def f(state, tw):
        qq, ww, hh = state[:4], state[4:7], state[7:]
        w_bo = ww - att.to_matrix(qq).T @ [0.0, W0, 0.0]
        wd = np.linalg.solve(IB, -np.cross(ww, IB @ ww + hh) - tw)
        return np.concatenate([att.derivative(qq, w_bo), wd, tw])

    s = np.concatenate([q, w, h])
    for k in range(600):
        cmd = c.update(_inputs(s[:4], s[4:7] - att.to_matrix(s[:4]).T @ [0, W0, 0],
                               Target(q_ref), s[7:]), k * 0.2, 0.2)
        assert cmd.is_finite() and np.all(np.abs(cmd.wheel_torque) <= 1.0 + 1e-12)
        for _ in range(4):
            k1 = f(s, cmd.wheel_torque)
            k2 = f(s + 0.025 * k1, cmd.wheel_torque)
            k3 = f(s + 0.025 * k2, cmd.wheel_torque)
            k4 = f(s + 0.05 * k3, cmd.wheel_torque)
            s = s + 0.05 / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            s[:4] /= np.linalg.norm(s[:4])
    err = np.degrees(mpi.lvlh_euler312_of(s[:4]))
    assert np.max(np.abs(err)) < 0.01


def test_registry_entry_builds_with_the_paper_inertia_and_refuses_no_wheels():
    from adcs_nodes import registry
    entry = registry.get('controller', 'mpi')
    # the applied command too: the wheel-health check (core/wheel_health.py) compares the
    # measured wheel speeds with the torque the manager applied
    assert entry.inputs == ('estimate', 'target', 'wheel_speeds', 'actuator_command')
    assert entry.actuators == ('wheels',) and entry.requires == ('spacecraft.wheels',)
    ctx = dict(inertia_kgm2=IB, wheel_axes_body=np.eye(3), wheel_max_torque_Nm=[1.0] * 3,
               wheel_max_momentum_Nms=[55.0] * 3, wheel_inertia_kgm2=[0.1] * 3, period_s=0.2)
    c = entry.build(entry.validate({'model_inertia_kgm2': IC.ravel().tolist()}), ctx)
    np.testing.assert_array_equal(c.inertia, IC)
    np.testing.assert_array_equal(entry.build(entry.validate({}), ctx).inertia, IB)
    no_wheels = dict(ctx, wheel_axes_body=np.zeros((0, 3)), wheel_max_torque_Nm=[],
                     wheel_max_momentum_Nms=[])
    with pytest.raises(ValueError, match='wheels'):
        entry.build(entry.validate({}), no_wheels)
    with pytest.raises(ValueError, match='9 values'):
        entry.build(entry.validate({'model_inertia_kgm2': [1.0, 2.0]}), ctx)
    est = registry.get('estimator', 'mekf')
    assert est.inputs == ('star_tracker', 'gyro')
    assert est.build(est.validate({}), ctx).s_st == pytest.approx(math.radians(0.02 / 3))


def test_reference_time_t0_plus_tau_leads_a_tracking_target_by_one_period():
    """Tracking a constant rate w about the LVLH-fixed body axis: the t0 + tau reference is
    the t0 one turned by w tau; the maneuver target (time to go > 0) is never propagated."""
    w = np.array([0.0, 0.0, 1e-3])
    q_ref = mpi.q_orbit_body_of_lvlh_euler312(np.radians([10.0, 5.0, -3.0]))
    lead = _controller(reference_time='t0_plus_tau')
    plain = _controller()
    q_ahead = att.multiply(q_ref, att.from_rotation_vector(w * 0.2))
    inputs = _inputs(q_ref, [0.0, 0.0, 0.0], Target(q_ref, w))
    ahead = _inputs(q_ref, [0.0, 0.0, 0.0], Target(q_ahead, w))
    np.testing.assert_allclose(lead.update(inputs, 0.0, 0.2).wheel_torque,
                               plain.update(ahead, 0.0, 0.2).wheel_torque, atol=1e-12)
    man = _inputs(q_ref, [0.0, 0.0, 0.0], Target(q_ref, w, time_to_go_s=50.0))
    np.testing.assert_allclose(lead.update(man, 0.0, 0.2).wheel_torque,
                               plain.update(man, 0.0, 0.2).wheel_torque, atol=1e-15)


@pytest.mark.parametrize('horizon, rho, fast_pole', [
    (0.2, 1.0, 0.0),       # the paper on a rigid body: dead-beat rate loop
    (0.2, 2.0, -1.02),     # the paper on a hub of half the inertia: the 2.5 Hz pole (P14)
    (0.4, 2.0, -0.02),     # the two-wing variant: dead-beat on that hub
])
def test_hold_horizon_variant_moves_the_nyquist_pole(horizon, rho, fast_pole):
    """Digest P14 and the module's 'beyond the paper' section, by hand: per axis the plant
    over one period T = 0.2 s is a double integrator whose input acts ``rho`` times harder
    than the law's model (hub inertia I / rho); the law is ``u = -Q^+ Phi x`` at horizon H.
    The closed loop's fast pole is ``1 - rho g`` with ``g = T (1 + H^2/2) / (H (1 + H^2/4))``
    and its slow pole stays near 0.98 (the paper's 10 s angle time constant)."""
    t = 0.2
    a = np.zeros((6, 6))
    a[:3, 3:] = np.eye(3)
    phi, q = mpi.transition(a, horizon, 5)
    k = (np.linalg.pinv(q) @ phi)[0, [0, 3]]                   # u_x = -k . [phi, phi_dot]
    g = t * (1 + horizon ** 2 / 2) / (horizon * (1 + horizon ** 2 / 4))
    assert t * k[1] == pytest.approx(g, rel=1e-12)
    closed = np.array([[1.0, t], [0.0, 1.0]]) - rho * np.outer([t * t / 2, t], k)
    poles = sorted(np.linalg.eigvals(closed).real)
    assert poles[0] == pytest.approx(1 - rho * g, abs=0.02)
    assert poles[0] == pytest.approx(fast_pole, abs=0.01)
    assert poles[1] == pytest.approx(0.98, abs=0.02)
