"""A sensor's covariance enters the paper 000 filter per body axis (``theta_axes``).

Independent truth: the scalar update (38) written out by hand (s = theta_j + h P h^T,
K = P h / s) for one axis; the limit theta -> infinity (no correction). (A rotation of a
covariance by scipy's own rotation matrix: ``tests/node/test_covariance_to_body.py``.)
"""
import numpy as np

from adcs_nodes.core import attitude
from adcs_nodes.core.estimation import magnetic_filter as mf
from adcs_nodes.core.estimation.magnetic_filter import MagneticFilter

I_PAPER = np.diag([118.0, 118.0, 19.6])
B_ORBIT = np.array([12e-6, -3e-6, -38e-6])
Q_TRUE = attitude.normalize(np.array([0.1, -0.2, 0.15, 0.96]))


def _filter():
    f = MagneticFilter(I_PAPER)
    f.reset(attitude.normalize(np.array([0.0, 0.0, 0.05, 1.0])), np.array([0.0, 1e-3, 0.0]))
    return f


def _measurement():
    return attitude.to_matrix(Q_TRUE).T @ B_ORBIT


def test_default_theta_on_every_axis_is_the_old_update():
    a, b = _filter(), _filter()
    ra = a.update(_measurement(), B_ORBIT)
    rb = b.update(_measurement(), B_ORBIT, theta_axes=[a.theta] * 3)
    assert ra['accepted'] and rb['accepted']
    assert np.array_equal(ra['correction'], rb['correction']) and np.array_equal(a.P, b.P)


def test_first_axis_gain_is_the_hand_written_scalar_update():
    f = _filter()
    p0, n = f.P.copy(), _measurement()
    n_star = mf.predicted_field_body(f.q_orbit_body, B_ORBIT)
    h = np.r_[-attitude.skew(n + n_star)[0], np.zeros(6)]      # row 1 of H, (36)
    theta = [4e-13, 1e-13, 2e-13]
    res = f.update(n, B_ORBIT, theta_axes=theta)
    s = theta[0] + h @ p0 @ h                 # (38), j = 1, by hand
    k = p0 @ h / s
    # the other two axes are sequential; make them inert to isolate axis 1
    g = _filter()
    res1 = g.update(n, B_ORBIT, theta_axes=[theta[0], 1e300, 1e300])
    assert res['accepted'] and res1['accepted']
    assert np.allclose(res1['correction'], k * (n - n_star)[0], rtol=1e-9, atol=1e-15)


def test_huge_covariance_means_no_correction_and_bad_values_are_rejected():
    f = _filter()
    res = f.update(_measurement(), B_ORBIT, theta_axes=[1e300] * 3)
    assert res['accepted'] and np.max(np.abs(res['correction'])) < 1e-200
    for bad in ([1e-13, 0.0, 1e-13], [np.nan] * 3, [1e-13] * 2, 'x'):
        g = _filter()
        q = g.q_orbit_body.copy()
        out = g.update(_measurement(), B_ORBIT, theta_axes=bad)
        assert not out['accepted'] and 'theta_axes' in out['reason']
        assert np.array_equal(g.q_orbit_body, q)


def test_estimator_core_uses_the_sample_variances_floored_at_theta():
    """The registry's magnetic-filter estimator passes max(theta, variance) per axis: a huge
    variance leaves the state as the prediction made it; zero variances (below the floor) give
    exactly the theta-only update; no variance given is the theta-only update."""
    from adcs_nodes.core.estimation.algorithms import EstimatorInputs, MagneticFilterEstimator
    from adcs_nodes.core.estimation.onboard import OnboardState

    ref = OnboardState(q_eci_orbit=np.array([0.0, 0.0, 0.0, 1.0]), b_orbit=B_ORBIT,
                       omega0=1.06e-3, u=0.0,
                       r_eci=np.array([7.07e6, 0.0, 0.0]))
    b_body = _measurement()

    def run(var):
        est = MagneticFilterEstimator(I_PAPER)
        est.step(EstimatorInputs(ref), 0.0, 0.0)                       # start
        step = est.step(EstimatorInputs(ref, b_body=b_body, b_body_var=var), 2.0, 2.0)
        return step, est.filter.q_orbit_body.copy()

    predicted = MagneticFilterEstimator(I_PAPER)
    predicted.step(EstimatorInputs(ref), 0.0, 0.0)
    predicted.step(EstimatorInputs(ref), 2.0, 2.0)
    q_pred = predicted.filter.q_orbit_body
    s_none, q_none = run(None)
    s_zero, q_zero = run(np.zeros(3))
    s_huge, q_huge = run(np.full(3, 1e300))
    assert s_none.updates == s_zero.updates == s_huge.updates == 1
    assert np.array_equal(q_none, q_zero)
    assert attitude.angle_between(q_huge, q_pred) < 1e-12
    assert attitude.angle_between(q_none, q_pred) > 1e-6
