"""The magnetic filter's compiled kernels (issue 13) against independent references.

* ``expm_taylor`` against ``scipy.linalg.expm`` (Pade, scaling and squaring);
* the filter (numba kernels, Taylor ``expm``) against the previous numpy implementation,
  written out here (scipy ``expm`` per substep, numpy RK4 of (33), the sequential update (38)
  with ``np.outer``): the same numbers to rounding over a tumbling run with torques, updates
  of both measurement forms, the literal form and ``sigma_from_innovation``;
* compiled and uncompiled (``NUMBA_DISABLE_JIT=1``, a fresh interpreter) give the same bits.

Tolerances between two implementations hold on any x86-64 CPU (DESIGN 9): the kernels are
compiled without fastmath (no FMA contraction, no reassociation: the same bits on every CPU),
but the reference calls BLAS/LAPACK (``@``, ``solve``, ``expm``), whose kernel (FMA, vector
width) OpenBLAS picks at run time. So a comparison allows ``C_ROUND * EPS * kappa * |value|``:
``kappa`` the condition number of the step (computed by :class:`Reference` for each step),
``C_ROUND`` the rounding errors of one result (inner products of length <= 9, Higham's bound
``9 eps``, and a few operations more): ``C_ROUND = 16``. Measured worst error / tolerance
over the host (AVX-512, FMA), ``NUMBA_CPU_NAME=generic``, ``OPENBLAS_CORETYPE`` Prescott,
Nehalem, Sandybridge and Haswell, glibc's libm and numpy's loops without AVX2/FMA, and all at
once: 0.034 for the filter steps, 0.027 for ``A``, 0.014 for ``expm`` of the filter's
matrices, 0.10 for ``expm`` of random ones. A wrong sign or a missing term is 1e3 to 1e11
times outside (mutations checked by hand, ``docs/decisions.md``).
"""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.linalg import expm

from adcs_nodes.core.estimation import magnetic_filter as mf
from adcs_nodes.core.estimation.magnetic_filter import MagneticFilter

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
I_PAPER = np.diag([118.0, 118.0, 19.6])
I_FULL = np.array([[100.0, 3.0, -2.0], [3.0, 130.0, 1.5], [-2.0, 1.5, 40.0]])
B_ORBIT = np.array([12e-6, -3e-6, -38e-6])
OMEGA0 = 1.06e-3
EPS = np.finfo(float).eps
C_ROUND = 16


# ------------------------------------------------------------- previous implementation
def _qmul(p, q):
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return np.array([pw * qx + px * qw + py * qz - pz * qy, pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw, pw * qw - px * qx - py * qy - pz * qz])


