"""Magnetometer-only attitude, rate and disturbance estimator of paper 000.

D. V. Lebedev, A. I. Tkachenko, Yu. N. Shtepa, "Magnetic system for controlling the angular
motion of a micro-satellite" (Glushkov Institute of Cybernetics, 1996), section 3; digest
``papers/magnetic-microsatellite.md`` sections 1, 2, 4 and 7. Equation numbers are the paper's.

Frames and the one convention boundary
--------------------------------------
The paper's ``Lambda = lambda0 + lambda`` (scalar first) maps body to orbit,
``r_J = Lambda . r_E . conj(Lambda)``, so it is this project's ``q_orbit_body`` with the scalar
moved to the end. The state quaternion ``N`` (estimate of ``Lambda``) is stored as
``q_orbit_body`` ``[x, y, z, w]``; :func:`q_orbit_body_from_lambda` and
:func:`lambda_from_q_orbit_body` (which call :func:`attitude.from_scalar_first` /
:func:`attitude.to_scalar_first`) are the only conversions, pinned by a test against (10).
The Hamilton product is the same in either storage order, so (33) and (39) are coded as printed.
Orbit frame J: x along-track, y orbit normal, z zenith; it turns at ``omega0`` about its y axis.

State (section 3 of the paper, digest 4.1)
------------------------------------------
``N`` (estimate of ``q_orbit_body``), ``omega'`` (estimate of ``omega_body_eci_body``, the
absolute rate in body axes) and ``m'`` (estimate of ``m = I^-1 M_r``, a constant disturbance
acceleration [rad/s^2]).

Equations
---------
Gravity-gradient and zenith/normal directions in body axes (paper (3), (10))::

    e_R = C(N) j3,  e_N = C(N) j2,  C(N) = R(N)^T (orbit -> body)                       (10)
    M_g = 3 omega0^2 e_R x I e_R                                                          (3)

Nonlinear prediction, integrated with RK4 over ``dt`` in ``substeps`` steps (orbit rate
``omega_* = (0, omega0, 0)`` in ORBIT axes on the left, ``omega'`` in BODY axes on the right)::

    dN/dt = 1/2 (N . omega' - omega_* . N)
    domega'/dt = I^-1 (I omega' x omega' + M_s) + m',   dm'/dt = 0                       (33)
    M_s = 3 omega0^2 e_R(N) x I e_R(N) + L x B

with ``L`` the commanded dipole [A m^2] and ``B`` [T] in body axes (given, the last accepted
measurement, or the reference rotated by ``N``).

Error state ``w = [mu, d_omega, d_m]`` (9,), ``M = mu0 + mu = conj(Lambda) . N`` (body-frame,
right multiplicative), ``d_omega = omega' - omega``, ``d_m = m' - m``; linearised model::

    dmu/dt      = -Phi(omega_E) mu + 1/2 d_omega
    dd_omega/dt = G(omega_E) d_omega - 6 omega0^2 G(e_R) Phi(e_R) mu + d_m                (34)
    dd_m/dt     = 0
    G(omega) = I^-1 [Phi(I omega) - Phi(omega) I]
             = [[0, b1 w3, b1 w2], [b2 w3, 0, b2 w1], [b3 w2, b3 w1, 0]]                   (35)
    b1 = (I_y - I_z) / I_x,  b2 = (I_z - I_x) / I_y,  b3 = (I_x - I_y) / I_z

``Phi(r)`` is the cross-product matrix; ``omega_E`` is taken as ``omega'`` and ``e_R`` from
``N``. The matrix ``A`` of (34) is frozen at the start of each substep, ``F = expm(A h)``, and
``P <- F P F^T`` (no process noise: the paper has none; ``sigma_j`` plays its role).
``expm`` is evaluated by scaling and squaring of its Taylor series (:func:`expm_taylor`)::

    expm(X) = (T_12(X / 2^s))^(2^s),  T_12(Y) = sum_{k=0}^{12} Y^k / k!,  ||X / 2^s||_1 <= 1/4

whose truncation error ``(1/4)^13 / 13! ~ 2e-18`` is below double rounding (tested against
``scipy.linalg.expm`` to 1e-13), without a LAPACK call per step.
The magnetic torque has no term in (34) (as in the paper), which is exact when ``B`` is the
measured field and neglects ``L x dB`` when ``B`` is the reference rotated by ``N``.

Measurement: ``n`` the magnetometer reading (body), ``n* = conj(N) . B* . N = C(N) B*`` with
``B*`` the model field in ORBIT axes, ``z = n - n*`` and, exactly for error-free ``n``::

    z = -(n + n*) x phi,   phi = mu / mu0                                                 (36)
    z = -(n + n*) x mu     (error O(|mu|^3); usable when mu0 may be near 0)               (37)
    H = [-Phi(n + n*), 0_3, 0_3]    (3, 9)

Sequential scalar update (guaranteed/fuzzy ellipsoids after Bakan 1995), ``j = 1, 2, 3``, with
``H_j^T`` the j-th row of ``H``, ``P_1^- = P``, ``P_{j+1}^- = P_j^+``::

    s_j = theta + H_j^T P_j^- H_j,   K_j = P_j^- H_j / s_j
    P_j^+ = sigma_j (P_j^- - K_j H_j^T P_j^-),   sigma_j = 1 + tau r_j^2 / s_j
    w_j = K_j r_j,   w = w_1 + w_2 + w_3                                                  (38)

Literal form (``literal_update=True``, as printed): ``r_j = z_j``. Default, the standard
sequential filter: ``r_j = nu_j = z_j - H_j^T (w_1 + ... + w_{j-1})``, the residual of ``z_j``
against the estimate already corrected by the earlier components. ``sigma_j`` uses the raw
``z_j`` in both forms unless ``sigma_from_innovation=True`` (digest 4.8 pseudo-code).
``theta`` is a variance of the field residual in T^2 (the digest's 0.09 uT^2 is 9e-14 T^2);
``(theta, tau, P) -> c (theta, tau, P)`` leaves ``K_j`` and ``w`` unchanged.

Recovery of the rotation part of ``w``: with (36) the first block is ``phi`` and
``mu0 = (1 + phi^T phi)^(-1/2)``, ``mu = mu0 phi``; with (37) it is ``mu`` (clamped to
``|mu| < 1``) and ``mu0 = (1 - |mu|^2)^(1/2)``. Correction (after it the error estimate is 0 and
``P`` keeps ``P^+``)::

    N+ = N- . (mu0 - mu),   omega'+ = omega'- - d_omega,   m'+ = m'- - d_m                (39)

``N . conj(M) = Lambda . M . conj(M) = Lambda``: the correction recovers the truth when ``w``
is exact.

Compiled kernels: :func:`predict_kernel` and :func:`update_kernel` hold the arithmetic (explicit
loops, no BLAS, numba without fastmath; the same code runs uncompiled with
``NUMBA_DISABLE_JIT=1``). Input checks and guards stay in Python around them.

Misalignment states (beyond the paper; ``misalignment_std0_rad`` > 0)
--------------------------------------------------------------------
The paper leaves the magnetometer misalignment (up to 10 deg) out of the filter. A reading
``n = R(delta) C B* + v`` of a sensor turned by the small constant ``delta`` (body axes) reads
like an attitude error, ``n - C B* ~ delta x n`` against ``-(n + n*) x phi`` (36), so one
reading cannot tell them apart; the dynamics can: the attitude error turns with the body
(``dmu/dt = -Phi(omega) mu + ...``, (34)) while ``delta`` stays in it. Three states
``d_delta = delta^ - delta`` extend ``w`` (12,), with ``dd_delta/dt = 0``, and::

    z = R(delta^)^T n - n*,   H = [-Phi(n + n*), 0_3, 0_3, 1/2 Phi(n + n*)]                 (M2)
    delta^+ = delta^ - d_delta                                                             (M3)
    P <- S (P - K H^T P) S,  S^2 = diag(sigma_j I_9, I_3)                                  (M4)

(M4): ``sigma_j`` of (38) stands for process noise of the dynamic states; a constant does not
get it (inflated, a weakly observed ``delta`` wandered in a slow hold). A sensor turned about
an axis of symmetry of the inertia reads and moves like the body turned about it: that
direction is left out of the prior (:func:`observable_misalignment`). The block starts at zero
and is opened by :meth:`MagneticFilter.open_misalignment` once the attitude is acquired.

Guards (not in the paper)
-------------------------
A reading or reference that is not a finite (3,) vector with magnitude in [1e-6, 1e-3] T is
rejected (state and ``P`` unchanged, reason returned, nothing raised); so is a correction that
is not finite or gives ``|omega'|`` > 1 rad/s or ``|m'|`` > 1e-4 rad/s^2 (limits configurable).
The quaternion is renormalised after every RK4 step and correction; ``P`` is symmetrised.
``P`` is an ellipsoid matrix, not a covariance.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude
from adcs_nodes.core.control import integer, positive
from adcs_nodes.core.kernels import cross, dcm, finite_vector, jit, matmul, mv, qmul, skew
from adcs_nodes.core.samples import all_finite

THETA_DEFAULT = (0.3e-6) ** 2
"""Default ``theta`` [T^2]: (0.3 uT)^2, about the largest magnetometer noise variance."""
TAU_DEFAULT = 0.01
"""Default ``tau`` (dimensionless) of ``sigma_j`` in (38)."""
P0_PHI_DEFAULT = np.array([10.0] * 3 + [0.0036] * 3 + [1e-14] * 3)
"""Default ``diag P(t0)`` for form (36): ``phi`` [-], rate [(rad/s)^2], ``m`` [(rad/s^2)^2]."""
P0_MU_DEFAULT = np.array([1.0] * 3 + [0.0036] * 3 + [1e-14] * 3)
"""Default ``diag P(t0)`` for form (37): ``mu`` [-], rate [(rad/s)^2], ``m`` [(rad/s^2)^2]."""
B_MIN_T = 1e-6
"""Smallest accepted field magnitude [T] (measured and reference)."""
B_MAX_T = 1e-3
"""Largest accepted field magnitude [T] (measured and reference)."""
MAX_RATE_DEFAULT = 1.0
"""Default largest accepted ``|omega'|`` [rad/s] after a correction (sanity guard, not paper)."""
MAX_DISTURBANCE_DEFAULT = 1e-2
"""Default largest accepted ``|m'|`` [rad/s^2] after a correction (divergence guard only)."""
MAX_MISALIGNMENT_RAD = math.radians(15.0)
"""Largest accepted misalignment estimate and prior std [rad] (paper 000: up to 10 deg)."""
MU_CLAMP = 0.999
"""Largest ``|mu|`` recovered from form (37) (digest pitfall 7)."""


