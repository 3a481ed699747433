"""Compiled flight-software and field kernels (issue 13) against the numpy code they replace.

* the magnetic law (:func:`magnetic.law_kernel` through :meth:`MagneticController.law`) against
  the previous implementation, written out here from the helper functions of the module
  ((7), (10), (16), (21), (29)-(31)) with numpy: the same bits for ``xi`` on a body axis, in
  all three modes, with saturation, targets and the two-stage switch;
* the manager's checks (:func:`manager.limit_violation`, :func:`manager.clip_finite`) against
  the numpy expressions (``isfinite``, ``abs > limit``, ``nan_to_num`` + ``clip``);
* the dipole field (G1), (G2) and the onboard reference's (R1) against the numpy expressions;
* compiled and uncompiled (``NUMBA_DISABLE_JIT=1``, a fresh interpreter) give the same bits
  for :func:`sample`: ``tests/graph/test_fresh_interpreters.py`` (processes).

"The same bits" as the numpy code holds where numpy's BLAS sums small dot products in index
order (checked first, :func:`_blas_sums_in_index_order`; true on the development machine);
elsewhere the comparison is to 1e-12 relative.
"""
import math
from datetime import datetime, timezone

import numpy as np
import pytest

from adcs_nodes.core import attitude, geomag, kernels, manager
from adcs_nodes.core.control import Estimate, Target, cross3, scale_to_limits
from adcs_nodes.core.control import magnetic
from adcs_nodes.core.control.magnetic import (MagneticController, dipole_from_torque,
                                              relative_rate, target_rate_one_axis,
                                              target_rate_three_axis, torque_demand)
from adcs_nodes.core.estimation import onboard

EPOCH = datetime(2025, 3, 20, tzinfo=timezone.utc)


def _blas_sums_in_index_order():
    """Whether this numpy's ``a @ b`` (3- and 4-vectors) and ``M.T @ v`` (3 x 3) sum in index
    order without fused multiply-adds, as the kernels do. The numpy code used them, so the
    kernels give its bits exactly where this holds (this development machine); another BLAS
    may round its sums differently, and then the two agree to rounding only."""
    rng = np.random.default_rng(0)
    for _ in range(20000):
        a, b, m = rng.standard_normal(4), rng.standard_normal(4), rng.standard_normal((3, 3))
        if a @ b != ((a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]) + a[3] * b[3]:
            return False
        if a[:3] @ b[:3] != (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]:
            return False
        mt = m.T @ a[:3]
        if any(mt[i] != (m[0, i] * a[0] + m[1, i] * a[1]) + m[2, i] * a[2] for i in range(3)):
            return False
    return True


EXACT = _blas_sums_in_index_order()


def same(got, expected):
    """Bit-identical where the BLAS sums in index order (see above), else equal to rounding."""
    got, expected = np.asarray(got, dtype=float), np.asarray(expected, dtype=float)
    if EXACT:
        return got.tobytes() == expected.tobytes()
    return np.allclose(got, expected, rtol=1e-12, atol=1e-300 + 1e-12 * np.abs(expected).max())


# ------------------------------------------------------------- previous implementations
def law_numpy(ctrl, q, w, omega0, q_ref, y_ref, b):
    """The law as it was (numpy helper functions); returns (dipole, info)."""
    q = attitude.normalize(q)
    q_err = attitude.multiply(attitude.conjugate(attitude.normalize(q_ref)), q)
    y = relative_rate(q, w, omega0)                                                   # (7)
    s = attitude.rotate(attitude.conjugate(q_err), ctrl.xi)
    one_axis_angle = math.acos(min(1.0, max(-1.0, float(ctrl.xi @ s))))
    if (ctrl.stage == 'one_axis' and ctrl.mode == 'two_stage'
            and one_axis_angle < ctrl.switch_angle
            and float(np.linalg.norm(y - y_ref)) < ctrl.switch_rate):
        ctrl.stage = 'three_axis'
    if ctrl.stage == 'three_axis':
        y_star = y_ref + target_rate_three_axis(q_err, ctrl.alpha)                   # (16)
        angle = attitude.angle_between(q_err, attitude.identity())
    else:
        y_star = y_ref + target_rate_one_axis(s, ctrl.xi, ctrl.alpha)                # (21)
        angle = one_axis_angle
    m_star = torque_demand(y, y_star, ctrl.k)                                         # (29)
    l_star = dipole_from_torque(m_star, b)                                            # (30)
    dipole, sigma = scale_to_limits(l_star, ctrl.max_dipole)                          # (31)
    return dipole, {'stage': ctrl.stage, 'y': y, 'y_star': y_star, 'torque_demand': m_star,
                    'dipole_demand': l_star, 'sigma': sigma,
                    'torque_applied': cross3(dipole, b), 'angle_rad': angle,
                    'axis_angle_rad': one_axis_angle}


