"""B-dot safe-mode controller (adcs_nodes.core.control.bdot) against hand-computed cases."""
import math

import numpy as np
import pytest

from adcs_nodes.core.control import Estimate
from adcs_nodes.core.control.bdot import BdotController

B1 = np.array([1.0e-5, 2.0e-5, 3.0e-5])
B2 = np.array([1.1e-5, 1.9e-5, 3.0e-5])    # dB/dt over 2 s = (5e-7, -5e-7, 0) T/s


def test_first_call_is_zero_then_minus_k_bdot():
    """m = -k dB/dt (B1), (B3): k = 1e7 A m^2 s/T, dB/dt = (5e-7, -5e-7, 0) T/s -> (-5, 5, 0)."""
    ctrl = BdotController(1e7, 40.0)
    first = ctrl.law(None, None, B1, 0.0, 2.0)
    assert np.array_equal(first.dipole_body, np.zeros(3)) and 'first' in first.reason
    cmd = ctrl.law(None, None, B2, 2.0, 2.0)
    assert cmd.reason == ''
    assert np.allclose(cmd.info['b_dot'], [5e-7, -5e-7, 0.0], rtol=1e-9, atol=1e-20)
    assert np.allclose(cmd.dipole_body, [-5.0, 5.0, 0.0], rtol=1e-9, atol=1e-12)
    assert cmd.info['sigma'] == 1.0


def test_scaling_onto_per_axis_limits_keeps_the_direction():
    """k = 1e8: demand (-50, 50, 0); limits 40 -> sigma 0.8 -> (-40, 40, 0); limits
    (10, 40, 40) -> sigma 0.2 -> (-10, 10, 0) (eq. (31))."""
    for lim, expect in ((40.0, [-40.0, 40.0, 0.0]), ([10.0, 40.0, 40.0], [-10.0, 10.0, 0.0])):
        ctrl = BdotController(1e8, lim)
        ctrl.law(None, None, B1, 0.0, 2.0)
        cmd = ctrl.law(None, None, B2, 2.0, 2.0)
        assert np.allclose(cmd.info['dipole_demand'], [-50.0, 50.0, 0.0])
        assert np.allclose(cmd.dipole_body, expect)


def test_missing_sample_is_skipped_and_the_real_gap_is_used():
    ctrl = BdotController(1e7, 40.0)
    ctrl.law(None, None, B1, 0.0, 2.0)
    for bad in (None, [np.nan, 0.0, 0.0], [1.0, 2.0]):
        cmd = ctrl.law(None, None, bad, 2.0, 2.0)
        assert np.all(cmd.dipole_body == 0.0) and 'no valid' in cmd.reason
    cmd = ctrl.law(None, None, B2, 4.0, 2.0)                   # gap 4 s: half the rate
    assert np.allclose(cmd.dipole_body, [-2.5, 2.5, 0.0])


def test_external_bdot_is_used_directly():
    ctrl = BdotController(1e7, 40.0)
    cmd = ctrl.law(None, None, None, 0.0, 2.0, b_dot_body=[1e-6, 0.0, -2e-6])
    assert np.allclose(cmd.dipole_body, [-10.0, 0.0, 20.0]) and cmd.reason == ''
    # a non-finite external value falls back to the finite difference
    cmd = ctrl.law(None, None, B1, 2.0, 2.0, b_dot_body=[np.nan, 0.0, 0.0])
    assert 'first' in cmd.reason