def observable_misalignment(inertia: ArrayLike, rel_tol: float = 1e-6) -> np.ndarray:
    """Projector (3, 3) onto the misalignment directions the dynamics can tell from attitude.

    A sensor turned about an axis of symmetry of the inertia ellipsoid reads like the body
    turned about it (same readings, same dynamics): with two principal moments equal (within
    ``rel_tol``) the distinct principal axis ``a`` is removed, ``I - a a^T``; with three equal,
    nothing is observable (zero); else the identity.
    """
    moments, axes = np.linalg.eigh(np.asarray(inertia, dtype=float))
    close = [abs(moments[i] - moments[j]) <= rel_tol * moments[2]
             for i, j in ((0, 1), (1, 2), (0, 2))]
    if all(close):
        return np.zeros((3, 3))
    if close[0] or close[1] or close[2]:
        a = axes[:, 2 if close[0] else 0 if close[1] else 1]
        return np.eye(3) - np.outer(a, a)
    return np.eye(3)


# ------------------------------------------------------------------- convention boundary
def q_orbit_body_from_lambda(lam: ArrayLike) -> np.ndarray:
    """``q_orbit_body`` (4,), scalar last (not renormalised), of the paper's ``Lambda =
    {lambda0, lambda1..3}`` (4,), scalar FIRST, mapping body to orbit."""
    return attitude.from_scalar_first(lam)