def random_case(rng):
    q = rng.standard_normal(4) * rng.uniform(0.5, 2.0)
    w = rng.normal(0.0, 10.0 ** rng.uniform(-4, -1), 3)
    b = rng.normal(0.0, 3e-5, 3)
    if rng.uniform() < 0.5:
        q_ref, y_ref = np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3)
    else:
        q_ref, y_ref = rng.standard_normal(4), rng.normal(0.0, 1e-3, 3)
    return q, w, 1.0625e-3 * rng.uniform(0.9, 1.1), q_ref, y_ref, b


@pytest.mark.parametrize('mode', magnetic.MODES)
@pytest.mark.parametrize('xi', [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)])
def test_magnetic_law_gives_the_bits_of_the_numpy_law(mode, xi):
    rng = np.random.default_rng(11)
    kw = dict(mode=mode, alpha=3e-3, k=0.2, max_dipole_Am2=[40.0, 30.0, 20.0], xi_body=xi,
              switch_angle_deg=60.0, switch_rate_deg_s=2.0)
    compiled, ref = MagneticController(**kw), MagneticController(**kw)
    saturated = switched = 0
    for _ in range(3000):
        q, w, omega0, q_ref, y_ref, b = random_case(rng)
        orbit_frame = q_ref[3] == 1.0 and not y_ref.any()      # half the cases: no target
        cmd = compiled.law(Estimate(q, w, omega0),
                           None if orbit_frame else Target(q_ref, y_ref), b, 0.0, 2.0)
        dipole, info = law_numpy(ref, q, w, omega0, q_ref, y_ref, b)
        assert same(cmd.dipole_body, dipole)
        for key, value in info.items():
            if key == 'stage':
                assert cmd.info[key] == value
            else:
                assert same(cmd.info[key], value), key
        saturated += info['sigma'] < 1.0
        if mode == 'two_stage' and compiled.stage == 'three_axis':
            switched += 1
            compiled.reset()
            ref.reset()
    assert saturated > 100                      # the scaling (31) was exercised
    assert mode != 'two_stage' or switched > 10  # and the switch


def test_magnetic_law_with_an_oblique_axis_agrees_to_rounding():
    """``s`` is summed in index order now, the numpy law used BLAS: equal to rounding."""
    rng = np.random.default_rng(12)
    xi = np.array([0.3, -0.5, 0.8])
    compiled = MagneticController(mode='one_axis', xi_body=xi)
    ref = MagneticController(mode='one_axis', xi_body=xi)
    for _ in range(2000):
        q, w, omega0, q_ref, y_ref, b = random_case(rng)
        cmd = compiled.law(Estimate(q, w, omega0), Target(q_ref, y_ref), b, 0.0, 2.0)
        dipole, _ = law_numpy(ref, q, w, omega0, q_ref, y_ref, b)
        np.testing.assert_allclose(cmd.dipole_body, dipole, rtol=1e-9, atol=1e-9 * 40.0)


def test_manager_checks_match_numpy():
    rng = np.random.default_rng(13)
    for n in (0, 3, 4):
        for _ in range(3000):
            lim = rng.choice([0.0, 1.0, 40.0, np.inf], n)
            v = rng.normal(0.0, 30.0, n) * rng.choice([0.0, 1.0], n)
            if n and rng.uniform() < 0.3:
                v[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
            finite = np.all(np.isfinite(v))
            over = np.abs(v) > lim * (1.0 + 1e-9) + 1e-12
            got = manager.limit_violation(v, lim, 1e-9)
            if not finite:
                assert got == -2 - int(np.argmax(~np.isfinite(v)))
            elif np.any(over):
                assert got == int(np.argmax(over))
            else:
                assert got == -1
            expected = np.clip(np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0), -lim, lim)
            np.testing.assert_array_equal(manager.clip_finite(v, lim), expected)
            assert np.all(np.isfinite(manager.clip_finite(v, lim)))


