"""Eigenaxis geometry of paper 003, against scipy's rotations and the digest's numbers."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from adcs_nodes.core import attitude
from adcs_nodes.core.control import eigenaxis as ea

RNG = np.random.default_rng(3)


def _rotvecs():
    """Random rotation vectors plus angles near 0 and near 180 deg."""
    out = [Rotation.random(random_state=7 + i).as_rotvec() for i in range(20)]
    for angle in (1e-9, 1e-7, 1e-4, 1e-2, math.pi - 1e-2, math.pi - 1e-4, math.pi - 1e-7,
                  math.pi):
        axis = RNG.normal(size=3)
        out.append(angle * axis / np.linalg.norm(axis))
    return out


def test_dcm_euler_321_is_scipy_zyx_transposed_and_the_printed_row_is_a_typo():
    psi, theta, gamma = np.radians([34.0, -7.5, 16.5])
    a = ea.dcm_euler_321(psi, theta, gamma)
    expected = Rotation.from_euler('ZYX', [psi, theta, gamma]).as_matrix().T
    np.testing.assert_allclose(a, expected, atol=1e-15)
    cp, sp, st, cg, sg = (np.cos(psi), np.sin(psi), np.sin(theta), np.cos(gamma),
                          np.sin(gamma))
    printed = a.copy()
    printed[2, :2] = [cg * st * sp + sg * sp, cg * st * cp - sg * cp]   # as printed in (1)
    assert np.abs(printed @ printed.T - np.eye(3)).max() > 0.04      # digest: about 0.045


@pytest.mark.parametrize('rv', _rotvecs())
def test_eigen_from_dcm_and_quaternion_match_scipy_rotation_vector(rv):
    angle = float(np.linalg.norm(rv))
    e_true = rv / angle
    r = Rotation.from_rotvec(rv)
    a = r.as_matrix().T                  # v_body = A v_target: A is R(q_target_body)^T
    q = r.as_quat()                      # scipy is scalar last too
    for phi, e in (ea.eigen_from_dcm(a), ea.eigen_from_quaternion(q)):
        assert phi == pytest.approx(angle, abs=1e-12)
        if angle < math.pi - 1e-6:
            np.testing.assert_allclose(e, e_true, atol=1e-8)
        else:                            # the sign is free at 180 deg
            np.testing.assert_allclose(abs(float(e @ e_true)), 1.0, atol=1e-8)
    # With the previous axis, the sign is kept through 180 deg.
    for phi, e in (ea.eigen_from_dcm(a, e_true), ea.eigen_from_quaternion(q, e_true)):
        np.testing.assert_allclose(e, e_true, atol=1e-8)


def test_axis_sign_is_kept_across_180_deg_and_angle_continues():
    axis = np.array([0.2, -0.5, 0.84])
    axis /= np.linalg.norm(axis)
    e_prev = axis
    angles = np.radians(np.linspace(179.0, 180.8, 19))
    for ang in angles:                          # rotating past 180 deg about +axis
        q = attitude.from_axis_angle(axis, ang)
        phi, e = ea.eigen_from_quaternion(q, e_prev)
        phi_d, e_d = ea.eigen_from_dcm(attitude.to_matrix(q).T, e_prev)
        np.testing.assert_allclose(e, axis, atol=1e-9)
        np.testing.assert_allclose(e_d, axis, atol=1e-7)
        assert phi == pytest.approx(ang, abs=1e-9)
        assert phi_d == pytest.approx(ang, abs=1e-7)
        e_prev = e


def test_zero_angle_gives_the_previous_axis_or_zeros():
    prev = np.array([0.0, 0.6, 0.8])
    assert ea.eigen_from_quaternion([0, 0, 0, 1.0])[0] == 0.0
    np.testing.assert_array_equal(ea.eigen_from_quaternion([0, 0, 0, 1.0])[1], np.zeros(3))
    np.testing.assert_array_equal(ea.eigen_from_dcm(np.eye(3), prev)[1], prev)


def test_paper_scenario_numbers_of_the_digest():
    a = ea.dcm_euler_321(*np.radians([34.0, -7.5, 16.5]))
    phi, e = ea.eigen_from_dcm(a)
    assert math.degrees(phi) == pytest.approx(39.34, abs=0.005)
    np.testing.assert_allclose(e, [0.4630, -0.0595, 0.8844], atol=1e-4)
    e_k, j_k = ea.torque_direction([250.0, 200.0, 180.0], e)
    np.testing.assert_allclose(e_k, [0.5870, -0.0604, 0.8073], atol=1e-4)
    assert j_k == pytest.approx(197.2, abs=0.05)


def test_torque_direction_accelerates_along_the_axis():
    J = np.array([[250.0, 3.0, -2.0], [3.0, 200.0, 1.0], [-2.0, 1.0, 180.0]])
    for _ in range(10):
        e = RNG.normal(size=3)
        e /= np.linalg.norm(e)
        e_k, j_k = ea.torque_direction(J, e)
        assert np.linalg.norm(e_k) == pytest.approx(1.0)
        np.testing.assert_allclose(np.linalg.solve(J, 2.0 * e_k), 2.0 / j_k * e, atol=1e-14)


def test_phi_dot_is_the_time_derivative_of_the_eigenangle():
    q = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_quat()
    w = np.array([0.01, -0.02, 0.015])
    phi, e = ea.eigen_from_quaternion(q)
    phi_dot, wg, g = ea.gyroscopic_rate(w, e)
    h = 1e-5
    q2 = (Rotation.from_quat(q) * Rotation.from_rotvec(w * h)).as_quat()   # body rate w
    assert (ea.eigen_from_quaternion(q2)[0] - phi) / h == pytest.approx(phi_dot, rel=1e-5)
    assert float(wg @ e) == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose(wg + phi_dot * e, w)
    assert g == pytest.approx(np.linalg.norm(w - (w @ e) * e))


def test_rate_modulus_derivative_backward_difference():
    d = ea.RateModulusDerivative()
    assert d.update(0.3, 0.1) == 0.0                 # first sample
    assert d.update(0.25, 0.1) == pytest.approx(-0.5)
    assert d.update(float('nan'), 0.1) == 0.0        # bad sample not stored
    assert d.update(0.35, 0.1) == pytest.approx(1.0)
    assert d.update(0.4, 0.0) == 0.0                 # bad period
    d.reset()
    assert d.update(1.0, 0.1) == 0.0