def lambda_from_q_orbit_body(q_orbit_body: ArrayLike) -> np.ndarray:
    """The paper's scalar-first ``Lambda`` (4,) of ``q_orbit_body`` (4,), scalar last."""
    return attitude.to_scalar_first(q_orbit_body)


# ---------------------------------------------------------------------------- helpers
# e_R = C(N) j3 and e_N = C(N) j2 of (10) are the rows 2 and 1 of ``dcm(N)`` in the kernels.

def predicted_field_body(q_orbit_body: ArrayLike, b_orbit: ArrayLike) -> np.ndarray:
    """``n* = conj(N) . B* . N = C(N) B*`` (3,) [T], body axes, of ``b_orbit`` (3,) [T], orbit."""
    return dcm(np.asarray(q_orbit_body, dtype=float)).T @ np.asarray(b_orbit, float)


def _check_field(b: np.ndarray, name: str, b_min: float, b_max: float) -> str:
    if b.shape != (3,):
        return f'{name} must have shape (3,), got {b.shape}'
    if not all_finite(b):
        return f'{name} is not finite'
    mag = math.sqrt(float(b @ b))
    if not b_min <= mag <= b_max:
        return f'|{name}| = {mag:.3g} T outside [{b_min:.3g}, {b_max:.3g}] T'
    return ''


# ------------------------------------------------------------------------ kernels
# Plain loops on float64 arrays: compiled by numba, or run as Python (NUMBA_DISABLE_JIT=1).
_TAYLOR_ORDER = 12
_TAYLOR_NORM = 0.25


@jit
def expm_taylor(x):
    """``expm(x)`` (n, n) of a finite float64 (n, n) matrix: ``(T_12(x / 2^s))^(2^s)`` with
    ``||x / 2^s||_1 <= 1/4`` (Taylor series, scaling and squaring)."""
    n = x.shape[0]
    norm = 0.0
    for j in range(n):
        col = 0.0
        for i in range(n):
            col += abs(x[i, j])
        norm = max(norm, col)
    s = 0
    while norm > _TAYLOR_NORM and s < 64:
        norm *= 0.5
        s += 1
    y = x * (0.5 ** s)
    out = np.eye(n)
    for k in range(_TAYLOR_ORDER, 0, -1):  # Horner: I + y/1 (I + y/2 (I + ...))
        out = matmul(y, out) * (1.0 / k)
        for i in range(n):
            out[i, i] += 1.0
    for _ in range(s):
        out = matmul(out, out)
    return out


