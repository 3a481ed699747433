"""Paper 000's magnetometer-only estimator against independent truth (no ROS).

The truth here is written independently of the filter: the paper's quaternion algebra in
scalar-first form with its own Hamilton product, scipy ``solve_ivp`` integrations, and for the
closed-loop runs a rigid body propagated in ECI (absolute kinematics, gravity gradient from the
position) and then expressed in the orbit frame.
"""
import math
from datetime import datetime, timezone

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm, logm
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from adcs_nodes.core import attitude
from adcs_nodes.core.estimation import magnetic_filter as mf
from adcs_nodes.core.estimation.magnetic_filter import MagneticFilter
from adcs_nodes.core.estimation.onboard import OnboardReference
from adcs_nodes.core.geomag import DipoleField
from adcs_nodes.core.orbit import MU_EARTH, CircularOrbit

EPOCH = datetime(2024, 3, 1, tzinfo=timezone.utc)
I_PAPER = np.diag([118.0, 118.0, 19.6])  # paper 000 example [kg m^2]
I_TEST = np.diag([100.0, 130.0, 40.0])  # all moments different: every entry of G is non-zero
B_ORBIT = np.array([12e-6, -3e-6, -38e-6])  # a LEO-sized field in orbit axes [T]


# --------------------------------------------------------------- independent paper algebra
def qmul_sf(a, b):
    """Hamilton product, scalar FIRST (paper 000, digest 1.3)."""
    a0, av, b0, bv = a[0], np.asarray(a[1:]), b[0], np.asarray(b[1:])
    return np.r_[a0 * b0 - av @ bv, a0 * bv + b0 * av + np.cross(av, bv)]


def conj_sf(a):
    return np.r_[a[0], -np.asarray(a[1:])]


def orbit_to_body_sf(lam, r_orbit):
    """``r_E = conj(Lambda) . r_J . Lambda`` (paper (2), (10))."""
    return qmul_sf(qmul_sf(conj_sf(lam), np.r_[0.0, r_orbit]), lam)[1:]


def angle(q1, q2):
    """Rotation angle [rad] between two scalar-last quaternions, accurate near zero."""
    return (Rotation.from_quat(q1).inv() * Rotation.from_quat(q2)).magnitude()


def random_lambda(rng):
    lam = rng.normal(size=4)
    return lam / np.linalg.norm(lam)


def paper_rhs(inertia, omega0, m, dipole=np.zeros(3), b_body=np.zeros(3)):
    """(33) written independently, state ``[Lambda (scalar first), omega]``."""
    i_inv = np.linalg.inv(inertia)

    def f(_t, x):
        lam, w = x[:4], x[4:]
        e_r = orbit_to_body_sf(lam / np.linalg.norm(lam), [0.0, 0.0, 1.0])
        m_s = 3 * omega0 ** 2 * np.cross(e_r, inertia @ e_r) + np.cross(dipole, b_body)
        lam_dot = 0.5 * (qmul_sf(lam, np.r_[0.0, w]) - qmul_sf([0.0, 0.0, omega0, 0.0], lam))
        return np.r_[lam_dot, i_inv @ (np.cross(inertia @ w, w) + m_s) + m]
    return f


def propagate_paper(inertia, omega0, lam, w, m, dt, **kw):
    sol = solve_ivp(paper_rhs(inertia, omega0, m, **kw), (0.0, dt), np.r_[lam, w],
                    method='DOP853', rtol=1e-13, atol=1e-15)
    x = sol.y[:, -1]
    return x[:4] / np.linalg.norm(x[:4]), x[4:]


def error_state(lam_true, w_true, m_true, lam_est, w_est, m_est):
    """``w = [mu, d_omega, d_m]`` with ``M = conj(Lambda) . N`` (paper, section 3)."""
    big_m = qmul_sf(conj_sf(lam_true), lam_est)
    if big_m[0] < 0:
        big_m = -big_m
    return np.r_[big_m[1:], w_est - w_true, m_est - m_true]


