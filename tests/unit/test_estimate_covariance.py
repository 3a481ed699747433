"""The magnetic filter's published 6x6 covariance: the small-angle map of its ``P``.

The error angle is ``2 phi`` (or ``2 mu``) for small errors, so the angle block is ``4 P_phi``,
the angle/rate block ``2 P_phi,w``, the rate block ``P_w`` (module docstring of
:mod:`adcs_nodes.core.estimation.algorithms`); built here with ``np.block`` (scaling by powers
of two is exact, so the comparison is exact).
"""
import numpy as np
import pytest

from adcs_nodes.core.estimation.algorithms import EstimatorInputs, MagneticFilterEstimator
from adcs_nodes.core.estimation.onboard import OnboardState

INERTIA = np.diag([118.0, 118.0, 19.6])


@pytest.mark.parametrize('mis', [0.0, 0.01])
def test_published_covariance_is_the_small_angle_map_of_p(mis):
    est = MagneticFilterEstimator(INERTIA, use_sensor_covariance=False,
                                  misalignment_std0_rad=mis)
    ref = OnboardState(np.array([0.0, 0.0, 0.0, 1.0]), np.array([2e-5, 0.0, -3e-5]), 1.07e-3,
                       0.0, np.array([7.0e6, 0.0, 0.0]))
    est.step(EstimatorInputs(ref), 0.0, 0.0)                     # started: P = diag(p0)
    n = 12 if mis else 9
    a = np.random.default_rng(5).standard_normal((n, n))
    p = a @ a.T + n * np.eye(n)                                     # symmetric positive definite
    est.filter.set_state([0.1, -0.2, 0.3, 0.9], [1e-3, -2e-3, 5e-4], np.zeros(3), p)
    cov = est.step(EstimatorInputs(ref), 0.0, 0.0).estimate.covariance   # no predict, no update
    expected = np.block([[4.0 * p[:3, :3], 2.0 * p[:3, 3:6]], [2.0 * p[3:6, :3], p[3:6, 3:6]]])
    assert cov.shape == (6, 6)
    assert np.array_equal(cov, expected)
    assert np.array_equal(cov, cov.T)