@jit
def _g_k(inertia, inertia_inv, v):
    """``G(v) = I^-1 [Phi(I v) - Phi(v) I]`` (3, 3) (35)."""
    inner = skew(mv(inertia, v)) - matmul(skew(v), inertia)
    return matmul(inertia_inv, inner)


@jit
def error_matrix_kernel(inertia, inertia_inv, omega0, q, omega):
    """Error-model matrix ``A`` (9, 9) of (34), ``dw/dt = A w``, ``w = [mu, d_omega, d_m]``, at
    ``N = q`` (4,) (``e_R`` (10)) and ``omega_E = omega`` (3,) [rad/s]; ``inertia`` (3, 3)
    [kg m^2] and its inverse, body axes; ``omega0`` the orbit rate [rad/s]."""
    e_r = dcm(q)[2, :].copy()
    a = np.zeros((9, 9))
    sk_w = skew(omega)
    c = matmul(_g_k(inertia, inertia_inv, e_r), skew(e_r))
    g = _g_k(inertia, inertia_inv, omega)
    for i in range(3):
        a[i, 3 + i] = 0.5                       # (34) first row
        a[3 + i, 6 + i] = 1.0                   # (34) second row, d_m
        for j in range(3):
            a[i, j] = -sk_w[i, j]
            a[3 + i, j] = -6.0 * omega0 ** 2 * c[i, j]
            a[3 + i, 3 + j] = g[i, j]
    return a


@jit
def _rates_k(q, omega, m, inertia, inertia_inv, omega0, dipole, field, field_mode):
    """(33): ``dN/dt`` (4,) and ``domega'/dt`` (3,); ``field_mode`` 0 none, 1 body, 2 orbit."""
    c_bo = dcm(q)                            # R(N); C(N) = R(N)^T (orbit -> body)
    e_r = c_bo[2, :].copy()
    m_s = 3.0 * omega0 ** 2 * cross(e_r, mv(inertia, e_r))  # (3) from the estimate
    if field_mode == 1:
        m_s = m_s + cross(dipole, field)     # (4) L x B, B measured or given
    elif field_mode == 2:
        b_body = np.empty(3)
        for i in range(3):
            b_body[i] = c_bo[0, i] * field[0] + c_bo[1, i] * field[1] + c_bo[2, i] * field[2]
        m_s = m_s + cross(dipole, b_body)    # (4) L x n*
    w4 = np.zeros(4)
    w4[0], w4[1], w4[2] = omega[0], omega[1], omega[2]
    o4 = np.zeros(4)
    o4[1] = omega0
    q_dot = 0.5 * (qmul(q, w4) - qmul(o4, q))   # (33)
    omega_dot = mv(inertia_inv, cross(mv(inertia, omega), omega) + m_s) + m
    return q_dot, omega_dot


@jit(loads_numba=True)
def predict_kernel(q, omega, m, p, inertia, inertia_inv, omega0, dipole, field, field_mode,
                   h, substeps):
    """``substeps`` RK4 steps of (33) of ``h`` [s] and ``P <- F P F^T`` (34); the arguments
    are :meth:`MagneticFilter.predict`'s on arrays (``field_mode`` 0: no magnetic torque, 1:
    ``L x field`` with ``field`` in body axes, 2: ``L x C(N) field``, orbit axes). Returns
    ``N`` (4,) (unit), ``omega'`` (3,), ``P`` (symmetrised), may be non-finite, and two flags:
    ``N`` and ``omega'`` finite, ``P`` finite."""
    f = np.eye(9)
    for _ in range(substeps):
        a = error_matrix_kernel(inertia, inertia_inv, omega0, q, omega)  # (34), frozen
        f = matmul(expm_taylor(a * h), f)
        k1q, k1w = _rates_k(q, omega, m, inertia, inertia_inv, omega0, dipole, field,
                            field_mode)                                     # (33), RK4
        k2q, k2w = _rates_k(q + 0.5 * h * k1q, omega + 0.5 * h * k1w, m, inertia, inertia_inv,
                            omega0, dipole, field, field_mode)
        k3q, k3w = _rates_k(q + 0.5 * h * k2q, omega + 0.5 * h * k2w, m, inertia, inertia_inv,
                            omega0, dipole, field, field_mode)
        k4q, k4w = _rates_k(q + h * k3q, omega + h * k3w, m, inertia, inertia_inv, omega0,
                            dipole, field, field_mode)
        q = q + h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        omega = omega + h / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)
        q = q / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    ns = p.shape[0]
    if ns > 9:    # constant misalignment states: F = blockdiag(F_9, I)
        f_full = np.eye(ns)
        f_full[:9, :9] = f
        f = f_full
    p = matmul(matmul(f, p), f.T.copy())
    p = 0.5 * (p + p.T)
    return (q, omega, p, np.isfinite(q).all() and np.isfinite(omega).all(),
            np.isfinite(p).all())


