"""Paper 000's magnetorquer laws (adcs_nodes.core.control.magnetic) against hand-computed truth.

The closed-loop smoke tests use a rigid-body + gravity-gradient + tilted-dipole model written
here (independent of sim_node), RK4 with a 2 s step and the command held over each step, with
ideal state knowledge (digest 3.6 sanity check).
"""
import math

import numpy as np
import pytest

from adcs_nodes.core import attitude
from adcs_nodes.core.control import Command, Estimate, Target, scale_to_limits
from adcs_nodes.core.control.bdot import BdotController
from adcs_nodes.core.control.magnetic import (MagneticController, check_gains,
                                              dipole_from_torque, orbit_axes_in_body,
                                              target_rate_one_axis, target_rate_three_axis)

ALPHA, K, L_MAX = 3e-3, 0.2, 40.0            # digest 3.6 proposals
W0 = 1.0625e-3                               # orbit rate at 690 km [rad/s] (digest 5.1)
LAMBDA0 = (0.36, 0.48, -0.48, 0.64)          # paper's Lambda(0), scalar first
OMEGA0_DEG = (-3.0, 3.0, 3.0)                # paper's omega(0) [deg/s]


def _est(q, w, w0=W0, valid=True):
    return Estimate(np.asarray(q, float), np.asarray(w, float), w0, valid)