# ------------------------------------------------------------------- convention boundary
def test_lambda_boundary_pins_eq10():
    rng = np.random.default_rng(10)
    for _ in range(20):
        lam = random_lambda(rng)
        l0, l1, l2, l3 = lam
        q = mf.q_orbit_body_from_lambda(lam)
        np.testing.assert_allclose(q, [l1, l2, l3, l0])
        np.testing.assert_allclose(mf.lambda_from_q_orbit_body(q), lam)
        e_r_10 = [2 * (l1 * l3 - l0 * l2), 2 * (l2 * l3 + l0 * l1), l0 ** 2 - l1 ** 2 - l2 ** 2
                  + l3 ** 2]  # (10), as printed
        e_n_10 = [2 * (l1 * l2 + l0 * l3), l0 ** 2 - l1 ** 2 + l2 ** 2 - l3 ** 2,
                  2 * (l2 * l3 - l0 * l1)]
        np.testing.assert_allclose(mf.dcm(q)[2], e_r_10, atol=1e-14)
        np.testing.assert_allclose(mf.dcm(q)[1], e_n_10, atol=1e-14)
        # n* = conj(N) . B* . N with the paper's own product
        np.testing.assert_allclose(mf.predicted_field_body(q, B_ORBIT),
                                   orbit_to_body_sf(lam, B_ORBIT), atol=1e-19)
        # and q is q_orbit_body in the project's convention: v_orbit = R(q) v_body
        np.testing.assert_allclose(attitude.rotate(q, mf.dcm(q)[2]), [0, 0, 1], atol=1e-14)
    flt = MagneticFilter(I_PAPER)
    lam0 = np.array([0.36, 0.48, -0.48, 0.64])
    flt.reset(mf.q_orbit_body_from_lambda(lam0), np.zeros(3))
    np.testing.assert_allclose(mf.lambda_from_q_orbit_body(flt.q_orbit_body), lam0, atol=1e-15)


def g_matrix(inertia, v):
    """The filter's own ``G(v)`` (35), as its error-matrix kernel computes it."""
    inertia = np.asarray(inertia, dtype=float)
    return mf._g_k(inertia, np.linalg.inv(inertia), np.asarray(v, dtype=float))


def test_g_matrix_is_table_35():
    ix, iy, iz = 100.0, 130.0, 40.0
    b1, b2, b3 = (iy - iz) / ix, (iz - ix) / iy, (ix - iy) / iz
    w1, w2, w3 = 0.03, -0.07, 0.05
    table = [[0, b1 * w3, b1 * w2], [b2 * w3, 0, b2 * w1], [b3 * w2, b3 * w1, 0]]
    np.testing.assert_allclose(g_matrix(I_TEST, [w1, w2, w3]), table, atol=1e-15)
    a, b, c = 0.6, -0.48, 0.64  # G(e_R) Phi(e_R) written out (digest 4.3)
    out = [[b1 * (c * c - b * b), b1 * a * b, -b1 * a * c],
           [-b2 * a * b, b2 * (a * a - c * c), b2 * b * c],
           [b3 * a * c, -b3 * b * c, b3 * (b * b - a * a)]]
    np.testing.assert_allclose(g_matrix(I_TEST, [a, b, c]) @ attitude.skew([a, b, c]), out,
                               atol=1e-15)


# ------------------------------------------------------------------ linearised models
def _transition_by_finite_differences(lam, w, m, omega0, dt):
    """Columns: central differences of the error state after dt, both states propagated by (33)."""
    lam_t, w_t = propagate_paper(I_TEST, omega0, lam, w, m, dt)
    eps = np.r_[[1e-5] * 3, [1e-6] * 3, [1e-7] * 3]
    phi_fd = np.zeros((9, 9))
    for k in range(9):
        cols = []
        for sgn in (1.0, -1.0):
            dx = np.zeros(9)
            dx[k] = sgn * eps[k]
            mu = dx[:3]
            big_m = np.r_[math.sqrt(1 - mu @ mu), mu]  # N = Lambda . M
            lam_e, w_e = propagate_paper(I_TEST, omega0, qmul_sf(lam, big_m), w + dx[3:6],
                                         m + dx[6:], dt)
            cols.append(error_state(lam_t, w_t, m, lam_e, w_e, m + dx[6:]))
        phi_fd[:, k] = (cols[0] - cols[1]) / (2 * eps[k])
    return phi_fd