def dipole_eci_numpy(field, r, t):
    theta = geomag.gmst(field.epoch, t)
    c, s = math.cos(theta), math.sin(theta)
    re = np.array([c * r[0] + s * r[1], c * r[1] - s * r[0], r[2]])                  # (G1)
    r2 = re @ re
    rn = math.sqrt(r2)
    b = field._k / (r2 * rn) * (3.0 * (field.m_ecef @ re) / r2 * re - field.m_ecef)  # (G2)
    return np.array([c * b[0] - s * b[1], s * b[0] + c * b[1], b[2]])


def test_dipole_field_and_orbit_axes_give_the_numpy_bits():
    rng = np.random.default_rng(14)
    field = geomag.DipoleField.from_igrf(EPOCH)
    igrf = geomag.IgrfField(EPOCH, max_degree=4)
    for _ in range(3000):
        r = rng.standard_normal(3) * rng.uniform(6.6e6, 4.2e7)
        t = rng.uniform(-1e5, 1e6)
        assert same(field.field_eci(r, t), dipole_eci_numpy(field, r, t))
        q = rng.standard_normal(4)
        b = rng.normal(0.0, 3e-5, 3)
        assert same(onboard.to_orbit_axes(q, b), attitude.to_matrix(q).T @ b)
    # the generic (G1) around IGRF's field_ecef
    for _ in range(200):
        r = rng.standard_normal(3) * 7e6
        t = rng.uniform(0.0, 1e5)
        theta = geomag.gmst(EPOCH, t)
        c, s = math.cos(theta), math.sin(theta)
        b = igrf.field_ecef(np.array([c * r[0] + s * r[1], c * r[1] - s * r[0], r[2]]), t)
        expected = np.array([c * b[0] - s * b[1], s * b[0] + c * b[1], b[2]])
        assert igrf.field_eci(r, t).tobytes() == expected.tobytes()    # elementwise only
    with pytest.raises(ValueError, match='non-zero'):
        field.field_eci(np.zeros(3), 0.0)
    with pytest.raises(ValueError, match='finite'):
        field.field_eci([np.nan, 1.0, 2.0], 0.0)


# ----------------------------------------------------------- compiled vs uncompiled
def sample(compile_now=True):
    """Outputs of every kernel here and of the shared ones (``core.kernels``) on fixed inputs,
    as hex floats (run compiled, with ``NUMBA_DISABLE_JIT=1``, and before numba is loaded:
    ``compile_now`` False, as in a node process that compiles nothing)."""
    if compile_now:
        kernels.compile_all()
    rng = np.random.default_rng(5)
    out = []
    for mode in magnetic.MODES:
        for _ in range(200):
            q, w, omega0, q_ref, y_ref, b = random_case(rng)
            r = magnetic.law_kernel(q, w, omega0, q_ref, y_ref, b, np.array([0.0, 0.0, 1.0]),
                                    3e-3, 0.2, np.array([40.0, 30.0, 20.0]),
                                    mode == 'three_axis', mode == 'two_stage',
                                    math.radians(60.0), math.radians(2.0), np.zeros(3),
                                    False)
            out.extend(r.tolist())
    for _ in range(200):
        v = rng.normal(0.0, 30.0, 3)
        lim = np.array([40.0, 1.0, np.inf])
        out.append(float(manager.limit_violation(v, lim, 1e-9)))
        out.extend(manager.clip_finite(v, lim).tolist())
        r = rng.standard_normal(3) * 7e6
        out.extend(geomag.dipole_eci(r, rng.uniform(0, 6.3), np.array([0.1, -0.2, -0.97]),
                                     8e15).tolist())
        out.extend(onboard.to_orbit_axes(rng.standard_normal(4), r).tolist())
        p, q, m = rng.standard_normal(4), rng.standard_normal(4), rng.standard_normal((3, 3))
        for value in (kernels.qmul(p, q), kernels.dcm(q), kernels.cross(p[:3], q[:3]),
                      kernels.skew(p[:3]), kernels.mv(m, q[:3]), kernels.matmul(m, m.T)):
            out.extend(value.ravel().tolist())
    kinds = [type(f).__name__ for f in (magnetic.law_kernel, manager.limit_violation,
                                        manager.clip_finite, geomag.dipole_eci,
                                        onboard.to_orbit_axes, kernels.qmul, kernels.matmul)]
    return kinds, [float(x).hex() for x in out]