def _random_quat(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


# ------------------------------------------------------------------- equation (10), law (16)
def test_eq10_hand_values_for_the_paper_initial_attitude():
    """Lambda = (0.36, 0.48, -0.48, 0.64):
    e_R = [2(l1 l3 - l0 l2), 2(l2 l3 + l0 l1), l0^2 - l1^2 - l2^2 + l3^2]
        = [2(0.3072 + 0.1728), 2(-0.3072 + 0.1728), 0.1296 - 0.2304 - 0.2304 + 0.4096]
        = [0.96, -0.2688, 0.0784]
    e_N = [2(l1 l2 + l0 l3), l0^2 - l1^2 + l2^2 - l3^2, 2(l2 l3 - l0 l1)]
        = [2(-0.2304 + 0.2304), 0.1296 - 0.2304 + 0.2304 - 0.4096, 2(-0.3072 - 0.1728)]
        = [0, -0.28, -0.96]
    """
    e_r, e_n = orbit_axes_in_body(attitude.from_scalar_first(LAMBDA0))
    assert np.allclose(e_r, [0.96, -0.2688, 0.0784], atol=1e-12)
    assert np.allclose(e_n, [0.0, -0.28, -0.96], atol=1e-12)


def test_eq10_equals_rotated_orbit_axes():
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = _random_quat(rng)
        e_r, e_n = orbit_axes_in_body(q)
        r_t = attitude.to_matrix(q).T                 # orbit -> body
        assert np.allclose(e_r, r_t[:, 2], atol=1e-12)
        assert np.allclose(e_n, r_t[:, 1], atol=1e-12)


def test_three_axis_law_hand_case():
    """Paper's initial state, alpha = 3e-3, k = 0.2, omega0 = 1.0625e-3:
    y  = omega - omega0 e_N                                             (7)
       = (-0.05235988, 0.05235988 + 0.28 omega0, 0.05235988 + 0.96 omega0)
       = (-0.05235988, 0.05265738, 0.05337988) rad/s
    y* = -2 alpha lambda sign(l0) / (1 + |l0|) = -(0.006 / 1.36) (0.48, -0.48, 0.64)   (16)
       = (-0.00211765, 0.00211765, -0.00282353) rad/s
    M* = -k (y - y*) = -0.2 (-0.05024223, 0.05053973, 0.05620341)      (29)
       = (0.01004845, -0.01010795, -0.01124068) N m
    B = (0, 0, 3e-5) T: L* = B x M* / |B|^2 = (-M*_y, M*_x, 0) / 3e-5  (30)
       = (336.9316, 334.9482, 0) A m^2
    sigma = 40 / 336.9316 = 0.118718; L = (40, 39.76454, 0) A m^2      (31)
    """
    ctrl = MagneticController(alpha=ALPHA, k=K, max_dipole_Am2=L_MAX)
    q = attitude.from_scalar_first(LAMBDA0)
    cmd = ctrl.law(_est(q, np.radians(OMEGA0_DEG)), None, [0.0, 0.0, 3e-5], 0.0, 2.0)
    info = cmd.info
    assert cmd.reason == '' and info['stage'] == 'three_axis'
    assert np.allclose(info['y'], [-0.05235988, 0.05265738, 0.05337988], atol=1e-8)
    assert np.allclose(info['y_star'], [-0.00211765, 0.00211765, -0.00282353], atol=1e-8)
    assert np.allclose(info['torque_demand'], [0.01004845, -0.01010795, -0.01124068],
                       atol=1e-8)
    assert np.allclose(info['dipole_demand'], [336.9316, 334.9482, 0.0], atol=1e-3)
    assert info['sigma'] == pytest.approx(0.118718, abs=1e-6)
    assert np.allclose(cmd.dipole_body, [40.0, 39.76454, 0.0], atol=1e-4)
    assert cmd.wheel_torque.shape == (0,) and np.all(cmd.torque_body == 0.0)


def test_three_axis_law_sign_of_lambda0_and_antipodal_quaternion():
    """sign(0) = +1: Lambda = (0, 1, 0, 0) gives y* = -2 alpha (1, 0, 0); q and -q agree."""
    assert np.allclose(target_rate_three_axis([1.0, 0.0, 0.0, 0.0], ALPHA),
                       [-2 * ALPHA, 0.0, 0.0])
    # 90 deg about x: y* = -2 alpha (0.70711, 0, 0) / 1.70711 = (-0.828427 alpha, 0, 0)
    q90 = attitude.from_scalar_first([math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])
    assert np.allclose(target_rate_three_axis(q90, ALPHA), [-0.828427 * ALPHA, 0, 0],
                       atol=1e-9)
    rng = np.random.default_rng(2)
    ctrl = MagneticController()
    for _ in range(20):
        q, w, b = _random_quat(rng), rng.normal(size=3) * 0.01, rng.normal(size=3) * 3e-5
        if abs(q[3]) < 1e-6:
            continue
        c1 = ctrl.law(_est(q, w), None, b, 0.0, 2.0)
        c2 = ctrl.law(_est(-q, w), None, b, 0.0, 2.0)
        assert np.allclose(c1.dipole_body, c2.dipole_body, atol=1e-12)


def test_one_axis_law_hand_case():
    """90 deg about x, Lambda = (0.70711, 0.70711, 0, 0), xi = z, omega = 0:
    e_R = (0, 2 l0 l1, l0^2 - l1^2) = (0, 1, 0) = s;  e_N = (0, 0, -1)            (10)
    s x xi = (0, 1, 0) x (0, 0, 1) = (1, 0, 0);  xi^T s = 0
    y* = -alpha (s x xi) / (1 + xi^T s) = (-3e-3, 0, 0)                           (21)
    y = omega - omega0 e_N = (0, 0, 1.0625e-3)                                    (7)
    M* = -k (y - y*) = -0.2 (3e-3, 0, 1.0625e-3) = (-6e-4, 0, -2.125e-4) N m      (32)
    """
    ctrl = MagneticController(mode='one_axis', alpha=ALPHA, k=K)
    q = attitude.from_scalar_first([math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])
    cmd = ctrl.law(_est(q, np.zeros(3)), None, [0.0, 2e-5, 2e-5], 0.0, 2.0)
    assert np.allclose(cmd.info['y_star'], [-3e-3, 0.0, 0.0], atol=1e-12)
    assert np.allclose(cmd.info['torque_demand'], [-6e-4, 0.0, -2.125e-4], atol=1e-12)
    assert cmd.info['angle_rad'] == pytest.approx(math.pi / 2)
    assert np.allclose(target_rate_one_axis([0, 1, 0], [0, 0, 1], ALPHA), [-ALPHA, 0, 0])


def test_target_other_than_orbit_frame_uses_error_quaternion():
    rng = np.random.default_rng(3)
    ctrl = MagneticController()
    for _ in range(20):
        q, q_ref = _random_quat(rng), _random_quat(rng)
        w, b = rng.normal(size=3) * 0.01, rng.normal(size=3) * 3e-5
        cmd = ctrl.law(_est(q, w), Target(q_ref, np.zeros(3)), b, 0.0, 2.0)
        q_err = attitude.multiply(attitude.conjugate(q_ref), q)
        assert np.allclose(cmd.info['y_star'], target_rate_three_axis(q_err, ALPHA))
    # on the target and moving with the orbital frame: nothing to do
    q = _random_quat(rng)
    _, e_n = orbit_axes_in_body(q)
    cmd = ctrl.law(_est(q, W0 * e_n), Target(q, np.zeros(3)), [1e-5, 2e-5, 3e-5], 0, 2)
    assert np.allclose(cmd.dipole_body, 0.0, atol=1e-12)
    # the target rate is a feed-forward of y*
    y_ref = np.array([1e-3, -2e-3, 5e-4])
    cmd = ctrl.law(_est(q, W0 * e_n), Target(q, y_ref), [1e-5, 2e-5, 3e-5], 0, 2)
    assert np.allclose(cmd.info['torque_demand'], K * y_ref)


# --------------------------------------------------------------------- dipole sign, (22), (31)
def test_dipole_sign_pin_eq22_and_printed_formula_is_positive_feedback():
    """L* = B x M* / |B|^2: L* x B = M* - b b^T M* (22) and M_u . M* >= 0. The printed
    L* = -k Phi^+(B) Y with Phi^+(B) = -Phi(B) / |B|^2 and M* = -k Y gives the opposite torque."""
    rng = np.random.default_rng(4)
    for _ in range(200):
        m_star = rng.normal(size=3) * 1e-3
        b = rng.normal(size=3) * 3e-5
        bh = b / np.linalg.norm(b)
        l_star = dipole_from_torque(m_star, b)
        m_u = np.cross(l_star, b)                                                # (4)
        assert np.allclose(m_u, m_star - bh * (bh @ m_star), atol=1e-15)
        assert m_u @ m_star >= 0.0
        assert abs(l_star @ b) < 1e-9 * np.linalg.norm(l_star) * np.linalg.norm(b)
        y_big = -m_star / K                                                      # M* = -k Y
        phi_plus = -attitude.skew(b) / (b @ b)
        l_printed = -K * phi_plus @ y_big
        assert np.allclose(np.cross(l_printed, b), -(m_star - bh * (bh @ m_star)), atol=1e-15)
    # through the controller, after the scaling (31): the applied torque still opposes y - y*
    ctrl = MagneticController()
    for _ in range(200):
        q, w, b = _random_quat(rng), rng.normal(size=3) * 0.05, rng.normal(size=3) * 3e-5
        cmd = ctrl.law(_est(q, w), None, b, 0.0, 2.0)
        applied = np.cross(cmd.dipole_body, b)
        assert np.allclose(applied, cmd.info['torque_applied'], atol=1e-15)
        assert applied @ cmd.info['torque_demand'] >= 0.0


def test_sigma_scaling_keeps_every_coil_inside_and_the_direction():
    rng = np.random.default_rng(5)
    for _ in range(3000):
        v = rng.normal(size=3) * 10.0 ** rng.uniform(-3, 4)
        lim = rng.uniform(0.5, 100.0, size=3)
        out, sigma = scale_to_limits(v, lim)
        assert np.all(np.abs(out) <= lim)
        assert 0.0 < sigma <= 1.0
        assert np.allclose(out, sigma * v, rtol=1e-12, atol=0.0)              # same direction
        if sigma < 1.0:
            assert np.max(np.abs(out) / lim) == pytest.approx(1.0, rel=1e-12)  # one coil full
        else:
            assert np.array_equal(out, v)
    # per-axis limits through the controller, random states
    lim = np.array([10.0, 40.0, 25.0])
    ctrl = MagneticController(max_dipole_Am2=lim)
    for _ in range(500):
        q, w, b = _random_quat(rng), rng.normal(size=3) * 0.1, rng.normal(size=3) * 3e-5
        cmd = ctrl.law(_est(q, w), None, b, 0.0, 2.0)
        assert np.all(np.abs(cmd.dipole_body) <= lim)
        demand = cmd.info['dipole_demand']
        assert np.linalg.norm(np.cross(cmd.dipole_body, demand)) <= \
            1e-12 * np.linalg.norm(cmd.dipole_body) * np.linalg.norm(demand)
        assert cmd.dipole_body @ demand >= 0.0


def test_zero_command_with_reason_on_bad_field_or_estimate():
    ctrl = MagneticController()
    q, w = attitude.from_scalar_first(LAMBDA0), np.radians(OMEGA0_DEG)
    cases = [
        (_est(q, w), [1e-10, 0.0, 0.0], 'pseudo-inverse'),       # |B| < 1e-9 T
        (_est(q, w), [0.0, 0.0, 0.0], 'pseudo-inverse'),
        (_est(q, w), None, 'no magnetic field'),
        (_est(q, w), [np.nan, 1e-5, 0.0], 'not finite'),
        (_est(q, w), [np.inf, 1e-5, 0.0], 'not finite'),
        (_est(q, w, valid=False), [0.0, 0.0, 3e-5], 'estimate'),
        (_est(q, [np.nan, 0, 0]), [0.0, 0.0, 3e-5], 'estimate'),
        (None, [0.0, 0.0, 3e-5], 'estimate'),
    ]
    for est, b, word in cases:
        cmd = ctrl.law(est, None, b, 0.0, 2.0)
        assert np.array_equal(cmd.dipole_body, np.zeros(3)) and cmd.is_finite()
        assert word in cmd.reason, cmd.reason
    # just above the guard: a finite (scaled) dipole
    cmd = ctrl.law(_est(q, w), None, [2e-9, 0.0, 0.0], 0.0, 2.0)
    assert cmd.reason == '' and cmd.is_finite() and np.all(np.abs(cmd.dipole_body) <= L_MAX)
    cmd = ctrl.law(_est(q, w), Target(np.array([np.nan, 0, 0, 1.0])), [0, 0, 3e-5], 0, 2)
    assert 'target' in cmd.reason and np.all(cmd.dipole_body == 0.0)


# ---------------------------------------------------------------------- kinematics (16), (21)
def _rk4(f, x, h):
    k1 = f(x)
    k2 = f(x + 0.5 * h * k1)
    k3 = f(x + 0.5 * h * k2)
    k4 = f(x + h * k3)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


@pytest.mark.parametrize('lam', [LAMBDA0, (-0.36, 0.48, -0.48, 0.64), (0.02, 0.6, 0.0, -0.8)])
def test_kinematic_law_16_gives_exact_exponential_decay_of_rho(lam):
    """2 dLambda/dt = Lambda . y (8) with y = y* (16): rho = 2(1 - |l0|) = rho0 exp(-alpha t)."""
    q = attitude.from_scalar_first(np.asarray(lam) / np.linalg.norm(lam))

    def f(x):
        return attitude.derivative(x, target_rate_three_axis(x, ALPHA))

    rho0, h = 2.0 * (1.0 - abs(q[3])), 1.0
    for i in range(1, 1501):
        q = _rk4(f, q, h)
        if i % 100 == 0:
            rho = 2.0 * (1.0 - abs(q[3]) / np.linalg.norm(q))
            assert rho == pytest.approx(rho0 * math.exp(-ALPHA * i * h), rel=1e-7, abs=1e-12)


def test_kinematic_law_21_gives_exact_exponential_decay_of_rho():
    """ds/dt = s x y (18) with y = y* (21): rho = 1 - xi^T s = rho0 exp(-alpha t)."""
    xi = np.array([0.0, 0.0, 1.0])
    s = np.array([0.6, -0.48, -0.64])                       # 130 deg away from xi
    s /= np.linalg.norm(s)

    def f(x):
        return np.cross(x, target_rate_one_axis(x, xi, ALPHA))

    rho0, h = 1.0 - xi @ s, 1.0
    for i in range(1, 1501):
        s = _rk4(f, s, h)
        if i % 100 == 0:
            rho = 1.0 - xi @ s / np.linalg.norm(s)
            assert rho == pytest.approx(rho0 * math.exp(-ALPHA * i * h), rel=1e-7)


# ------------------------------------------------------------------ two-stage, gains, config
def test_two_stage_switches_once_on_angle_and_rate_then_resets():
    ctrl = MagneticController(mode='two_stage', switch_angle_deg=15.0, switch_rate_deg_s=0.2)
    b = [1e-5, 2e-5, 3e-5]
    q10 = attitude.from_axis_angle([1.0, 0.0, 0.0], math.radians(10.0))   # z 10 deg off
    q20 = attitude.from_axis_angle([1.0, 0.0, 0.0], math.radians(20.0))
    _, e_n10 = orbit_axes_in_body(q10)
    slow = W0 * e_n10 + np.radians([0.1, 0.0, 0.0])          # |y| = 0.1 deg/s
    fast = W0 * e_n10 + np.radians([0.3, 0.0, 0.0])          # |y| = 0.3 deg/s
    assert ctrl.law(_est(q10, fast), None, b, 0, 2).info['stage'] == 'one_axis'
    assert ctrl.law(_est(q20, np.zeros(3)), None, b, 2, 2).info['stage'] == 'one_axis'
    assert ctrl.law(_est(q10, slow), None, b, 4, 2).info['stage'] == 'three_axis'
    assert ctrl.law(_est(q20, fast), None, b, 6, 2).info['stage'] == 'three_axis'  # latched
    ctrl.reset()
    assert ctrl.stage == 'one_axis'
    one = MagneticController(mode='one_axis')
    assert one.law(_est(q10, slow), None, b, 0, 2).info['stage'] == 'one_axis'


def test_gain_check_refuses_bad_gains():
    with pytest.raises(ValueError, match='alpha'):
        MagneticController(alpha=0.0)
    with pytest.raises(ValueError, match='alpha'):
        MagneticController(alpha=-1e-3)
    with pytest.raises(ValueError, match='k must'):
        MagneticController(k=0.0)
    with pytest.raises(ValueError, match='k must'):
        MagneticController(k=float('nan'))
    # beta = 2e-3 J: beta / (2 alpha) = 2e-3 / 6e-3 = 0.333 > k = 0.2: violated (28)
    with pytest.raises(ValueError, match=r'k > beta / \(2 alpha Sigma\*\).*0\.333333'):
        MagneticController(alpha=ALPHA, k=K, beta=2e-3)
    # beta = 1e-3 J: bound 0.1667 < 0.2: accepted; with Sigma* = 0.5 the bound is 0.333
    MagneticController(alpha=ALPHA, k=K, beta=1e-3)
    with pytest.raises(ValueError, match='eq. \\(28\\)'):
        MagneticController(alpha=ALPHA, k=K, beta=1e-3, sigma_star=0.5)
    with pytest.raises(ValueError, match='sigma_star'):
        check_gains(ALPHA, K, None, sigma_star=1.5)
    check_gains(ALPHA, K)                                   # beta free: only alpha, k > 0
    for kw, word in [({'mode': 'x'}, 'mode'), ({'max_dipole_Am2': [40, 0, 40]}, 'max_dipole'),
                     ({'max_dipole_Am2': [40, 40]}, 'max_dipole'),
                     ({'switch_angle_deg': 180.0}, 'switch_angle_deg'),
                     ({'switch_rate_deg_s': 0.0}, 'switch_rate_deg_s'),
                     ({'xi_body': [0, 0, 0]}, 'xi_body'), ({'n_wheels': -1}, 'n_wheels'),
                     ({'b_min_T': 0.0}, 'b_min_T')]:
        with pytest.raises(ValueError, match=word):
            MagneticController(**kw)
    assert MagneticController(n_wheels=4).law(
        _est([0, 0, 0, 1.0], np.zeros(3)), None, [0, 0, 3e-5], 0, 2).wheel_torque.shape == (4,)


# ------------------------------------------------------- closed loop (model written here)
class _World:
    """Rigid body on a circular 690 km, i = 98 deg orbit (RAAN 0, u(0) = 0), gravity gradient
    3 w0^2 e_R x I e_R, tilted dipole field (B0 = 3e-5 T, pole 79 N 71 W, rotating with the
    Earth, Greenwich angle 0 at t = 0). Orbit frame: x = v, y = h, z = r (zenith)."""

    MU, R = 3.986004418e14, 6378137.0 + 690e3
    INC, WE = math.radians(98.0), 7.2921e-5
    J = np.diag([118.0, 118.0, 19.6])
    JINV = np.linalg.inv(J)

    def __init__(self):
        self.w0 = math.sqrt(self.MU / self.R ** 3)
        self.period = 2 * math.pi / self.w0
        th, ph = math.radians(11.0), math.radians(-71.0)
        self.pole = np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph),
                              math.cos(th)])
        self.bs = 3.0e-5 * (6371.2e3 / self.R) ** 3

    @staticmethod
    def cross(a, b):
        return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                         a[0] * b[1] - a[1] * b[0]])

    @staticmethod
    def qmul(p, q):
        px, py, pz, pw = p
        qx, qy, qz, qw = q
        return np.array([pw * qx + px * qw + py * qz - pz * qy,
                         pw * qy - px * qz + py * qw + pz * qx,
                         pw * qz + px * qy - py * qx + pz * qw,
                         pw * qw - px * qx - py * qy - pz * qz])

    @staticmethod
    def qmat(q):
        x, y, z, w = q
        return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])

    def r_hat(self, t):
        u = self.w0 * t
        return np.array([math.cos(u), math.sin(u) * math.cos(self.INC),
                         math.sin(u) * math.sin(self.INC)])

    def q_eci_orbit(self, t):
        """Rx(i) Rz(u) times the cyclic permutation (x_o, y_o, z_o) = (y_p, z_p, x_p)."""
        qi = [math.sin(self.INC / 2), 0.0, 0.0, math.cos(self.INC / 2)]
        qu = [0.0, 0.0, math.sin(self.w0 * t / 2), math.cos(self.w0 * t / 2)]
        return self.qmul(self.qmul(qi, qu), [0.5, 0.5, 0.5, 0.5])

    def b_eci(self, t, r):
        g = self.WE * t
        p = self.pole
        m = -np.array([math.cos(g) * p[0] - math.sin(g) * p[1],
                       math.sin(g) * p[0] + math.cos(g) * p[1], p[2]])
        return self.bs * (3.0 * (m @ r) * r - m)

    def deriv(self, t, q, w, dipole):
        rot_t = self.qmat(q).T
        r = self.r_hat(t)
        b = rot_t @ self.b_eci(t, r)
        e_r = rot_t @ r
        tau = (self.cross(dipole, b) + 3 * self.w0 ** 2 * self.cross(e_r, self.J @ e_r)
               - self.cross(w, self.J @ w))
        x, y, z, s = q
        q_dot = 0.5 * np.array([s * w[0] + y * w[2] - z * w[1], s * w[1] + z * w[0] - x * w[2],
                                s * w[2] + x * w[1] - y * w[0], -x * w[0] - y * w[1] - z * w[2]])
        return q_dot, self.JINV @ tau

    def run(self, ctrl, orbits, h=2.0, lam=LAMBDA0, omega_deg=OMEGA0_DEG):
        """Closed loop from the paper's initial state; returns t, attitude error to the orbit
        frame [deg], |omega| [deg/s], dipoles, commands."""
        q_ob = attitude.from_scalar_first(lam)
        q = self.qmul(self.q_eci_orbit(0.0), q_ob)
        w = np.radians(omega_deg)
        ts, errs, rates, dips, cmds = [], [], [], [], []
        for i in range(int(round(orbits * self.period / h))):
            t = i * h
            q_eo = self.q_eci_orbit(t)
            q_ob = self.qmul([-q_eo[0], -q_eo[1], -q_eo[2], q_eo[3]], q)
            b = self.qmat(q).T @ self.b_eci(t, self.r_hat(t))
            cmd = ctrl.law(Estimate(q_ob, w.copy(), self.w0, True), None, b, t, h)
            ts.append(t)
            errs.append(math.degrees(2 * math.acos(min(1.0, abs(q_ob[3])))))
            rates.append(math.degrees(np.linalg.norm(w)))
            dips.append(cmd.dipole_body)
            cmds.append(cmd)
            d = cmd.dipole_body
            k1 = self.deriv(t, q, w, d)
            k2 = self.deriv(t + h / 2, q + h / 2 * k1[0], w + h / 2 * k1[1], d)
            k3 = self.deriv(t + h / 2, q + h / 2 * k2[0], w + h / 2 * k2[1], d)
            k4 = self.deriv(t + h, q + h * k3[0], w + h * k3[1], d)
            q = q + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            q /= np.linalg.norm(q)
            w = w + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        return np.array(ts), np.array(errs), np.array(rates), np.array(dips), cmds