def test_error_matrix_34_against_finite_differences_of_33():
    """Perturb the error state, propagate truth and estimate by (33), compare with expm(A dt)."""
    omega0 = 0.02  # exaggerated so that the gravity-gradient block is well above round-off
    lam = random_lambda(np.random.default_rng(3))
    w = np.array([0.05, -0.03, 0.08])
    m = np.array([1e-6, -2e-6, 3e-6])
    a = mf.error_matrix_kernel(I_TEST, np.linalg.inv(I_TEST), omega0,
                               mf.q_orbit_body_from_lambda(lam), np.asarray(w, dtype=float))
    fd = {dt: _transition_by_finite_differences(lam, w, m, omega0, dt) for dt in (0.2, 0.1)}
    # F = expm(A dt) freezes A over dt, so in every block the mismatch must shrink as dt^2 (or
    # faster); a wrong entry of A would leave an O(dt) mismatch (ratio 2 instead of 4).
    # Measured ratios: 4.0, 8.0, 4.0, 4.0, 8.0, 16; mismatch/change at dt = 0.1: <= 0.34 %.
    blocks = [(slice(0, 3), slice(0, 3)), (slice(0, 3), slice(3, 6)), (slice(3, 6), slice(0, 3)),
              (slice(3, 6), slice(3, 6)), (slice(3, 6), slice(6, 9)), (slice(0, 3), slice(6, 9))]
    for rows, cols in blocks:
        mism = [np.abs((fd[dt] - expm(a * dt))[rows, cols]).max() for dt in (0.2, 0.1)]
        change = np.abs((expm(a * 0.1) - np.eye(9))[rows, cols]).max()
        assert change > 1e-5  # the block is really exercised
        assert mism[0] / mism[1] > 3.5
        assert mism[1] < 0.01 * change
    assert np.abs(fd[0.1][6:] - np.eye(9)[6:]).max() < 1e-12  # d_m is constant
    # and log(phi_fd) / dt (the mean A over the step) approximates A itself
    np.testing.assert_allclose(np.real(logm(fd[0.1])) / 0.1, a, atol=2e-3 * np.abs(a).max())


def test_measurement_matrix_against_finite_differences():
    rng = np.random.default_rng(4)
    lam = random_lambda(rng)
    n = orbit_to_body_sf(lam, B_ORBIT)  # error-free reading

    def z_of(phi):
        mu0 = 1 / math.sqrt(1 + phi @ phi)
        lam_est = qmul_sf(lam, np.r_[mu0, mu0 * phi])  # N = Lambda . M
        return n - orbit_to_body_sf(lam_est, B_ORBIT)

    q = mf.q_orbit_body_from_lambda(lam)
    h = np.zeros((3, 9))                                  # H of (36), as printed
    h[:, :3] = -attitude.skew(n + mf.predicted_field_body(q, B_ORBIT))
    eps = 1e-6
    jac = np.column_stack([(z_of(eps * e) - z_of(-eps * e)) / (2 * eps) for e in np.eye(3)])
    np.testing.assert_allclose(h[:, :3], jac, atol=1e-12 * np.linalg.norm(B_ORBIT) / 1e-5)
    np.testing.assert_allclose(h[:, :3], -2 * attitude.skew(n), atol=1e-18)
    assert not h[:, 3:].any()


