"""Quaternion conventions pinned against independent truth (scipy, hand rotations, paper 000)."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from adcs_nodes.core import attitude as att

RNG = np.random.default_rng(7)


def random_q(n=50):
    return [att.normalize(RNG.normal(size=4)) for _ in range(n)]


def test_storage_is_scalar_last_like_geometry_msgs_and_scipy():
    assert list(att.identity()) == [0.0, 0.0, 0.0, 1.0]
    q = att.from_axis_angle([0, 0, 1], np.pi / 2)
    assert q == pytest.approx([0, 0, np.sqrt(0.5), np.sqrt(0.5)])
    for q in random_q():
        assert np.allclose(att.to_matrix(q), Rotation.from_quat(q).as_matrix(), atol=1e-12)


def test_q_a_b_maps_b_components_into_a():
    # frame B is frame A turned +90 deg about z: B's x axis is A's y axis
    q_a_b = att.from_axis_angle([0, 0, 1], np.pi / 2)
    # a matrix from the quaternion (a few eps an entry) times a vector (3 terms, BLAS may fuse
    # them): 8 eps holds on any x86-64 CPU; 1 eps measured here
    tol = 8 * np.finfo(float).eps
    assert np.allclose(att.rotate(q_a_b, [1, 0, 0]), [0, 1, 0], rtol=0, atol=tol)
    # composition: q_A_C = q_A_B (x) q_B_C
    q_b_c = att.from_axis_angle([1, 0, 0], np.pi / 2)     # C's y axis is B's z axis
    q_a_c = att.multiply(q_a_b, q_b_c)
    assert np.allclose(att.rotate(q_a_c, [0, 1, 0]), [0, 0, 1], rtol=0, atol=tol)
    for p, q in zip(random_q(), random_q()):
        assert np.allclose(att.to_matrix(att.multiply(p, q)),
                           att.to_matrix(p) @ att.to_matrix(q), atol=1e-12)
        assert np.allclose(att.multiply(p, att.conjugate(p)), att.identity(), atol=1e-12)


def test_antipodal_quaternions_are_the_same_attitude():
    for q in random_q():
        assert np.allclose(att.to_matrix(q), att.to_matrix(-q), atol=1e-15)
        assert att.angle_between(q, -q) == pytest.approx(0.0, abs=1e-7)
        assert att.canonical(-q)[3] >= 0.0
        assert np.allclose(att.to_rotation_vector(q), att.to_rotation_vector(-q), atol=1e-12)


def test_matrix_round_trip_and_rotation_vector_against_scipy():
    for q in random_q():
        back = att.from_matrix(att.to_matrix(q))
        assert att.angle_between(back, q) < 1e-7
        rv = att.to_rotation_vector(q)
        assert np.allclose(Rotation.from_rotvec(rv).as_matrix(), att.to_matrix(q), atol=1e-12)
        assert np.linalg.norm(rv) <= np.pi + 1e-12
        assert att.angle_between(att.from_rotation_vector(rv), q) < 1e-7
    # 180 deg rotation (w = 0) survives the round trip
    q180 = att.from_axis_angle([1, 1, 0], np.pi)
    assert att.angle_between(att.from_matrix(att.to_matrix(q180)), q180) < 1e-7


def test_euler_321_is_yaw_pitch_roll():
    roll, pitch, yaw = 0.1, -0.2, 2.5
    q = att.from_euler_321(roll, pitch, yaw)
    ref = Rotation.from_euler('ZYX', [yaw, pitch, roll]).as_matrix()   # intrinsic z-y'-x''
    assert np.allclose(att.to_matrix(q), ref, atol=1e-12)
    assert np.allclose(att.to_euler_321(q), [roll, pitch, yaw], atol=1e-12)


def test_kinematics_match_a_constant_rate_rotation():
    w = np.array([0.01, -0.02, 0.03])
    q0 = random_q(1)[0]
    # exact: q(t) = q0 (x) exp(w t / 2)
    t, h, q = 20.0, 0.01, q0.copy()
    for _ in range(int(t / h)):   # RK4 on dq/dt = 1/2 q (x) [w, 0]
        k1 = att.derivative(q, w)
        k2 = att.derivative(q + 0.5 * h * k1, w)
        k3 = att.derivative(q + 0.5 * h * k2, w)
        k4 = att.derivative(q + h * k3, w)
        q = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    exact = att.multiply(q0, att.from_rotation_vector(w * t))
    assert att.angle_between(q, exact) < 1e-9


def test_paper000_lambda_is_q_orbit_body_scalar_first():
    """Paper 000 eq. (10): e_R and e_N are the orbit z and y axes in body components."""
    lam = np.array([0.36, 0.48, -0.48, 0.64])            # Lambda(0), scalar first
    l0, l1, l2, l3 = lam
    e_r = [2 * (l1 * l3 - l0 * l2), 2 * (l2 * l3 + l0 * l1), l0**2 - l1**2 - l2**2 + l3**2]
    e_n = [2 * (l1 * l2 + l0 * l3), l0**2 - l1**2 + l2**2 - l3**2, 2 * (l2 * l3 - l0 * l1)]
    q_orbit_body = att.from_scalar_first(lam)
    r_body_orbit = att.to_matrix(q_orbit_body).T
    assert np.allclose(r_body_orbit @ [0, 0, 1], e_r, atol=1e-12)
    assert np.allclose(r_body_orbit @ [0, 1, 0], e_n, atol=1e-12)
    assert np.allclose(att.to_scalar_first(q_orbit_body), lam)


@pytest.mark.parametrize('bad', [
    lambda: att.normalize([0, 0, 0, 0]),
    lambda: att.normalize([np.nan, 0, 0, 1]),
    lambda: att.multiply([0, 0, 1], [0, 0, 0, 1]),
    lambda: att.from_matrix(np.diag([1.0, 1.0, -1.0])),
    lambda: att.from_axis_angle([0, 0, 0], 1.0),
    lambda: att.rotate([0, 0, 0, 1], [1, np.inf, 0]),
])
def test_bad_inputs_raise_value_error(bad):
    with pytest.raises(ValueError):
        bad()


def test_finiteness_checks_accept_finite_values_whose_sum_overflows():
    """The fast check sums the values; a sum that overflows falls back to the exact one."""
    from adcs_nodes.core.samples import all_finite
    big = [1e308, 1e308, -1e308]
    np.testing.assert_array_equal(att.as_vec3(big), big)
    assert all_finite(np.array(big), np.array([1e308, 1e308, 0.0, 1.0]))
    assert att.conjugate([1e308, 1e308, 0.0, 1.0])[3] == 1.0
    for bad in ([1.0, np.inf, -np.inf], [1e308, 1e308, np.nan]):
        assert not all_finite(np.array(bad))
        with pytest.raises(ValueError, match='not finite'):
            att.as_vec3(bad)
    with pytest.raises(ValueError, match='not finite'):
        att.normalize([np.inf, -np.inf, 0.0, 1.0])       # inf - inf: the sum is NaN