@jit(loads_numba=True)
def update_kernel(q, omega, m, p, n, b_ref, theta, tau, literal, sigma_from_innovation,
                  form_phi):
    """(36)/(37) (and (M2)), the sequential update (38) and the correction (39) on arrays:
    the arguments of :meth:`MagneticFilter.update` (``theta`` (3,) [T^2] per body axis,
    ``form_phi``: (36)). Returns ``N+`` (4,), ``omega'+`` (3,), ``m'+`` (3,), ``P+``, ``z``
    (3,), ``w``, ``sigma`` (3,) (may be non-finite) and whether ``N+``, ``omega'+``, ``m'+``
    and ``P+`` are finite."""
    r = dcm(q)
    n_star = np.empty(3)
    for i in range(3):   # n* = C(N) B* = R(N)^T B*
        n_star[i] = r[0, i] * b_ref[0] + r[1, i] * b_ref[1] + r[2, i] * b_ref[2]
    z = n - n_star
    ns = p.shape[0]
    h_mat = np.zeros((3, ns))
    sk = skew(n + n_star)
    for i in range(3):
        for j in range(3):
            h_mat[i, j] = -sk[i, j]              # (36)/(37)
            if ns > 9:
                h_mat[i, 9 + j] = 0.5 * sk[i, j]    # (M2): misalignment error
    p = p.copy()
    w = np.zeros(ns)
    sigma = np.ones(3)
    for j in range(3):   # (38), sequential
        hj = h_mat[j]
        ph = np.zeros(ns)
        for a in range(ns):
            acc = 0.0
            for b in range(ns):
                acc += p[a, b] * hj[b]
            ph[a] = acc
        hph = 0.0
        hw = 0.0
        for a in range(ns):
            hph += hj[a] * ph[a]
            hw += hj[a] * w[a]
        s = theta[j] + hph
        k = ph / s
        nu = z[j] if literal else z[j] - hw
        r_sig = nu if (sigma_from_innovation and not literal) else z[j]
        sigma[j] = 1.0 + tau * r_sig * r_sig / s
        for a in range(ns):
            for b in range(ns):
                p[a, b] = sigma[j] * (p[a, b] - k[a] * ph[b])
        if ns > 9:   # (M4): P <- S P S, S^2 = diag(sigma, 1): no inflation of a constant
            root = 1.0 / math.sqrt(sigma[j])
            for a in range(9, ns):
                for b in range(ns):
                    p[a, b] *= root
                    p[b, a] *= root
        w = w + k * nu
    p = 0.5 * (p + p.T)
    q_new, omega_new, m_new = correct_kernel(q, omega, m, w, form_phi)
    finite = (np.isfinite(q_new).all() and np.isfinite(omega_new).all()
              and np.isfinite(m_new).all() and np.isfinite(p).all())
    return q_new, omega_new, m_new, p, z, w, sigma, finite


@jit(loads_numba=True)
def correct_kernel(q, omega, m, w, form_phi):
    """Correction (39): ``N-`` (4,), ``omega'-`` (3,) [rad/s], ``m'-`` (3,) [rad/s^2] less the
    error estimate ``w`` ``[phi or mu, d_omega, d_m]`` (estimate minus truth; ``form_phi``:
    form (36), else (37)). Returns ``N+`` (unit, not sign-normalised), ``omega'+``, ``m'+``."""
    v = w[0:3].copy()
    vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    if form_phi:   # (36): the block is phi
        mu0 = 1.0 / math.sqrt(1.0 + vv)
        mu = mu0 * v
    else:          # (37): the block is mu, clamped to |mu| < 1
        nv = math.sqrt(vv)
        mu = v if nv < MU_CLAMP else v * (MU_CLAMP / nv)
        mu0 = math.sqrt(max(0.0, 1.0 - (mu[0] * mu[0] + mu[1] * mu[1] + mu[2] * mu[2])))
    corr = np.empty(4)
    corr[0], corr[1], corr[2], corr[3] = -mu[0], -mu[1], -mu[2], mu0
    q_new = qmul(q, corr)   # (39): N . (mu0 - mu)
    qn = math.sqrt(q_new[0] ** 2 + q_new[1] ** 2 + q_new[2] ** 2 + q_new[3] ** 2)
    if qn > 0.0 and math.isfinite(qn):
        q_new = q_new / qn
    return q_new, omega - w[3:6], m - w[6:9]   # (39)


_WARM = {'done': False}


def warm_up() -> None:
    """Compile (or load from the numba cache) every kernel with the filter's argument types,
    once per process, so that compilation happens before a node joins the lockstep."""
    if _WARM['done']:
        return
    eye3, z3 = np.eye(3), np.zeros(3)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    for mode in (0, 1, 2):
        predict_kernel(q, z3, z3, np.eye(9), eye3, eye3, 1e-3, z3, z3, mode, 1.0, 1)
    for literal in (False, True):
        update_kernel(q, z3, z3, np.eye(9), np.ones(3), np.ones(3), np.ones(3), 0.01,
                      literal, False, True)
    update_kernel(q, z3, z3, np.eye(12), np.ones(3), np.ones(3), np.ones(3), 0.01, False,
                  False, True)
    predict_kernel(q, z3, z3, np.eye(12), eye3, eye3, 1e-3, z3, z3, 2, 1.0, 1)
    correct_kernel(q, z3, z3, np.zeros(9), False)
    _WARM['done'] = True