def _dcm(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _g(inertia, v):
    return np.linalg.solve(inertia, _skew(inertia @ v) - _skew(v) @ inertia)


def _a_matrix(inertia, omega0, q, omega):
    e_r = _dcm(q)[2, :]
    a = np.zeros((9, 9))
    a[0:3, 0:3] = -_skew(omega)
    a[0:3, 3:6] = 0.5 * np.eye(3)
    a[3:6, 0:3] = -6.0 * omega0 ** 2 * _g(inertia, e_r) @ _skew(e_r)
    a[3:6, 3:6] = _g(inertia, omega)
    a[3:6, 6:9] = np.eye(3)
    return a


class Reference:
    """The filter as implemented before the kernels (numpy + scipy ``expm``)."""

    def __init__(self, inertia, theta, tau, p0, form, literal, sigma_nu):
        self.i, self.i_inv = inertia, np.linalg.inv(inertia)
        self.theta, self.tau, self.form = theta, tau, form
        self.literal, self.sigma_nu = literal, sigma_nu
        self.p = np.diag(p0)

    def rates(self, q, w, m, omega0, dipole, b_orbit):
        c_ob = _dcm(q).T
        e_r = c_ob[:, 2]
        m_s = 3.0 * omega0 ** 2 * np.cross(e_r, self.i @ e_r)
        if b_orbit is not None:
            m_s = m_s + np.cross(dipole, c_ob @ b_orbit)
        q_dot = 0.5 * (_qmul(q, np.append(w, 0.0)) - _qmul(np.array([0.0, omega0, 0.0, 0.0]),
                                                           q))
        return q_dot, self.i_inv @ (np.cross(self.i @ w, w) + m_s) + m

    def predict(self, q, w, m, dt, omega0, dipole, b_orbit, substeps):
        """One predict; sets the step's conditioning ``kappa`` (state) and ``kappa_p`` (``P``).

        State: the rates go through ``I^-1`` (kernel: the inverse; here: ``solve``), relative
        error ``eps cond(I)`` per substep, scaled by the step ``h |x_dot|`` (``|x_new - x|``).
        ``P``: ``F = expm(A h)``, Taylor against Pade, agree to ``eps`` times
        :func:`_expm_kappa` per substep; ``F P F^T`` keeps that, relative to ``max|P|``
        (normwise: scipy's ``F`` errs by ``eps ||F||`` even where ``F`` is exactly 0, so an
        element-by-element bound would not hold).
        """
        h = dt / substeps
        f = np.eye(9)
        self.kappa = substeps * np.linalg.cond(self.i)
        self.kappa_p = 0.0
        for _ in range(substeps):
            a_h = _a_matrix(self.i, omega0, q, w) * h
            self.kappa_p += _expm_kappa(a_h)
            f = expm(a_h) @ f
            k1 = self.rates(q, w, m, omega0, dipole, b_orbit)
            k2 = self.rates(q + 0.5 * h * k1[0], w + 0.5 * h * k1[1], m, omega0, dipole, b_orbit)
            k3 = self.rates(q + 0.5 * h * k2[0], w + 0.5 * h * k2[1], m, omega0, dipole, b_orbit)
            k4 = self.rates(q + h * k3[0], w + h * k3[1], m, omega0, dipole, b_orbit)
            q = q + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            w = w + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            q = q / np.linalg.norm(q)
        p = f @ self.p @ f.T
        self.p = 0.5 * (p + p.T)
        return q, w

    def update(self, q, w, m, n, b_ref):
        n_star = _dcm(q).T @ b_ref
        z = n - n_star
        h_mat = np.zeros((3, 9))
        h_mat[:, 0:3] = -_skew(n + n_star)
        p, corr = self.p.copy(), np.zeros(9)
        # kappa = max_j s_j / theta: the factor by which the update shrinks P along H_j, the
        # cancellation in P - K H P and nu_j = z_j - H_j w that amplifies rounding; it carries
        # over to the gain, the correction w (|dx| <~ eps kappa |w|) and P+ (eps kappa max|P|).
        self.kappa = self.kappa_p = 1.0
        for j in range(3):
            h = h_mat[j]
            ph = p @ h
            s = self.theta + h @ ph
            self.kappa = self.kappa_p = max(self.kappa, s / self.theta)
            k = ph / s
            nu = z[j] if self.literal else z[j] - h @ corr
            r_sig = nu if (self.sigma_nu and not self.literal) else z[j]
            p = (1.0 + self.tau * r_sig ** 2 / s) * (p - np.outer(k, ph))
            corr = corr + k * nu
        self.p = 0.5 * (p + p.T)
        v = corr[0:3]
        if self.form == 'phi':
            mu0 = 1.0 / math.sqrt(1.0 + v @ v)
            mu = mu0 * v
        else:
            nv = np.linalg.norm(v)
            mu = v if nv < mf.MU_CLAMP else v * (mf.MU_CLAMP / nv)
            mu0 = math.sqrt(max(0.0, 1.0 - mu @ mu))
        q = _qmul(q, np.append(-mu, mu0))
        return q / np.linalg.norm(q), w - corr[3:6], m - corr[6:9]


def _check_step(f, ref, after, before):
    """One step of the filter against the reference from the same state, to rounding.

    ``q``, ``omega'``, ``m'``: ``C_ROUND eps (|x| + kappa |x - x_before|)``, the final rounding
    of ``x`` plus the step's change times its conditioning (``ref.kappa``). ``P``:
    ``C_ROUND eps kappa_p max|P|`` (``ref.kappa_p``). A wrong term gives 1e-6 or more.
    """
    got = (f.q_orbit_body, f.omega_body_eci_body, f.m)
    for name, x, want, old in zip(('q', 'omega', 'm'), got, after, before):
        tol = C_ROUND * EPS * (np.abs(want).max() + ref.kappa * np.abs(want - old).max())
        np.testing.assert_allclose(x, want, rtol=0, atol=tol, err_msg=name)
    np.testing.assert_allclose(f.P, ref.p, rtol=0,
                               atol=C_ROUND * EPS * ref.kappa_p * np.abs(ref.p).max())


def _expm_kappa(x):
    """Error growth of ``expm(x)`` by scaling and squaring (Taylor here, Pade in scipy): 12
    Horner products, then ``s`` squarings that can each double the relative error, with
    ``2^s < 8 ||x||_1`` (the Taylor kernel scales to a norm below 1/4, scipy to about 5)."""
    return 12.0 + 8.0 * np.abs(x).sum(axis=0).max()


# ------------------------------------------------------------------------- tests
def test_expm_taylor_matches_scipy():
    rng = np.random.default_rng(1)
    for scale in (1e-6, 0.1, 0.25, 1.0, 3.0, 20.0):
        for _ in range(20):
            x = rng.normal(size=(9, 9)) * scale / 3.0
            ref = expm(x)
            err = np.abs(mf.expm_taylor(x) - ref).max() / max(1.0, np.abs(ref).max())
            # relative to max|expm|: C_ROUND eps kappa, from 4.3e-14 (scale 1e-6) to 2.7e-12
            # (scale 20, ||x||_1 up to 93); was 1e-13, which the host reached to 0.88
            assert err < C_ROUND * EPS * _expm_kappa(x), (scale, err)
    assert np.array_equal(mf.expm_taylor(np.zeros((9, 9))), np.eye(9))


def test_expm_taylor_on_the_filter_matrices():
    rng = np.random.default_rng(2)
    for _ in range(50):
        q = rng.normal(size=4)
        w = rng.normal(size=3) * 0.1
        a = mf.error_matrix_kernel(I_FULL, np.linalg.inv(I_FULL), OMEGA0,
                                   q / np.linalg.norm(q), w)
        # G(v) = I^-1 [Phi(I v) - Phi(v) I], kernel through the inverse, here a LAPACK solve:
        # both err by ~eps cond(I) |I^-1| |I| |v| = eps cond(I)^2 |v|, v = omega (the G block)
        # or e_R times 6 omega0^2 (the gravity block); -Phi(omega), 0.5, 1 are exact copies
        cond = np.linalg.cond(I_FULL)
        np.testing.assert_allclose(a, _a_matrix(I_FULL, OMEGA0, q / np.linalg.norm(q), w),
                                   rtol=0, atol=C_ROUND * EPS * cond ** 2
                                   * max(np.abs(w).max(), 6.0 * OMEGA0 ** 2))
        for h in (0.1, 2.0, 10.0):
            ref = expm(a * h)
            np.testing.assert_allclose(mf.expm_taylor(a * h), ref, rtol=0,
                                       atol=C_ROUND * EPS * _expm_kappa(a * h)
                                       * np.abs(ref).max())


@pytest.mark.parametrize('inertia, form, literal, sigma_nu, substeps', [
    (I_PAPER, 'phi', False, False, 1),
    (I_FULL, 'mu', False, True, 3),
    (I_PAPER, 'phi', True, False, 2),
])
def test_filter_matches_the_previous_implementation(inertia, form, literal, sigma_nu,
                                                    substeps):
    """Step by step from the same state (the filter is re-synchronised to the reference
    before every predict/update): each step agrees to rounding. Over many steps rounding
    differences grow (an update with a large innovation amplifies them ~100x), so a free
    run is compared only to engineering tolerance below."""
    rng = np.random.default_rng(3)
    theta, tau = 9e-14, 0.01
    p0 = mf.P0_PHI_DEFAULT if form == 'phi' else mf.P0_MU_DEFAULT
    f = MagneticFilter(inertia, theta=theta, tau=tau, measurement_form=form,
                       literal_update=literal, substeps=substeps, sigma_from_innovation=sigma_nu)
    ref = Reference(inertia, theta, tau, p0, form, literal, sigma_nu)
    q = np.array([0.2, -0.1, 0.4, 0.9])
    q /= np.linalg.norm(q)
    w, m = np.radians([-3.0, 3.0, 3.0]), np.zeros(3)
    f.reset(q, w)

    def sync():
        f._q, f._omega, f._m, f._p = q.copy(), w.copy(), m.copy(), ref.p.copy()
        return q, w, m

    accepted = 0
    for k in range(40):
        dipole = rng.normal(size=3) * 10.0
        before = sync()
        assert f.predict(2.0, OMEGA0, dipole, b_orbit_for_torque=B_ORBIT)
        q, w = ref.predict(q, w, m, 2.0, OMEGA0, dipole, B_ORBIT, substeps)
        _check_step(f, ref, (q, w, m), before)
        if k % 5 == 4:
            n = _dcm(rng.normal(size=4)).T @ B_ORBIT * 1.02
            before = sync()
            res = f.update(n, B_ORBIT)
            if res['accepted']:
                accepted += 1
                q, w, m = ref.update(q, w, m, n, B_ORBIT)
                _check_step(f, ref, (q, w, m), before)
            else:   # the reference has no guards: go on from the unchanged state
                assert np.array_equal(f.q_orbit_body, q)
    assert accepted >= 4 or literal


def test_free_run_tracks_the_previous_implementation():
    """Paper example, measurements consistent with a truth: 200 frames (400 s) free run."""
    rng = np.random.default_rng(4)
    f = MagneticFilter(I_PAPER)
    ref = Reference(I_PAPER, f.theta, f.tau, mf.P0_PHI_DEFAULT, 'phi', False, False)
    q_true = np.array([0.48, -0.48, 0.64, 0.36])
    q, w, m = np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.0, OMEGA0, 0.0]), np.zeros(3)
    f.reset(q, w)
    for k in range(200):
        f.predict(2.0, OMEGA0)
        q, w = ref.predict(q, w, m, 2.0, OMEGA0, np.zeros(3), None, 1)
        if k % 5 == 4:
            n = _dcm(q_true).T @ B_ORBIT + rng.normal(size=3) * 1e-7
            assert f.update(n, B_ORBIT)['accepted']
            q, w, m = ref.update(q, w, m, n, B_ORBIT)
    np.testing.assert_allclose(f.q_orbit_body, q, atol=1e-9)
    np.testing.assert_allclose(f.omega_body_eci_body, w, atol=1e-11)
    np.testing.assert_allclose(f.P, ref.p, rtol=0, atol=1e-8 * np.abs(ref.p).max())


