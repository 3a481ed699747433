"""Wheel allocation written once (adcs_nodes.core.control.wheel_allocation), against independent
truth: the analytic right inverse ``A^T (A A^T)^-1`` and its minimum-norm property, the torque
limits (A2) / (A3) as properties (parallel and on the box, or per-wheel clip), the momentum
headroom (A4) against the plant's own wheel model (sim_node WheelCluster.apply), and the two
users (MPI and the eigenaxis laws) realising the demanded torque on the body (W3)."""
import numpy as np
import pytest

from adcs_nodes.core.control import ControlInputs, Estimate
from adcs_nodes.core.control.eigenaxis import realise
from adcs_nodes.core.control.wheel_allocation import WheelAllocator

#: Four wheels in a pyramid (the usual 3+1 skew): spans 3-D with one redundant wheel.
BETA = np.radians(54.7356)
PYRAMID = np.array([[np.sin(BETA) * np.cos(a), np.sin(BETA) * np.sin(a), np.cos(BETA)]
                    for a in np.radians([45.0, 135.0, 225.0, 315.0])])


def _right_inverse(axes):
    """A^T (A A^T)^-1 with A (3, n) the unit axes as columns: computed without pinv/SVD."""
    a = (axes / np.linalg.norm(axes, axis=1)[:, None]).T
    return a.T @ np.linalg.inv(a @ a.T)


@pytest.mark.parametrize('axes', [np.eye(3), PYRAMID, 2.5 * PYRAMID,
                                  [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]])
def test_allocation_is_the_minimum_norm_exact_solution(axes):
    rng = np.random.default_rng(7)
    alloc = WheelAllocator(axes, np.inf)
    a = alloc.A_w
    np.testing.assert_allclose(np.linalg.norm(a, axis=0), 1.0, rtol=1e-15)   # unit axes
    null = np.linalg.svd(a)[2][3:]                                   # (n - 3, n) null space
    for _ in range(5):
        h_dot = rng.normal(size=3)
        tau = alloc.torques(h_dot)
        np.testing.assert_allclose(a @ tau, h_dot, atol=1e-13)                     # (A1)
        np.testing.assert_allclose(tau, _right_inverse(np.asarray(axes, float)) @ h_dot,
                                   atol=1e-13)
        for v in null:                    # any other exact solution is longer
            assert np.linalg.norm(tau + 0.1 * v) > np.linalg.norm(tau)
    if np.shape(axes) == (3, 3):          # orthogonal wheels: tau_w = h_dot_b
        np.testing.assert_array_equal(alloc.torques([0.3, -0.2, 0.1]), [0.3, -0.2, 0.1])


def test_scale_keeps_the_direction_and_touches_the_box():
    lim = np.array([0.1, 0.2, 0.3, 0.4])
    alloc = WheelAllocator(PYRAMID, lim, 'scale')
    rng = np.random.default_rng(3)
    for _ in range(20):
        h_dot = rng.normal(scale=0.5, size=3)
        out, sigma, raw = alloc.allocate(h_dot)
        ratio = np.max(np.abs(raw) / lim)
        assert sigma == pytest.approx(min(1.0, 1.0 / ratio), rel=1e-15)
        np.testing.assert_allclose(out, sigma * raw, rtol=1e-15, atol=1e-17)
        assert np.all(np.abs(out) <= lim)
        if ratio > 1.0:                   # saturated: one wheel exactly at its limit
            assert np.max(np.abs(out) / lim) == pytest.approx(1.0, rel=1e-15)
            # the body still gets the demanded direction, shortened by sigma
            np.testing.assert_allclose(alloc.A_w @ out, sigma * h_dot, atol=1e-13)
        else:
            np.testing.assert_array_equal(out, raw)


def test_clip_clips_each_wheel_on_its_own():
    lim = np.array([0.1, 0.2, 0.3])
    alloc = WheelAllocator(np.eye(3), lim, 'clip')
    out, sigma, raw = alloc.allocate([0.5, -0.05, -0.9])
    np.testing.assert_array_equal(raw, [0.5, -0.05, -0.9])
    np.testing.assert_array_equal(out, [0.1, -0.05, -0.3])
    assert sigma == 1.0