def test_phi_form_36_is_exact_and_37_is_third_order():
    rng = np.random.default_rng(5)
    for _ in range(20):
        lam = random_lambda(rng)
        big_m = random_lambda(rng)  # any error, up to 180 deg
        if abs(big_m[0]) < 0.05:
            continue
        n = orbit_to_body_sf(lam, B_ORBIT)
        n_star = mf.predicted_field_body(mf.q_orbit_body_from_lambda(qmul_sf(lam, big_m)),
                                         B_ORBIT)
        phi = big_m[1:] / big_m[0]
        np.testing.assert_allclose(n - n_star, -np.cross(n + n_star, phi), atol=1e-17)  # (36)
        assert abs((n - n_star) @ big_m[1:]) < 1e-18
    lam = random_lambda(rng)
    n = orbit_to_body_sf(lam, B_ORBIT)
    axis = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])
    errs = []
    for ang in (0.02, 0.04, 0.08):
        big_m = np.r_[math.cos(ang / 2), math.sin(ang / 2) * axis]
        n_star = orbit_to_body_sf(qmul_sf(lam, big_m), B_ORBIT)
        errs.append(np.linalg.norm((n - n_star) + np.cross(n + n_star, big_m[1:])))  # (37)
    ratios = np.array(errs[1:]) / np.array(errs[:-1])
    np.testing.assert_allclose(ratios, 8.0, rtol=0.02)  # O(|mu|^3)


@pytest.mark.parametrize('form', ['phi', 'mu'])
def test_correction_39_recovers_truth_when_w_is_exact(form):
    rng = np.random.default_rng(6)
    lam = random_lambda(rng)
    big_m = np.r_[0.8, 0.36, -0.48, 0.0]  # a 74 deg error
    w, m = np.array([0.01, 0.02, -0.03]), np.array([1e-8, 2e-8, 3e-8])
    d_w, d_m = np.array([1e-3, -2e-3, 5e-4]), np.array([3e-9, -1e-9, 2e-9])
    block = big_m[1:] / big_m[0] if form == 'phi' else big_m[1:]
    q, w_new, m_new = mf.correct_kernel(mf.q_orbit_body_from_lambda(qmul_sf(lam, big_m)),
                                        w + d_w, m + d_m, np.r_[block, d_w, d_m], form == 'phi')
    assert angle(q, mf.q_orbit_body_from_lambda(lam)) < 1e-12
    np.testing.assert_allclose(w_new, w, atol=1e-17)
    np.testing.assert_allclose(m_new, m, atol=1e-22)