def test_predict_with_a_body_field_and_without_torque_matches():
    f = MagneticFilter(I_FULL)
    ref = Reference(I_FULL, f.theta, f.tau, mf.P0_PHI_DEFAULT, 'phi', False, False)
    q, w = np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.01, -0.02, 0.005])
    f.reset(q, w)
    b_body = np.array([2e-5, -1e-5, 3e-5])
    dipole = np.array([5.0, -3.0, 1.0])
    f.predict(2.0, OMEGA0, dipole, b_body_for_torque=b_body)

    def rates(qq, ww, mm, omega0, dip, _b):   # L x B with B given in body axes
        c_ob = _dcm(qq).T
        e_r = c_ob[:, 2]
        m_s = 3.0 * omega0 ** 2 * np.cross(e_r, I_FULL @ e_r) + np.cross(dip, b_body)
        q_dot = 0.5 * (_qmul(qq, np.append(ww, 0.0))
                       - _qmul(np.array([0.0, omega0, 0.0, 0.0]), qq))
        return q_dot, ref.i_inv @ (np.cross(I_FULL @ ww, ww) + m_s) + mm
    ref.rates = rates
    q1, w1 = ref.predict(q, w, np.zeros(3), 2.0, OMEGA0, dipole, None, 1)
    _check_step(f, ref, (q1, w1, np.zeros(3)), (q, w, np.zeros(3)))