def _capture_orbits(world, ts, errs, limit_deg=5.0):
    """First time after which the error stays below ``limit_deg`` (digest 3.6), in orbits."""
    above = np.nonzero(errs >= limit_deg)[0]
    if len(above) == 0:
        return 0.0
    if above[-1] + 1 >= len(ts):
        return math.inf
    return ts[above[-1] + 1] / world.period


def test_closed_loop_three_axis_capture_from_the_paper_initial_state():
    """Measured (ideal knowledge, no disturbance): capture (error < 5 deg for good) after
    2.96 orbits, error at 4.5 orbits ~0.05 deg, |omega| -> omega0. The digest's own check
    gave ~2.6 orbits; the paper (with estimator and disturbances) 3-4 orbits."""
    world = _World()
    ctrl = MagneticController(alpha=ALPHA, k=K, max_dipole_Am2=L_MAX, beta=1e-3)
    ts, errs, rates, dips, _ = world.run(ctrl, 4.5)
    capture = _capture_orbits(world, ts, errs)
    last = ts >= 4.0 * world.period
    print(f'\nthree-axis: capture {capture:.2f} orbits, error at end {errs[-1]:.3f} deg, '
          f'max error in the last half orbit {errs[last].max():.3f} deg, '
          f'|omega| at end {rates[-1]:.4f} deg/s')
    assert capture < 3.3
    assert errs[last].max() < 0.5
    assert rates[-1] == pytest.approx(math.degrees(world.w0), rel=0.02)
    assert np.all(np.abs(dips) <= L_MAX)
    assert np.max(np.abs(dips)) == pytest.approx(L_MAX)          # it did saturate


