"""Star tracker + gyro MEKF (adcs_nodes.core.estimation.mekf).

Truth: a known rotation (constant body rate, exact quaternion exponential) measured by the
simulator's independent sensor models (sim_node StarTracker and Gyro with a random-walk bias);
the filter's consistency by the normalised estimation error squared (NEES) over a Monte Carlo
of independent runs against chi-square bounds (scipy).
"""
import math
import sys

import numpy as np
import pytest
from scipy.stats import chi2

sys.modules.setdefault('rclpy', None)

from adcs_nodes.core import attitude as att  # noqa: E402
from adcs_nodes.core.estimation.algorithms import EstimatorInputs  # noqa: E402
from adcs_nodes.core.estimation.mekf import MEKF  # noqa: E402
from adcs_nodes.core.estimation.onboard import OnboardState  # noqa: E402
from sim_node.models.sensors import Gyro, StarTracker  # noqa: E402

REF = OnboardState(att.from_axis_angle([1, 2, 3], 0.7), np.zeros(3), 1.0831e-3, 0.0,
                   np.array([7e6, 0, 0]))
ST_STD = 1e-3          # amplified noise so that the bias is observable in a short run
GYRO_STD = 2e-5
WALK = 2e-6
DT = 0.2


P0_BIAS = 2e-3


def _run(seed, steps=600, omega=(0.01, -0.02, 0.015)):
    rng = np.random.default_rng(seed)
    st = StarTracker(ST_STD, seed=seed)
    bias0 = P0_BIAS * rng.normal(size=3)         # initial error drawn from P0 (NEES needs it)
    gyro = Gyro(GYRO_STD, bias0, WALK, seed=seed + 1000)
    f = MEKF(ST_STD, GYRO_STD, WALK, p0_bias_rad_s=P0_BIAS)
    q0 = att.normalize(rng.normal(size=4))
    w = np.array(omega)
    nees, att_err, bias_err = [], [], []
    for k in range(steps):
        t = k * DT
        q_true = att.multiply(q0, att.from_rotation_vector(w * t))
        g = gyro.measure(w, DT if k else 0.0)
        out = f.step(EstimatorInputs(REF, gyro_rate_body=g, q_eci_body_meas=st.measure(q_true)),
                     t, DT if k else 0.0)
        assert out.estimate is not None and not out.rejections
        d_theta = att.to_rotation_vector(att.multiply(att.conjugate(f.q), q_true))
        d_b = gyro.bias - f.b
        e = np.concatenate([d_theta, d_b])
        nees.append(float(e @ np.linalg.solve(f.P, e)))
        att_err.append(np.linalg.norm(d_theta))
        bias_err.append(np.linalg.norm(d_b))
        # the published estimate: orbit attitude and rate from the same state
        q_ob_true = att.multiply(att.conjugate(REF.q_eci_orbit), q_true)
        assert att.angle_between(out.estimate.q_orbit_body, q_ob_true) == pytest.approx(
            np.linalg.norm(d_theta), abs=1e-9)
    return np.array(nees), np.array(att_err), np.array(bias_err), f, out, bias0


def test_converges_on_a_known_rotation():
    _, att_err, bias_err, f, out, bias0 = _run(1)
    assert np.max(att_err[300:]) < 3 * math.sqrt(3) * ST_STD
    assert bias_err[-1] < 0.05 * np.linalg.norm(bias0)
    np.testing.assert_allclose(out.estimate.omega_body_eci_body, [0.01, -0.02, 0.015],
                               atol=5 * GYRO_STD + 3e-4)
    cov = out.estimate.covariance
    assert cov.shape == (6, 6) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_nees_is_consistent_over_a_monte_carlo():
    """Mean NEES over M independent runs at well-separated times lies within the two-sided
    99 % band chi-square(6 M)/M (6 = error-state dimension); a filter that over- or
    under-states its covariance by 2x fails it."""
    m = 40
    runs = np.array([_run(s, steps=201)[0] for s in range(100, 100 + m)])
    lo, hi = chi2.ppf(0.005, 6 * m) / m, chi2.ppf(0.995, 6 * m) / m
    assert 4.2 < lo < 6.0 < hi < 8.2
    for k in (100, 200):
        assert lo < runs[:, k].mean() < hi, (k, runs[:, k].mean(), lo, hi)


def test_outliers_are_refused_and_bad_samples_never_give_nan():
    f = MEKF(ST_STD, GYRO_STD, WALK)
    q = att.identity()
    out = f.step(EstimatorInputs(REF, gyro_rate_body=np.zeros(3), q_eci_body_meas=q), 0.0, 0.0)
    assert out.estimate is not None
    far = att.from_axis_angle([0, 0, 1], 0.5)
    out = f.step(EstimatorInputs(REF, gyro_rate_body=np.zeros(3), q_eci_body_meas=far), 0.2, 0.2)
    assert out.rejections and 'refused' in out.rejections[0]
    assert att.angle_between(f.q, q) < 1e-3
    out = f.step(EstimatorInputs(REF, gyro_rate_body=np.array([np.nan, 0, 0]),
                                 q_eci_body_meas=np.array([np.nan, 0, 0, 1])), 0.4, 0.2)
    assert len(out.rejections) == 2
    assert np.all(np.isfinite(out.estimate.q_orbit_body))
    assert np.all(np.isfinite(out.estimate.omega_body_eci_body))
    for k in range(9):                  # a real jump: the 10th refusal in a row restarts
        out = f.step(EstimatorInputs(REF, gyro_rate_body=np.zeros(3), q_eci_body_meas=far),
                     0.6 + 0.2 * k, 0.2)
    assert 'restarted' in out.rejections[-1]
    f.step(EstimatorInputs(REF, gyro_rate_body=np.zeros(3), q_eci_body_meas=far), 3.0, 0.2)
    assert att.angle_between(f.q, far) < 1e-12


def test_no_estimate_before_the_first_star_tracker_sample_and_bad_config():
    f = MEKF()
    out = f.step(EstimatorInputs(REF, gyro_rate_body=np.zeros(3)), 0.0, 0.0)
    assert out.estimate is None
    with pytest.raises(ValueError, match='star_tracker_std_rad'):
        MEKF(star_tracker_std_rad=0.0)
    with pytest.raises(ValueError, match='gyro_noise_std_rad_s'):
        MEKF(gyro_noise_std_rad_s=-1.0)
    with pytest.raises(ValueError, match='max_rejections'):
        MEKF(max_rejections=0)


def test_accelerating_rotation_leaves_no_false_bias():
    """Constant angular acceleration about a fixed axis (exact truth q0 exp(a (w0 t + alpha
    t^2 / 2))), noiseless sensors: the mean of the two gyro samples integrates it to
    O(dt^3), so the bias stays near zero (holding one sample would leak alpha dt / 2 =
    1e-4 rad/s into it)."""
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    w0, alpha = 0.01, 1e-3
    f = MEKF(ST_STD, GYRO_STD, WALK, p0_bias_rad_s=1e-3)
    q0 = att.from_axis_angle([0, 1, 0], 0.3)
    for k in range(300):
        t = k * DT
        q = att.multiply(q0, att.from_rotation_vector(axis * (w0 * t + 0.5 * alpha * t * t)))
        f.step(EstimatorInputs(REF, gyro_rate_body=axis * (w0 + alpha * t),
                               q_eci_body_meas=q), t, DT if k else 0.0)
    assert np.linalg.norm(f.b) < 2e-6
    assert att.angle_between(f.q, q) < 1e-6
