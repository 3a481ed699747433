"""``adcs report`` judges an estimate against the truth interpolated at the estimate's own
stamp (issue 23, defect 4): :func:`adcs_nodes.tools.analyse.metrics.estimate_errors_deg` against an
analytic rotation (a constant rate about a fixed axis, for which slerp between two samples is
exact), with estimate stamps off the truth's grid."""
import math

import numpy as np
import pytest

from adcs_nodes.tools.analyse.metrics import angle_between_deg, estimate_errors_deg, slerp_at

AXIS = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
RATE = math.radians(3.0)            # [rad/s]


def q_true(t):
    """exp of the rotation ``AXIS * RATE * t`` (scalar last), the analytic truth."""
    t = np.asarray(t, dtype=float).reshape(-1)
    half = RATE * t / 2.0
    return np.concatenate([np.sin(half)[:, None] * AXIS, np.cos(half)[:, None]], axis=1)


def qmul(a, b):
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


T_TRUTH = np.arange(0.0, 200.0 + 1e-9, 2.0)         # the world's 2 s frames
T_EST = 0.37 + 1.3 * np.arange(150)                 # a live estimator's stamps (off grid)


def test_slerp_at_matches_the_analytic_rotation_between_samples():
    q = slerp_at(T_TRUTH, q_true(T_TRUTH), T_EST)
    assert angle_between_deg(q, q_true(T_EST)).max() < 1e-9
    # the sign of a stored sample does not matter (q and -q are one attitude)
    flipped = q_true(T_TRUTH) * np.where(np.arange(T_TRUTH.size) % 2, -1.0, 1.0)[:, None]
    q2 = slerp_at(T_TRUTH, flipped, T_EST)
    assert np.abs(np.abs(np.sum(q2 * q_true(T_EST), axis=1)) - 1.0).max() < 1e-12


def test_an_exact_estimate_off_the_grid_has_no_error():
    out = estimate_errors_deg(T_TRUTH, q_true(T_TRUTH), T_EST, q_true(T_EST))
    assert out['t'].size == np.sum(T_EST <= T_TRUTH[-1])
    assert out['deg'].max() < 1e-9
    # what matching each estimate to the nearest truth sample would have said: up to 3 deg
    nearest = T_TRUTH[np.abs(T_EST[:, None] - T_TRUTH[None, :]).argmin(axis=1)]
    naive = np.degrees(RATE * np.abs(T_EST - nearest))
    assert naive.max() > 2.5


def test_a_known_error_is_measured_at_the_estimate_stamp():
    small = math.radians(0.5)                              # the estimate's error, body axes
    err_q = np.array([math.sin(small / 2) * 0.6, math.sin(small / 2) * 0.8, 0.0,
                      math.cos(small / 2)])
    q_est = qmul(q_true(T_EST), np.broadcast_to(err_q, (T_EST.size, 4)))
    out = estimate_errors_deg(T_TRUTH, q_true(T_TRUTH), T_EST, q_est)
    assert out['deg'] == pytest.approx(0.5, abs=1e-6)
    assert out['on_grid'] == 0


def test_stamps_on_the_grid_use_the_truth_sample_and_outside_stamps_are_left_out():
    t_est = np.array([-1.0, 0.0, 4.0, 5.0, 200.0, 201.0])
    q_est = q_true(t_est)
    out = estimate_errors_deg(T_TRUTH, q_true(T_TRUTH), t_est, q_est)
    assert list(out['t']) == [0.0, 4.0, 5.0, 200.0]
    assert (out['on_grid'], out['outside']) == (3, 2)
    exact = slerp_at(T_TRUTH, q_true(T_TRUTH), [4.0])
    assert np.array_equal(exact[0], q_true(T_TRUTH)[2])    # the sample itself, bit for bit


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError):
        estimate_errors_deg(T_TRUTH, q_true(T_TRUTH), T_EST, q_true(T_EST)[:3])
    with pytest.raises(ValueError):
        slerp_at(T_TRUTH[:3], q_true(T_TRUTH), T_EST)