def test_closed_loop_two_stage_aligns_z_then_captures():
    """Measured: the one-axis stage brings body z to the vertical and hands over during the
    third orbit; three-axis capture (< 5 deg for good) after ~3.5 orbits."""
    world = _World()
    ctrl = MagneticController(mode='two_stage', alpha=ALPHA, k=K, max_dipole_Am2=L_MAX)
    ts, errs, rates, dips, cmds = world.run(ctrl, 4.5)
    stages = [c.info['stage'] for c in cmds]
    t_switch = ts[stages.index('three_axis')] / world.period
    assert stages[0] == 'one_axis' and stages[-1] == 'three_axis'
    i_sw = stages.index('three_axis')
    assert 'one_axis' not in stages[i_sw:]
    assert cmds[i_sw].info['axis_angle_rad'] < math.radians(15.0)    # z on the vertical
    assert cmds[i_sw - 1].info['angle_rad'] == cmds[i_sw - 1].info['axis_angle_rad']
    capture = _capture_orbits(world, ts, errs)
    print(f'\ntwo-stage: switch at {t_switch:.2f} orbits, capture {capture:.2f} orbits, '
          f'error at end {errs[-1]:.3f} deg')
    assert capture < 4.0 and errs[-1] < 1.0
    assert np.all(np.abs(dips) <= L_MAX)


def test_closed_loop_bdot_reduces_the_tumble():
    """B-dot (k_b = 1e8 A m^2 s/T, 40 A m^2) from the paper's 5.2 deg/s tumble for one orbit;
    measured |omega| 5.20 -> 1.35 deg/s. Without control the rate stays near 5 deg/s."""
    world = _World()
    _, _, rates, dips, cmds = world.run(BdotController(1e8, L_MAX), 1.0)
    print(f'\nB-dot: |omega| {rates[0]:.2f} -> {rates[-1]:.2f} deg/s in one orbit')
    assert rates[-1] < 0.35 * rates[0]
    assert np.all(np.abs(dips) <= L_MAX)
    assert 'first' in cmds[0].reason and np.all(dips[0] == 0.0)

    class _Off:
        def law(self, *args):
            return Command.zero()

    _, _, free, _, _ = world.run(_Off(), 0.25)
    assert free[-1] > 0.8 * free[0]