@pytest.mark.parametrize('saturation', ['scale', 'clip'])
def test_momentum_headroom_is_the_plant_rule(saturation):
    from sim_node.models.actuators import WheelCluster
    lim, h_max, period = 0.2, np.array([1.0, 2.0, 0.5, 3.0]), 0.5
    alloc = WheelAllocator(PYRAMID, lim, saturation, max_momentum_Nms=h_max, period_s=period)
    plant = WheelCluster(PYRAMID, max_torque=lim, max_momentum=h_max, inertia=0.01)
    rng = np.random.default_rng(11)
    for _ in range(50):
        h = rng.uniform(-1.0, 1.0, 4) * h_max            # inside the limits
        h[rng.integers(4)] = h_max[0] * np.sign(rng.normal())   # one near or at a limit
        h = np.clip(h, -h_max, h_max)
        tau = rng.normal(scale=0.3, size=4)
        out, _ = alloc.limit(tau, h)
        limited, _ = WheelAllocator(PYRAMID, lim, saturation).limit(tau)
        # the commanded torque is one the plant applies unchanged ...
        np.testing.assert_allclose(plant.apply(out, h, period), out, atol=1e-15)
        # ... and equals the plant's own rule on the torque-limited command
        np.testing.assert_allclose(out, plant.apply(limited, h, period), atol=1e-15)
        assert np.all(np.abs(h + period * out) <= h_max + 1e-12)
    # far from the limits the headroom changes nothing
    far, _ = alloc.limit([0.1, -0.1, 0.05, 0.0], np.zeros(4))
    np.testing.assert_array_equal(far, [0.1, -0.1, 0.05, 0.0])
    with pytest.raises(ValueError, match='h_w'):
        alloc.limit(np.zeros(4))


def test_bad_configuration_raises():
    with pytest.raises(ValueError, match='empty'):
        WheelAllocator(np.zeros((0, 3)), [])
    with pytest.raises(ValueError, match='span'):
        WheelAllocator([[1, 0, 0], [0, 1, 0], [1, 1, 0]], 1.0)     # coplanar
    with pytest.raises(ValueError, match='span'):
        WheelAllocator([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]], 1.0)   # a zero axis
    with pytest.raises(ValueError, match='not finite'):
        WheelAllocator([[1, 0, 0], [0, 1, 0], [0, 0, np.nan]], 1.0)
    with pytest.raises(ValueError, match='saturation'):
        WheelAllocator(np.eye(3), 1.0, 'round')
    with pytest.raises(ValueError, match='period_s'):
        WheelAllocator(np.eye(3), 1.0, max_momentum_Nms=1.0)
    with pytest.raises(ValueError, match='wheel_max_torque_Nm'):
        WheelAllocator(np.eye(3), [1.0, 0.0, 1.0])


def test_eigenaxis_realise_gives_the_body_the_demanded_torque():
    """(W3): the body feels -A tau_w; with wheel momentum h the law cancels omega x A h, so
    -A tau_w = M + omega x A h when nothing saturates."""
    class Ctrl:
        wheels = WheelAllocator(PYRAMID, 1.0, 'scale')
        A_w = wheels.A_w
    m = np.array([0.01, -0.02, 0.015])
    omega = np.array([0.01, 0.02, -0.03])
    h = np.array([0.1, -0.2, 0.3, 0.05])
    inputs = ControlInputs(Estimate([0.0, 0.0, 0.0, 1.0], omega, 1e-3), None,
                           wheel_momentum_Nms=h)
    cmd = realise(m, omega, inputs, Ctrl, {})
    body = -Ctrl.A_w @ cmd.wheel_torque
    np.testing.assert_allclose(body, m + np.cross(omega, Ctrl.A_w @ h), atol=1e-15)
    big = realise(100 * m, omega, inputs, Ctrl, {})     # saturated: the direction is kept
    body = -Ctrl.A_w @ big.wheel_torque
    want = 100 * m + np.cross(omega, Ctrl.A_w @ h)
    np.testing.assert_allclose(body / np.linalg.norm(body), want / np.linalg.norm(want),
                               atol=1e-12)
    assert np.max(np.abs(big.wheel_torque)) == pytest.approx(1.0)