def test_low_pass_filter_first_order():
    """tau = 10 s, steps of 2 s: f2 = f1 + (1 - exp(-0.2)) (raw2 - f1), 1 - exp(-0.2) =
    0.18126925 (B4); the first derivative initialises the filter."""
    ctrl = BdotController(1e7, 1e3, filter_time_constant_s=10.0)
    ctrl.law(None, None, B1, 0.0, 2.0)
    c1 = ctrl.law(None, None, B2, 2.0, 2.0)                    # raw1 = (5e-7, -5e-7, 0)
    assert np.allclose(c1.info['b_dot'], [5e-7, -5e-7, 0.0])
    b3 = B2 + np.array([0.0, 0.0, 2e-6])                          # raw2 = (0, 0, 1e-6)
    c2 = ctrl.law(None, None, b3, 4.0, 2.0)
    a = 0.18126925
    expect = np.array([5e-7, -5e-7, 0.0]) + a * (np.array([0.0, 0.0, 1e-6])
                                                 - np.array([5e-7, -5e-7, 0.0]))
    assert np.allclose(c2.info['b_dot'], expect, rtol=1e-7, atol=1e-20)
    assert np.allclose(c2.dipole_body, -1e7 * expect, rtol=1e-7)
    # the external derivative goes through the same filter
    c3 = ctrl.law(None, None, None, 6.0, 2.0, b_dot_body=[0.0, 0.0, 0.0])
    assert np.allclose(c3.info['b_dot'], (1 - a) * expect, rtol=1e-7, atol=1e-20)


def test_time_not_advancing_restarts_and_reset_forgets():
    ctrl = BdotController(1e7, 40.0, filter_time_constant_s=5.0)
    ctrl.law(None, None, B1, 10.0, 2.0)
    cmd = ctrl.law(None, None, B2, 10.0, 2.0)
    assert 'did not advance' in cmd.reason and np.all(cmd.dipole_body == 0.0)
    cmd = ctrl.law(None, None, B1, 12.0, 2.0)                  # against B2 at t = 10
    assert np.allclose(cmd.dipole_body, [5.0, -5.0, 0.0])
    ctrl.reset()
    assert 'first' in ctrl.law(None, None, B2, 14.0, 2.0).reason


def test_dissipation_with_the_kinematic_field_rate_and_limits():
    """dB_body/dt = -omega x B (inertial field constant): the torque m x B never adds energy,
    omega . (m x B) <= 0 (B2), also after the scaling; the output is always in the limits."""
    rng = np.random.default_rng(7)
    lim = np.array([5.0, 40.0, 20.0])
    ctrl = BdotController(1e7, lim)
    for _ in range(500):
        w = rng.normal(size=3) * 0.05
        b = rng.normal(size=3) * 3e-5
        cmd = ctrl.law(None, None, b, 0.0, 2.0, b_dot_body=-np.cross(w, b))
        assert np.all(np.abs(cmd.dipole_body) <= lim)
        assert w @ np.cross(cmd.dipole_body, b) <= 1e-18
        assert cmd.is_finite()


def test_interface_accepts_estimate_and_wheels():
    est = Estimate(np.array([0, 0, 0, 1.0]), np.zeros(3), 1e-3)
    ctrl = BdotController(1e7, 40.0, n_wheels=3)
    cmd = ctrl.law(est, None, B1, 0.0, 2.0)
    assert cmd.wheel_torque.shape == (3,) and np.all(cmd.torque_body == 0.0)


@pytest.mark.parametrize('kw, word', [
    ({'gain': 0.0}, 'gain'), ({'gain': -1.0}, 'gain'), ({'gain': math.nan}, 'gain'),
    ({'gain': 'x'}, 'gain'), ({'filter_time_constant_s': -1.0}, 'filter_time_constant_s'),
    ({'max_dipole_Am2': [40.0, 40.0]}, 'max_dipole_Am2'),
    ({'max_dipole_Am2': 0.0}, 'max_dipole_Am2'), ({'max_dipole_Am2': math.inf}, 'max_dipole'),
    ({'n_wheels': 1.5}, 'n_wheels')])
def test_bad_configuration_raises(kw, word):
    args = {'gain': 1e7, 'max_dipole_Am2': 40.0}
    args.update(kw)
    with pytest.raises(ValueError, match=word):
        BdotController(**args)