def test_gain_and_correction_invariant_under_common_scaling():
    rng = np.random.default_rng(7)
    lam = random_lambda(rng)
    n = orbit_to_body_sf(lam, B_ORBIT) + rng.normal(scale=2e-7, size=3)
    q0 = mf.q_orbit_body_from_lambda(qmul_sf(lam, [0.9, 0.3, 0.1, -0.3]))
    results = []
    for c in (1.0, 37.0):
        flt = MagneticFilter(I_PAPER, theta=c * 9e-14, tau=c * 0.01,
                             p0_diag=c * mf.P0_PHI_DEFAULT)
        flt.reset(q0, [0.01, 0.02, 0.03])
        flt.predict(2.0, 1.06e-3)
        res = flt.update(n, B_ORBIT)
        results.append((res['correction'], res['sigma'], flt.q_orbit_body, flt.P / c))
    (w1, s1, q1, p1), (w2, s2, q2, p2) = results
    np.testing.assert_allclose(w2, w1, rtol=1e-9, atol=1e-20)
    np.testing.assert_allclose(s2, s1, rtol=1e-9)
    np.testing.assert_allclose(q2, q1, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(p2, p1, rtol=1e-9, atol=1e-25)


def test_prediction_matches_independent_integration_with_magnetic_torque():
    lam = np.array([0.36, 0.48, -0.48, 0.64])
    w = np.radians([-3.0, 3.0, 3.0])
    m = np.array([1e-8, 1e-8, 3e-8])
    dipole, b_body = np.array([20.0, -10.0, 5.0]), np.array([1e-5, -2e-5, 3e-5])
    omega0 = 1.0625e-3
    lam_t, w_t = propagate_paper(I_PAPER, omega0, lam, w, m, 10.0, dipole=dipole,
                                 b_body=b_body)
    errors = []
    for substeps in (4, 8):
        flt = MagneticFilter(I_PAPER, substeps=substeps)
        flt.reset(mf.q_orbit_body_from_lambda(lam), w, m)
        assert flt.predict(10.0, omega0, dipole, b_body_for_torque=b_body)
        errors.append((angle(flt.q_orbit_body, mf.q_orbit_body_from_lambda(lam_t)),
                       np.linalg.norm(flt.omega_body_eci_body - w_t)))
        np.testing.assert_allclose(flt.m, m)
    # RK4: halving the step divides the error by ~2^4 (measured 4.3e-6 -> 2.7e-7 rad and
    # 3.8e-8 -> 2.4e-9 rad/s), so (33) is integrated as written, torque included
    assert errors[1][0] < 5e-7 and errors[1][1] < 5e-9
    assert errors[0][0] / errors[1][0] > 10.0 and errors[0][1] / errors[1][1] > 10.0
    with pytest.raises(ValueError, match='dipole'):
        MagneticFilter(I_PAPER).predict(2.0, omega0, dipole)
    with pytest.raises(ValueError):
        flt.predict(0.0, omega0)


def test_relative_rate_7_is_zero_in_orbital_attitude():
    omega0 = 1.06e-3
    flt = MagneticFilter(I_PAPER)
    flt.reset([0.0, 0.0, 0.0, 1.0], [0.0, omega0, 0.0])  # Lambda* = 1, omega = omega0 j2
    y = flt.omega_body_eci_body - omega0 * mf.dcm(flt.q_orbit_body)[1]    # (7)
    np.testing.assert_allclose(y, 0.0, atol=1e-20)
    flt.predict(2.0, omega0)  # a relative equilibrium (11): nothing moves
    np.testing.assert_allclose(flt.q_orbit_body, [0, 0, 0, 1], atol=1e-15)


# --------------------------------------------------------------------- bad measurements
@pytest.mark.parametrize('b_meas, b_ref', [
    ([np.nan, 1e-5, 1e-5], B_ORBIT), ([np.inf, 0, 0], B_ORBIT), ([0.0, 0.0, 0.0], B_ORBIT),
    ([1e-7, 0, 0], B_ORBIT), ([2e-3, 0, 0], B_ORBIT), ([1e-5, 1e-5], B_ORBIT),
    ('abc', B_ORBIT), (B_ORBIT, [0.0, 0.0, 0.0]), (B_ORBIT, [np.nan, 0, 1e-5]),
])
def test_bad_measurements_are_rejected_and_state_kept(b_meas, b_ref):
    flt = MagneticFilter(I_PAPER)
    flt.reset([0.1, 0.2, 0.3, 0.9], [0.01, 0.0, 0.0])
    before = (flt.q_orbit_body, flt.omega_body_eci_body, flt.m, flt.P)
    res = flt.update(b_meas, b_ref)
    assert res['accepted'] is False and res['reason']
    assert all(np.all(np.isfinite(res[k])) for k in ('innovation', 'sigma', 'correction'))
    for a, b in zip(before, (flt.q_orbit_body, flt.omega_body_eci_body, flt.m, flt.P)):
        np.testing.assert_array_equal(a, b)


def test_half_turn_error_and_huge_residuals_stay_finite():
    flt = MagneticFilter(I_PAPER, measurement_form='mu', literal_update=True, tau=10.0)
    lam = np.array([0.0, 1.0, 0.0, 0.0])  # 180 deg from the estimate: n* = -n possible
    flt.reset([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0])
    n = orbit_to_body_sf(lam, [0.0, 0.0, 4e-5])
    for _ in range(50):
        flt.update(n, [0.0, 0.0, 4e-5])
        flt.update(-n * 20, [1e-5, 0.0, 4e-5])
        flt.predict(2.0, 1e-3)
        for v in (flt.q_orbit_body, flt.omega_body_eci_body, flt.m, flt.P):
            assert np.all(np.isfinite(v))


def test_constructor_validation():
    with pytest.raises(ValueError):
        MagneticFilter(np.diag([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError):
        MagneticFilter(I_PAPER, theta=0.0)
    with pytest.raises(ValueError):
        MagneticFilter(I_PAPER, measurement_form='psi')
    with pytest.raises(ValueError):
        MagneticFilter(I_PAPER, p0_diag=np.ones(6))
    with pytest.raises(ValueError):
        MagneticFilter(I_PAPER, substeps=0)


# -------------------------------------------------------- closed loop on a tumbling body
ORBIT_PERIOD = 2 * math.pi / CircularOrbit(690e3, 0.0, epoch=EPOCH).mean_motion
T_RUN = 0.75 * ORBIT_PERIOD
M_DIST = np.array([1e-8, 1e-8, 3e-8])  # paper example, I^-1 M_r [rad/s^2]
NOISE = np.array([375e-9, 25e-9, 65e-9])  # paper example, 1 sigma per axis [T]


@pytest.fixture(scope='module')
def world():
    """Truth: 690 km / 98 deg circular orbit, aligned dipole, paper 000's tumbling body."""
    orbit = CircularOrbit(690e3, math.radians(98.0), epoch=EPOCH)
    field = DipoleField(EPOCH, pole_colatitude_rad=0.0)
    i_inv = np.linalg.inv(I_PAPER)
    lam0 = np.array([0.36, 0.48, -0.48, 0.64])
    r_eci_orbit0 = Rotation.from_quat(orbit.state(0.0).q_eci_orbit)
    q_eci_body0 = (r_eci_orbit0 * Rotation.from_quat(np.r_[lam0[1:], lam0[0]])).as_quat()

    def rhs(t, x):  # absolute kinematics in ECI, gravity gradient from the position
        q, w = x[:4], x[4:]
        r = orbit.state(t).r_eci
        r_b = Rotation.from_quat(q).inv().apply(r) / np.linalg.norm(r)
        torque = 3 * MU_EARTH / np.linalg.norm(r) ** 3 * np.cross(r_b, I_PAPER @ r_b)
        x_, y_, z_, s_ = q
        big_omega = np.array([[0, w[2], -w[1], w[0]], [-w[2], 0, w[0], w[1]],
                              [w[1], -w[0], 0, w[2]], [-w[0], -w[1], -w[2], 0]])
        return np.r_[0.5 * big_omega @ q,
                     i_inv @ (torque - np.cross(w, I_PAPER @ w)) + M_DIST]

    times = np.arange(0.0, T_RUN, 2.0)
    sol = solve_ivp(rhs, (0.0, times[-1]), np.r_[q_eci_body0, np.radians([-3.0, 3.0, 3.0])],
                    t_eval=times, method='DOP853', rtol=1e-10, atol=1e-12)
    q_eci_body = sol.y[:4].T / np.linalg.norm(sol.y[:4], axis=0)[:, None]
    return orbit, field, times, q_eci_body, sol.y[4:].T


def run_filter(world, noise, n_steps=None, seed=11, **kw):
    """Prediction every 2 s, a magnetometer update every 10 s; errors at every step."""
    orbit, field, times, q_eci_body, w_true = world
    ref = OnboardReference(orbit, field)
    omega0 = orbit.mean_motion
    rng = np.random.default_rng(seed)
    flt = MagneticFilter(I_PAPER, **kw)
    flt.reset([0.0, 0.0, 0.0, 1.0], [0.0, omega0, 0.0])  # N = {1, 0, 0, 0}, omega' = (0, w0, 0)
    rows = []
    for k, t in enumerate(times[:n_steps]):
        if k:
            flt.predict(2.0, omega0)
        st = ref.at(t)
        r_body_eci = Rotation.from_quat(q_eci_body[k]).inv()
        if k and k % 5 == 0:
            b_body = r_body_eci.apply(field.field_eci(st.r_eci, t)) + noise * rng.normal(size=3)
            flt.update(b_body, st.b_orbit)
        q_true = (Rotation.from_quat(st.q_eci_orbit).inv() * Rotation.from_quat(q_eci_body[k]))
        err = (q_true.inv() * Rotation.from_quat(flt.q_orbit_body)).as_quat()  # M = conj(L) N
        phi = err[:3] / err[3]
        e = np.r_[phi, flt.omega_body_eci_body - w_true[k]]
        p6 = flt.P[:6, :6]
        rows.append((t, 2 * math.atan(np.linalg.norm(phi)), np.linalg.norm(e[3:]),
                     float(e @ np.linalg.solve(p6, e)), np.abs(e) / np.sqrt(np.diag(p6)),
                     np.all(np.isfinite(flt.P)) and np.all(np.isfinite(flt.q_orbit_body))))
    t = np.array([r[0] for r in rows])
    return (t, np.degrees([r[1] for r in rows]), np.degrees([r[2] for r in rows]),
            np.array([r[3] for r in rows]), np.array([r[4] for r in rows]),
            all(r[5] for r in rows))


def test_converges_from_paper_initial_state_without_sensor_errors(world):
    """Start error 138 deg; measured: < 2 deg for good from 850 s (0.14 T), at most 0.65 deg
    (median 0.32 deg) and 0.008 deg/s on [T/4, T/2]. The remaining error is the estimator's:
    P shrinks during the nonlinear transient and, without noise, sigma_j ~ 1 stops re-inflating
    it (NEES about 16 here); with 4 RK4 substeps from a close start the error goes to ~0.
    """
    n_half = int(0.5 * ORBIT_PERIOD / 2.0) + 1
    t, ang, rate, _, _, finite = run_filter(world, 0.0, n_steps=n_half)
    assert finite
    assert ang[0] > 60.0  # it really starts far away (about 98 deg)
    late = t >= 0.25 * ORBIT_PERIOD
    assert ang[late].max() < 2.0
    assert rate[late].max() < 0.05  # deg/s
    assert ang[-1] < 2.0


def test_nees_with_magnetometer_noise(world):
    """Noise 375/25/65 nT, disturbance m of the paper, theta=(0.3 uT)^2, tau=0.01, P0 of digest.

    P of the guaranteed/fuzzy filter is not a Kalman covariance: theta (0.09 uT^2) exceeds the
    y and z noise variances 150 and 20 times, and sigma_j >= 1 inflates P. Measured on
    [T/4, 0.75 T] (seed 11): attitude error <= 0.71 deg (median 0.30 deg), rate error <= 0.04
    deg/s; mean NEES (6 dof) 3.8 (a consistent filter gives 6), NEES below its 97.5 % chi-square
    bound (14.4) in 100 % of samples, inside the two-sided 95 % band in 87 %; all 6 components
    inside 3 sigma of P in 100 %. So P is conservative, not overconfident: these are the
    properties tested (NEES over one run's correlated samples, not an ensemble).
    """
    t, ang, _, nees, ratio, finite = run_filter(world, NOISE)
    assert finite
    late = t >= 0.25 * ORBIT_PERIOD
    assert ang[late].max() < 2.0
    assert np.mean(nees[late] < chi2.ppf(0.975, 6)) >= 0.95
    assert np.mean((ratio[late] < 3.0).all(axis=1)) >= 0.95
    assert 0.5 < nees[late].mean() < 9.0


def test_literal_update_form_diverges_in_the_same_case(world):
    """Digest 4.5: the printed (38) (raw z_j summed) diverges from N = identity, large P0.

    Measured on [T/4, T/2]: attitude error median 132 deg (up to 180 deg), rate error median
    56 deg/s (held near the 1 rad/s guard, whose rejections keep it finite), while the standard
    form on the same data stays under 0.71 deg.
    """
    n_half = int(0.5 * ORBIT_PERIOD / 2.0) + 1
    t, ang, rate, _, _, finite = run_filter(world, NOISE, n_steps=n_half, literal_update=True)
    assert finite
    late = t >= 0.25 * ORBIT_PERIOD
    assert np.median(ang[late]) > 20.0
    assert np.median(rate[late]) > 1.0  # deg/s