@pytest.mark.parametrize('axes,failed', [(PYRAMID, [0]), (PYRAMID, [2]),
                                         (np.vstack([np.eye(3), [[1, 1, 1]]]), [1])])
def test_failed_wheels_are_left_out_and_the_rest_is_the_lstsq_solution(axes, failed):
    """Three healthy wheels of four still span 3-D: the healthy torques are numpy's
    least-squares (minimum-norm) solution on the healthy axes, the body gets the whole demand,
    the failed wheel 0 and no dipole."""
    rng = np.random.default_rng(3)
    alloc = WheelAllocator(axes, np.inf)
    ok = np.ones(alloc.n, bool)
    ok[failed] = False
    a = np.asarray(axes, float)
    a_h = (a / np.linalg.norm(a, axis=1)[:, None]).T[:, ok]
    for _ in range(5):
        h_dot = rng.normal(size=3)
        tau, dipole, sigma, _, refusal = alloc.allocate_healthy(h_dot, ok=ok)
        assert refusal == '' and sigma == 1.0 and np.all(dipole == 0.0)
        assert np.all(tau[~ok] == 0.0)
        np.testing.assert_allclose(tau[ok], np.linalg.lstsq(a_h, h_dot, rcond=None)[0],
                                   atol=1e-13)
        np.testing.assert_allclose(a_h @ tau[ok], h_dot, atol=1e-13)       # the whole demand


def test_without_a_spanning_set_the_magnetorquers_take_the_rest_by_a5():
    """Three axis wheels, wheel x failed: y and z take their part (lstsq), the dipole makes the
    x body torque the wheels cannot, less its part along the field (m x b = T - (T.b^) b^)."""
    alloc = WheelAllocator(np.eye(3), 0.01)
    ok = np.array([False, True, True])
    b = np.array([2e-5, -1e-5, 3e-5])
    h_dot = np.array([1e-5, -2e-5, 4e-6])
    tau, dipole, _, _, refusal = alloc.allocate_healthy(h_dot, ok=ok, b_body=b,
                                                        max_dipole_Am2=[5.0] * 3)
    assert refusal == ''
    np.testing.assert_allclose(tau, [0.0, h_dot[1], h_dot[2]], atol=1e-18)
    t_left = np.array([-h_dot[0], 0.0, 0.0])                  # the body feels -h_dot
    b_hat = b / np.linalg.norm(b)
    expected = t_left - (t_left @ b_hat) * b_hat
    np.testing.assert_allclose(np.cross(dipole, b), expected, rtol=1e-12, atol=1e-20)
    # saturated: the dipole is scaled onto the box, its direction kept (31)
    _, big, _, _, _ = alloc.allocate_healthy(1e3 * h_dot, ok=ok, b_body=b,
                                             max_dipole_Am2=[5.0] * 3)
    assert np.max(np.abs(big)) == pytest.approx(5.0)
    np.testing.assert_allclose(big / np.linalg.norm(big), dipole / np.linalg.norm(dipole),
                               atol=1e-12)


@pytest.mark.parametrize('dipole,b,what', [(None, [1e-5, 0, 0], 'no magnetorquer'),
                                           ([5.0] * 3, None, 'no usable magnetic field'),
                                           ([5.0] * 3, [0.0, 0.0, 0.0],
                                            'no usable magnetic field')])
def test_without_a_spanning_set_nor_a_way_to_cover_it_the_allocation_refuses(dipole, b, what):
    alloc = WheelAllocator(np.eye(3), 0.01)
    tau, m, sigma, _, refusal = alloc.allocate_healthy(
        [1e-3, 0, 0], ok=[True, False, True], b_body=b, max_dipole_Am2=dipole)
    assert refusal == f'the 2 healthy wheels of 3 span 2 axes, and {what} for the rest'
    assert np.all(tau == 0.0) and np.all(m == 0.0) and sigma == 0.0
    _, _, _, _, refusal = alloc.allocate_healthy([1e-3, 0, 0], ok=[False] * 3)
    assert refusal.startswith('the 0 healthy wheels of 3 span 0 axes')