# ----------------------------------------------------------------------------- filter
class MagneticFilter:
    """Paper 000's magnetometer-only estimator of ``q_orbit_body``, ``omega_body_eci_body``, ``m``.

    ``inertia`` (3, 3) [kg m^2], body axes, SPD; ``theta`` > 0 [T^2] and ``tau`` >= 0 of (38);
    ``p0_diag``: ``diag P(t0)`` (9,) of ``[phi or mu, d_omega, d_m]`` in [-], [(rad/s)^2],
    [(rad/s^2)^2] (``None``: :data:`P0_PHI_DEFAULT` or :data:`P0_MU_DEFAULT`);
    ``measurement_form`` 'phi' (36) or 'mu' (37); ``literal_update``: the printed (38) with the
    raw ``z_j`` (default: sequential innovations ``nu_j``); ``substeps``: RK4 steps per
    :meth:`predict`; ``sigma_from_innovation``: ``nu_j`` in ``sigma_j``; ``b_limits_T``: the
    accepted field magnitudes [T]; ``max_rate_rad_s`` [rad/s] and ``max_disturbance_rad_s2``
    [rad/s^2]: a correction beyond them is rejected (guards, not in the paper);
    ``misalignment_std0_rad``: prior std [rad] of the states (M2)-(M4), 0: the paper's 9.
    A bad value is a ``ValueError``.
    """

    def __init__(self, inertia: ArrayLike, theta: float = THETA_DEFAULT, tau: float = TAU_DEFAULT,
                 p0_diag: Optional[ArrayLike] = None, measurement_form: str = 'phi',
                 literal_update: bool = False, substeps: int = 1,
                 sigma_from_innovation: bool = False,
                 b_limits_T: tuple[float, float] = (B_MIN_T, B_MAX_T),
                 max_rate_rad_s: float = MAX_RATE_DEFAULT,
                 max_disturbance_rad_s2: float = MAX_DISTURBANCE_DEFAULT,
                 misalignment_std0_rad: float = 0.0) -> None:
        inertia = np.asarray(inertia, dtype=float)
        theta, tau = positive(theta, 'theta', 'T^2'), positive(tau, 'tau', zero=True)
        max_rate_rad_s = positive(max_rate_rad_s, 'max_rate_rad_s')
        max_disturbance_rad_s2 = positive(max_disturbance_rad_s2, 'max_disturbance_rad_s2')
        if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)) \
                or not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(inertia) <= 0):
            raise ValueError('inertia must be a finite symmetric positive definite (3, 3) array')
        if measurement_form not in ('phi', 'mu'):
            raise ValueError(f"measurement_form must be 'phi' or 'mu', got {measurement_form!r}")
        substeps = integer(substeps, 'substeps')
        if p0_diag is None:
            p0_diag = P0_PHI_DEFAULT if measurement_form == 'phi' else P0_MU_DEFAULT
        p0 = np.asarray(p0_diag, dtype=float)
        if p0.shape != (9,) or not np.all(np.isfinite(p0)) or np.any(p0 <= 0.0):
            raise ValueError(f'p0_diag must be 9 finite positive numbers, got {p0_diag!r}')
        b_min, b_max = (float(b) for b in b_limits_T)
        if not 0.0 < b_min < b_max:
            raise ValueError(f'b_limits_T must satisfy 0 < min < max, got {b_limits_T!r}')
        self.inertia = inertia
        self._inertia_inv = np.linalg.inv(inertia)
        self.theta = float(theta)
        self.tau = float(tau)
        self.p0_diag = p0.copy()
        self.measurement_form = measurement_form
        self.literal_update = bool(literal_update)
        self.substeps = int(substeps)
        self.sigma_from_innovation = bool(sigma_from_innovation)
        self.b_limits = (b_min, b_max)
        self.max_rate = float(max_rate_rad_s)
        self.max_disturbance = float(max_disturbance_rad_s2)
        mis = float(misalignment_std0_rad)
        if not (math.isfinite(mis) and 0.0 <= mis <= MAX_MISALIGNMENT_RAD):
            raise ValueError(f'misalignment_std0_rad must be in [0, {MAX_MISALIGNMENT_RAD}], '
                             f'got {misalignment_std0_rad}')
        self._p0 = np.diag(p0)
        if mis > 0.0:
            self._p0 = np.zeros((12, 12))
            self._p0[:9, :9] = np.diag(p0)
            self._p_mis = mis ** 2 * observable_misalignment(inertia)
        warm_up()   # compiled kernels ready before the first step (numba cache)
        self.reset(attitude.identity(), np.zeros(3))

    # ----------------------------------------------------------------------- state
    def reset(self, q_orbit_body0: ArrayLike, omega_body_eci_body0: ArrayLike,
              m0: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        """Set ``N(t0)`` (4,), ``omega'(t0)`` (3,) [rad/s], ``m'(t0)`` (3,) [rad/s^2] (body
        axes) and ``P = diag(p0_diag)``; ``ValueError`` on non-finite input or a zero
        quaternion."""
        self._q = attitude.normalize(q_orbit_body0)
        self._omega = finite_vector(omega_body_eci_body0, 'omega_body_eci_body0', (3,)).copy()
        self._m = finite_vector(m0, 'm0', (3,)).copy()
        self._p = self._p0.copy()
        self._delta = np.zeros(3)
        self._last_b_meas: Optional[np.ndarray] = None

    def set_state(self, q_orbit_body: ArrayLike, omega_body_eci_body: ArrayLike, m: ArrayLike,
                  p: ArrayLike) -> None:
        """Set ``N`` (4,), ``omega'`` (3,) [rad/s], ``m'`` (3,) [rad/s^2] and ``P`` (9 or 12)."""
        self._q = attitude.normalize(q_orbit_body)
        self._omega = finite_vector(omega_body_eci_body, 'omega_body_eci_body', (3,)).copy()
        self._m = finite_vector(m, 'm', (3,)).copy()
        self._p = np.array(p, dtype=float).reshape(self._p0.shape)

    @property
    def q_orbit_body(self) -> np.ndarray:
        """``N`` (4,), scalar last: estimate of ``q_orbit_body`` (``v_orbit = R(N) v_body``)."""
        return self._q.copy()

    @property
    def omega_body_eci_body(self) -> np.ndarray:
        """``omega'`` (3,) [rad/s]: estimated rate of body w.r.t. ECI, body axes."""
        return self._omega.copy()

    @property
    def m(self) -> np.ndarray:
        """``m'`` (3,) [rad/s^2]: estimated disturbance acceleration ``I^-1 M_r``, body axes."""
        return self._m.copy()

    def open_misalignment(self) -> bool:
        """Open the misalignment block of ``P`` (prior ``misalignment_std0_rad``, observable
        directions only); the states start closed (zero) so that the attitude is acquired
        first. False when there are no such states or they are already open."""
        if self._p.shape[0] == 9 or self._p[9:, 9:].any():
            return False
        self._p[9:, 9:] = self._p_mis
        return True

    @property
    def misalignment_rad(self) -> np.ndarray:
        """``delta^`` (3,) [rad]: estimated sensor misalignment, ``n = R(delta) C B*`` (zero
        unless ``misalignment_std0_rad`` > 0)."""
        return self._delta.copy()

    def corrected(self, b_meas_body: ArrayLike) -> np.ndarray:
        """``R(delta^)^T n`` (3,) [T]: the reading with the estimated misalignment removed."""
        n = np.asarray(b_meas_body, dtype=float)
        if self._p0.shape[0] == 9:
            return n
        return attitude.to_matrix(attitude.from_rotation_vector(self._delta)).T @ n

    def residual(self, b_meas_body: ArrayLike, b_ref_orbit: ArrayLike) -> np.ndarray:
        """``z = n - n*`` (3,) [T] of a reading before the update (misalignment removed)."""
        return self.corrected(b_meas_body) - predicted_field_body(self._q, b_ref_orbit)

    @property
    def P(self) -> np.ndarray:
        """``P`` (9, 9) or (12, 12): ellipsoid matrix of ``[phi or mu, d_omega, d_m(, d_delta)]``
        (not a covariance)."""
        return self._p.copy()

    # ------------------------------------------------------------------ prediction
    def predict(self, dt: float, omega0: float, dipole_body: ArrayLike = (0.0, 0.0, 0.0),
                b_body_for_torque: Optional[ArrayLike] = None,
                b_orbit_for_torque: Optional[ArrayLike] = None) -> bool:
        """Propagate the estimate by (33) (RK4) and ``P`` by ``F P F^T``, ``F = expm(A dt)`` (34).

        ``dt`` [s] > 0; ``omega0`` the orbit rate [rad/s]; ``dipole_body`` ``L`` (3,) [A m^2]
        held over ``dt``; the field of ``L x B``: ``b_body_for_torque`` (3,) [T] body axes, else
        ``b_orbit_for_torque`` (3,) [T] orbit axes rotated by ``N`` at each RK4 stage, else the
        last accepted reading. Returns ``False`` if a result was not finite (a non-finite ``N``
        or ``omega'`` leaves the state unchanged, a non-finite ``P`` is reset to
        ``diag(p0_diag)``). ``ValueError`` on ``dt <= 0``, non-finite input, or a non-zero
        dipole with no field available.
        """
        dt, omega0 = float(dt), float(omega0)
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f'dt must be finite and > 0 [s], got {dt}')
        if not math.isfinite(omega0):
            raise ValueError(f'omega0 must be finite [rad/s], got {omega0}')
        dipole = finite_vector(dipole_body, 'dipole_body', (3,))
        b_body = b_orbit = None
        if dipole.any():
            if b_body_for_torque is not None:
                b_body = finite_vector(b_body_for_torque, 'b_body_for_torque', (3,))
            elif b_orbit_for_torque is not None:
                b_orbit = finite_vector(b_orbit_for_torque, 'b_orbit_for_torque', (3,))
            elif self._last_b_meas is not None:
                b_body = self._last_b_meas
            else:
                raise ValueError('a non-zero dipole needs b_body_for_torque, b_orbit_for_torque'
                                 ' or an earlier accepted measurement')
        field_mode, field = 0, np.zeros(3)
        if b_body is not None:
            field_mode, field = 1, b_body
        elif b_orbit is not None:
            field_mode, field = 2, b_orbit
        q, omega, p, finite_state, finite_p = predict_kernel(
            self._q, self._omega, self._m, self._p, self.inertia, self._inertia_inv, omega0,
            dipole, field, field_mode, dt / self.substeps, self.substeps)
        if not finite_state:
            return False
        self._q, self._omega = q, omega
        if not finite_p:
            self._p = self._p0.copy()
            return False
        self._p = p
        return True

    # ---------------------------------------------------------------------- update
    def update(self, b_meas_body: ArrayLike, b_ref_orbit: ArrayLike,
               theta_axes: Optional[ArrayLike] = None) -> dict:
        """Process one magnetometer reading: (36)/(37), sequential (38), correction (39).

        ``b_meas_body`` ``n`` (3,) [T], body axes; ``b_ref_orbit`` the model field ``B*`` (3,)
        [T], ORBIT axes, at the same instant; ``theta_axes`` (3,) [T^2]: ``theta`` of (38) per
        body axis for this reading only (``None``: the filter's ``theta``). Returns a dict:
        ``innovation`` ``z = n - n*`` (3,) [T], ``accepted``, ``reason`` (empty when accepted),
        ``sigma`` (3,) and ``correction`` ``w``. A rejected reading leaves the state and ``P``
        unchanged; nothing raises.
        """
        out = {'innovation': np.zeros(3), 'accepted': False, 'reason': '',
               'sigma': np.ones(3), 'correction': np.zeros(9)}
        try:
            n = np.asarray(b_meas_body, dtype=float)
            b_ref = np.asarray(b_ref_orbit, dtype=float)
        except (TypeError, ValueError):
            out['reason'] = 'field inputs are not numeric arrays'
            return out
        reason = (_check_field(n, 'b_meas_body', *self.b_limits)
                  or _check_field(b_ref, 'b_ref_orbit', *self.b_limits))
        theta = np.full(3, self.theta)
        if theta_axes is not None and not reason:
            try:
                theta = np.asarray(theta_axes, dtype=float).reshape(-1)
            except (TypeError, ValueError):
                theta = np.zeros(0)
            if theta.shape != (3,) or not np.all(np.isfinite(theta)) or np.any(theta <= 0):
                reason = 'theta_axes must be 3 finite positive variances [T^2]'
        if reason:
            out['reason'] = reason
            return out
        # n* = conj(N) . B* . N, (36)/(37), (38) sequential, correction (39)
        q, omega, m, p, z, w, sigma, finite = update_kernel(
            self._q, self._omega, self._m, self._p, np.ascontiguousarray(self.corrected(n)),
            np.ascontiguousarray(b_ref), np.ascontiguousarray(theta, dtype=float),
            self.tau, self.literal_update, self.sigma_from_innovation,
            self.measurement_form == 'phi')
        out['innovation'] = z
        if not finite or math.sqrt(float(q @ q)) < 1e-12:
            out['reason'] = 'update produced a non-finite state; reading ignored'
            return out
        rate, dist = math.sqrt(float(omega @ omega)), math.sqrt(float(m @ m))
        if rate > self.max_rate or dist > self.max_disturbance:
            out['reason'] = (f"correction gives |omega'| = {rate:.3g} rad/s, |m'| = {dist:.3g} "
                             f'rad/s^2, beyond ({self.max_rate:.3g}, {self.max_disturbance:.3g}); '
                             'reading ignored')
            return out
        delta = self._delta - w[9:12] if w.size > 9 else self._delta    # (M3)
        if not math.sqrt(float(delta @ delta)) <= MAX_MISALIGNMENT_RAD:
            out['reason'] = (f'correction gives a misalignment of {np.degrees(delta)} deg, '
                             f'beyond {math.degrees(MAX_MISALIGNMENT_RAD):.3g}; reading ignored')
            return out
        self._q, self._omega, self._m, self._p, self._delta = q, omega, m, p, delta
        self._last_b_meas = n.copy()
        out['accepted'], out['correction'], out['sigma'] = True, w, sigma
        return out