SCRIPT = r'''
import json, sys
import numpy as np
from adcs_nodes.core.estimation.magnetic_filter import MagneticFilter
rng = np.random.default_rng(5)
f = MagneticFilter(np.diag([118.0, 118.0, 19.6]), substeps=2)
f.reset([0.1, -0.2, 0.3, 0.9], [0.01, -0.02, 0.03])
out = []
for k in range(30):
    f.predict(2.0, 1.06e-3, rng.normal(size=3) * 10, b_orbit_for_torque=[12e-6, -3e-6, -38e-6])
    if k % 5 == 0:
        f.update(rng.normal(size=3) * 1e-6 + [20e-6, 5e-6, -30e-6], [12e-6, -3e-6, -38e-6])
    out.append([float(x).hex() for x in np.r_[f.q_orbit_body, f.omega_body_eci_body, f.m,
                                               f.P.ravel()]])
print(json.dumps(out))
'''


def test_compiled_and_uncompiled_give_the_same_bits():
    """One code path run two ways: the same bits on any x86-64 CPU, not only on this one.

    The compiled kernels have no FMA, no reassociation, no BLAS and no libm call but ``sqrt``
    (correctly rounded everywhere): checked in their code, host and ``generic``. Uncompiled,
    numpy rounds each element alike whatever its vector width. The one difference is ``x ** 2``:
    numba multiplies, CPython and numpy call libm ``pow``, which misrounds about 1e-3 of
    random ``x`` (glibc's ``pow``, FMA or not, errs by at most about 0.51 ULP for these
    arguments). Every value squared along this run is at least 0.036 ULP from a rounding
    midpoint, so any such ``pow`` gives ``x * x`` (``docs/decisions.md``, "Bit for bit
    across machines")."""
    pytest.importorskip('numba')
    runs = {}
    for jit in ('0', '1'):
        env = dict(os.environ, NUMBA_DISABLE_JIT=jit)
        proc = subprocess.run([sys.executable, '-c', SCRIPT], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        runs[jit] = json.loads(proc.stdout)
    assert len(runs['0']) == 30
    assert runs['0'] == runs['1']


def test_kernels_are_compiled_when_numba_is_there():
    numba = pytest.importorskip('numba')
    if os.environ.get('NUMBA_DISABLE_JIT', '0') not in ('', '0'):
        pytest.skip('JIT disabled in this process')
    mf.warm_up()                      # (the filter's kernels load numba at their first call)
    assert isinstance(mf.predict_kernel, numba.core.registry.CPUDispatcher)
    assert isinstance(mf.update_kernel, numba.core.registry.CPUDispatcher)
    for fn in (mf.predict_kernel, mf.update_kernel):
        assert not fn.targetoptions.get('fastmath', False)
