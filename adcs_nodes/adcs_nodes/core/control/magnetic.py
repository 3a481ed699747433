"""Magnetorquer-only attitude control to the orbital frame (paper 000, section 2; pure numpy).

Lebedev, Tkachenko, Shtepa, "Magnetic system for controlling the angular motion of a
micro-satellite" (seed paper 000; digest ``papers/magnetic-microsatellite.md``, sections 1-3).
Equation numbers are the paper's; (derived) marks what the digest derived.

Frames and state
----------------
``Lambda = lambda0 + lambda`` (scalar first) is our ``q_orbit_body`` (scalar last), converted
only by :func:`adcs_nodes.core.attitude.to_scalar_first`. Body components of the orbit normal
``j2`` and the vertical ``j3`` (zenith)::

    e_R = [2(l1 l3 - l0 l2), 2(l2 l3 + l0 l1), l0^2 - l1^2 - l2^2 + l3^2]^T              (10)
    e_N = [2(l1 l2 + l0 l3), l0^2 - l1^2 + l2^2 - l3^2, 2(l2 l3 - l0 l1)]^T

    y = omega - omega0 e_N          relative rate of the body w.r.t. the orbital frame       (7)
    2 dLambda/dt = Lambda . y                                                               (8)

Three-axis law (Lyapunov, two stages)::

    y* = -2 alpha lambda sign(lambda0) / (1 + |lambda0|)       kinematic law, rho = 2(1-|l0|) (16)
    M* = -k (y - y*)                                            torque demand             (27)
       = -k (y + 2 alpha lambda sign(lambda0) / (1 + |lambda0|))                           (29)

``sign(0) = +1`` (paper). Under (16) alone ``rho(t) = rho(0) exp(-alpha t)`` exactly
(derived; digest 6.2).

One-axis law (``xi`` a body axis, ``s`` a direction fixed in the orbital frame, both in body
components; ``ds/dt = s x y`` (18))::

    y* = -alpha (s x xi) / (1 + xi^T s)                         rho = 1 - xi^T s          (21)
    M* = -k (y - y*)                                                                      (32)

Magnetorquers only realise the part of ``M*`` perpendicular to ``B`` (body, measured)::

    M_u = L x B = M* - b (b^T M*),   b = B / |B|                                          (4), (22)
    Phi(B) L* = -M*  (pseudo-solution)  ->  L* = (B x M*) / |B|^2                         (30)
    L = sigma L*,  sigma = min(1, 1 / max_i(|L*_i| / l_i))                                (31)

**Sign of (30).** The printed ``L* = -k Phi^+(B) Y`` is positive feedback (digest 3.4); this
module solves (30) itself, ``L* = B x M* / |B|^2``, so ``M_u . M* >= 0`` (a unit test pins it).

Gain condition
--------------
With ``V = 1/2 Y^T I Y + beta |lambda|^2`` (25), ``beta > 0``, the paper needs::

    k > beta / (2 alpha)                                                                  (28)
    k > beta / (2 alpha Sigma*),   Sigma* = min_t sigma(t)   with the scaling (31)

``beta`` is free (it appears only in the proof): the start-up check uses a configured ``beta``
(and ``Sigma*``, default 1), else only ``alpha > 0``, ``k > 0``; in every mode.

Assumptions (not in the paper)
------------------------------
* Default gains ``alpha = 3e-3 1/s``, ``k = 0.2 N m s``, ``l_i = 40 A m^2``: the digest's
  proposals (3.6), not the paper's values.
* Target other than the orbital frame: the error quaternion ``q_err = conj(q_ref) (x) q``
  (``= q_ref_body``) replaces ``Lambda`` in (16)/(29); ``y`` stays the rate relative to the
  orbital frame (the reference is fixed in it) and the target rate ``omega_body_ref_body`` is
  added to ``y*`` as a feed-forward. For the one-axis law the orbit-fixed direction is where
  ``xi`` points at the target attitude: ``s = R(q)^T R(q_ref) xi`` (``= e_R`` for the
  identity target and ``xi = z``).
* Two-stage switching (the paper gives no criterion): one-axis law until the angle between
  ``xi`` and ``s`` is below ``switch_angle_deg`` AND ``|y - y_ref|`` is below
  ``switch_rate_deg_s`` (digest proposal: 15 deg, 0.2 deg/s), then the three-axis law until
  :meth:`MagneticController.reset` (no way back: one switch, as in the paper's description).
* (21) is singular at ``s = -xi``: its denominator ``1 + xi^T s`` is floored at 0.01
  (beyond ~171.9 deg ``|y*|`` stays below ~14 alpha); exactly at ``s = -xi`` ``y* = 0`` and the
  law only damps ``y`` until any motion leaves that unstable point.
* ``|B| < b_min_T`` (default 1e-9 T): zero dipole with a reason (guarded pseudo-inverse,
  pitfall 8). ``B`` is the measured field (digest 3.6).

Beyond the paper: feed-forward (``inertia`` given; DEPARTURE, off by default)
------------------------------------------------------------------------------
The gyroscopic and gravity-gradient torques, left out of the paper's Lyapunov argument, added
to the demand from the estimate::

    M* <- M* + omega x I omega - 3 omega0^2 e_R x I e_R                                      (F1)

The loop is periodic (``1 - b b^T`` turns with the field): unstable once ``sqrt(k alpha / 2I)``
exceeds about ``omega0`` (Floquet; ``docs/decisions.md``, magnetic acquisition).

Compiled law
------------
:func:`law_kernel` (numba, ``cache=True``, no fastmath) repeats the helper functions'
operations in their order, so it gives their bits (a unit test compares them, and the kernel
run uncompiled).
"""
from __future__ import annotations

import functools
import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude
from adcs_nodes.core.control import (Command, ControlInputs, Estimate, Target, cross3,
                                     finite_vector, limits_vector, positive)
from adcs_nodes.core.kernels import cross, jit
from adcs_nodes.core.samples import all_finite

MODES = ('three_axis', 'one_axis', 'two_stage')
"""Accepted values of ``mode``."""
B_MIN_DEFAULT_T = 1e-9
"""Field magnitude below which no dipole is commanded [T]."""
ONE_AXIS_DENOMINATOR_FLOOR = 0.01
"""Floor of ``1 + xi^T s`` in (21) (assumption, see the module docstring)."""


def sign0(x: float) -> float:
    """The paper's ``sign``: +1 for ``x >= 0`` (so ``sign(0) = +1``), -1 otherwise."""
    return 1.0 if x >= 0.0 else -1.0


def orbit_axes_in_body(q_orbit_body: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Body components of the vertical ``e_R`` and the orbit normal ``e_N``, eq. (10).

    Parameters
    ----------
    q_orbit_body : array_like, shape (4,)
        Attitude, scalar last (normalised here).

    Returns
    -------
    e_R, e_N : ndarray, shape (3,)
        Unit vectors, body axes (zenith ``j3`` and orbit normal ``j2``).
    """
    l0, l1, l2, l3 = attitude.to_scalar_first(attitude.normalize(q_orbit_body))
    e_r = np.array([2.0 * (l1 * l3 - l0 * l2), 2.0 * (l2 * l3 + l0 * l1),
                    l0 * l0 - l1 * l1 - l2 * l2 + l3 * l3])                           # (10)
    e_n = np.array([2.0 * (l1 * l2 + l0 * l3), l0 * l0 - l1 * l1 + l2 * l2 - l3 * l3,
                    2.0 * (l2 * l3 - l0 * l1)])                                       # (10)
    return e_r, e_n


def relative_rate(q_orbit_body: ArrayLike, omega_body_eci_body: ArrayLike,
                  omega0: float) -> np.ndarray:
    """Rate of the body w.r.t. the orbital frame, body axes [rad/s]: ``y = omega - omega0 e_N``
    (7)."""
    _, e_n = orbit_axes_in_body(q_orbit_body)
    return np.asarray(omega_body_eci_body, dtype=float) - float(omega0) * e_n         # (7)


def target_rate_three_axis(q_err: ArrayLike, alpha: float) -> np.ndarray:
    """Kinematic three-axis law (16).

    Parameters
    ----------
    q_err : array_like, shape (4,)
        Attitude error, scalar last (``Lambda`` of the paper, scalar moved to the end).
    alpha : float
        Kinematic gain [1/s].

    Returns
    -------
    ndarray, shape (3,)
        ``y* = -2 alpha lambda sign(lambda0) / (1 + |lambda0|)``, body axes [rad/s].
    """
    q = attitude.normalize(q_err)
    lam, lam0 = q[:3], q[3]
    return -2.0 * alpha * lam * sign0(lam0) / (1.0 + abs(lam0))                       # (16)


def target_rate_one_axis(s: ArrayLike, xi: ArrayLike, alpha: float) -> np.ndarray:
    """Kinematic one-axis law (21), ``y* = -alpha (s x xi) / (1 + xi^T s)`` [rad/s].

    Parameters
    ----------
    s : array_like, shape (3,)
        Unit direction fixed in the orbital frame, body components.
    xi : array_like, shape (3,)
        Unit body axis to align with ``s``.
    alpha : float
        Kinematic gain [1/s].

    Notes
    -----
    The denominator is floored at :data:`ONE_AXIS_DENOMINATOR_FLOOR` near ``s = -xi``.
    """
    s = np.asarray(s, dtype=float)
    xi = np.asarray(xi, dtype=float)
    den = max(1.0 + float(xi @ s), ONE_AXIS_DENOMINATOR_FLOOR)
    return -alpha * cross3(s, xi) / den                                               # (21)


def torque_demand(y: ArrayLike, y_star: ArrayLike, k: float) -> np.ndarray:
    """Torque demand ``M* = -k (y - y*)`` [N m], body axes, eqs. (27), (29), (32)."""
    return -float(k) * (np.asarray(y, dtype=float) - np.asarray(y_star, dtype=float))


def dipole_from_torque(m_star: ArrayLike, b_body: ArrayLike) -> np.ndarray:
    """Pseudo-solution of ``Phi(B) L* = -M*`` (30), sign as in the digest (3.4).

    Parameters
    ----------
    m_star : array_like, shape (3,)
        Demanded torque, body axes [N m].
    b_body : array_like, shape (3,)
        Geomagnetic field, body axes [T]; must be non-zero (the caller guards ``|B|``).

    Returns
    -------
    ndarray, shape (3,)
        ``L* = (B x M*) / |B|^2`` [A m^2], perpendicular to ``B``, with
        ``L* x B = M* - b (b^T M*)`` (22).
    """
    b = np.asarray(b_body, dtype=float)
    return cross3(b, np.asarray(m_star, dtype=float)) / float(b @ b)                  # (30)


def check_gains(alpha: float, k: float, beta: Optional[float] = None,
                sigma_star: float = 1.0) -> None:
    """Start-up gain check, eqs. (12), (27), (28) and the scaled form after (31).

    Parameters
    ----------
    alpha : float
        Kinematic gain [1/s], must be > 0 (12).
    k : float
        Rate gain [N m s], must be > 0 (27).
    beta : float, optional
        Lyapunov weight of (25) [J]; when given, ``k > beta / (2 alpha Sigma*)`` must hold.
    sigma_star : float
        ``Sigma*``, the smallest scaling factor (31) expected, in (0, 1].

    Raises
    ------
    ValueError
        Naming the parameters and the violated condition.
    """
    alpha = positive(alpha, 'alpha', '1/s')
    k = positive(k, 'k', 'N m s')
    sigma_star = positive(sigma_star, 'sigma_star', '-')
    if sigma_star > 1.0:
        raise ValueError(f'sigma_star (Sigma*, smallest scaling factor of eq. (31)) must be in '
                         f'(0, 1], got {sigma_star}')
    if beta is None:
        return
    beta = positive(beta, 'beta', 'J')
    bound = beta / (2.0 * alpha * sigma_star)
    if not k > bound:
        raise ValueError(
            f'gain condition of paper 000 eq. (28) violated: need k > beta / (2 alpha Sigma*) '
            f'= {beta:g} / (2 * {alpha:g} * {sigma_star:g}) = {bound:g} N m s, got k = {k:g} '
            f'(raise k or alpha, or lower beta below 2 alpha k Sigma* = '
            f'{2.0 * alpha * k * sigma_star:g})')


# No target: the orbital frame itself (11); read by the kernel, never written.
_ORBIT_Q_REF = Target().q_orbit_body_ref
_ZERO_RATE = Target().omega_body_ref_body

#: Layout of the :func:`law_kernel` output (one float64 array): offsets of the (3,) vectors
#: ``y``, ``y*``, ``M*``, ``L*``, ``L``, ``L x B``, then the scalars.
K_Y, K_Y_STAR, K_M_STAR, K_L_STAR, K_DIPOLE, K_TORQUE = 0, 3, 6, 9, 12, 15
K_SIGMA, K_ANGLE, K_AXIS_ANGLE, K_THREE_AXIS = 18, 19, 20, 21
K_SIZE = 22


@jit
def _normalized(q):
    """``q / |q|``, ``|q| = sqrt(q . q)`` summed in index order (as :func:`attitude.normalize`)."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return np.array([q[0] / n, q[1] / n, q[2] / n, q[3] / n])


@jit
def law_kernel(q_orbit_body, omega_body_eci_body, omega0, q_ref, y_ref, b_body, xi, alpha, k,
               max_dipole, three_axis, may_switch, switch_angle, switch_rate, m_ff, use_ff):
    """Paper 000's magnetic law for one frame, compiled (see the module docstring).

    Parameters
    ----------
    q_orbit_body : numpy.ndarray, shape (4,)
        Estimated attitude, scalar last (normalised here).
    omega_body_eci_body : numpy.ndarray, shape (3,)
        Estimated absolute rate, body axes [rad/s].
    omega0 : float
        Orbit rate [rad/s].
    q_ref, y_ref : numpy.ndarray, shapes (4,), (3,)
        Target ``q_orbit_body_ref`` and rate ``omega_body_ref_body`` [rad/s].
    b_body : numpy.ndarray, shape (3,)
        Field, body axes [T], ``|B| > 0``.
    xi : numpy.ndarray, shape (3,)
        Unit body axis of the one-axis law.
    alpha, k : float
        Gains [1/s], [N m s].
    max_dipole : numpy.ndarray, shape (3,)
        Coil limits ``l_i`` [A m^2], > 0.
    three_axis : bool
        True: the three-axis law (16); False: the one-axis law (21).
    may_switch : bool
        Two-stage mode in the one-axis stage: switch to the three-axis law when the axis
        angle is below ``switch_angle`` [rad] and ``|y - y_ref|`` below ``switch_rate``
        [rad/s].
    m_ff : numpy.ndarray, shape (3,)
        Feed-forward torque (F1) [N m], added to ``M*`` when ``use_ff``.

    Returns
    -------
    numpy.ndarray, shape (K_SIZE,)
        ``y``, ``y*``, ``M*``, ``L*``, ``L = sigma L*``, ``L x B`` (slices ``K_*``), then
        ``sigma``, the attitude error of the active law (three-axis: its half-angle cosine
        ``min(1, |q_err_w|)``, the caller takes ``2 arccos`` with numpy's ``arccos``, whose
        bits :func:`attitude.angle_between` has; one-axis: the angle [rad]), the one-axis
        angle [rad] and 1.0 when the three-axis law was used.
    """
    out = np.zeros(K_SIZE)
    q = _normalized(q_orbit_body)
    qr = _normalized(q_ref)
    q_err = np.array([0.0, 0.0, 0.0, 0.0])
    px, py, pz, pw = -qr[0], -qr[1], -qr[2], qr[3]                 # conj(q_ref) (x) q
    q_err[0] = pw * q[0] + px * q[3] + py * q[2] - pz * q[1]
    q_err[1] = pw * q[1] - px * q[2] + py * q[3] + pz * q[0]
    q_err[2] = pw * q[2] + px * q[1] - py * q[0] + pz * q[3]
    q_err[3] = pw * q[3] - px * q[0] - py * q[1] - pz * q[2]
    # (7), (10): y = omega - omega0 e_N, Lambda = (l0, l1, l2, l3) scalar first
    qn = _normalized(q)
    l0, l1, l2, l3 = qn[3], qn[0], qn[1], qn[2]
    e_n0 = 2.0 * (l1 * l2 + l0 * l3)                                                  # (10)
    e_n1 = l0 * l0 - l1 * l1 + l2 * l2 - l3 * l3
    e_n2 = 2.0 * (l2 * l3 - l0 * l1)
    y = np.array([omega_body_eci_body[0] - omega0 * e_n0,                             # (7)
                  omega_body_eci_body[1] - omega0 * e_n1,
                  omega_body_eci_body[2] - omega0 * e_n2])
    # one-axis direction s = R(conj(q_err)) xi, the target's xi in body axes
    c = _normalized(np.array([-q_err[0], -q_err[1], -q_err[2], q_err[3]]))
    x_, y_, z_, w_ = c[0], c[1], c[2], c[3]
    r = np.array([[1 - 2 * (y_ * y_ + z_ * z_), 2 * (x_ * y_ - z_ * w_), 2 * (x_ * z_ + y_ * w_)],
                  [2 * (x_ * y_ + z_ * w_), 1 - 2 * (x_ * x_ + z_ * z_), 2 * (y_ * z_ - x_ * w_)],
                  [2 * (x_ * z_ - y_ * w_), 2 * (y_ * z_ + x_ * w_), 1 - 2 * (x_ * x_ + y_ * y_)]])
    s = np.zeros(3)
    for i in range(3):
        s[i] = r[i, 0] * xi[0] + r[i, 1] * xi[1] + r[i, 2] * xi[2]
    xs = xi[0] * s[0] + xi[1] * s[1] + xi[2] * s[2]
    axis_angle = math.acos(min(1.0, max(-1.0, xs)))
    if may_switch and axis_angle < switch_angle:
        d0, d1, d2 = y[0] - y_ref[0], y[1] - y_ref[1], y[2] - y_ref[2]
        if math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) < switch_rate:
            three_axis = True                                                       # assumption
    y_star = np.zeros(3)
    if three_axis:
        qe = _normalized(q_err)                                                       # (16)
        sg = 1.0 if qe[3] >= 0.0 else -1.0
        den = 1.0 + abs(qe[3])
        for i in range(3):
            y_star[i] = y_ref[i] + -2.0 * alpha * qe[i] * sg / den
        angle = min(1.0, abs(qe[3]))         # cos(angle / 2), angle_between(q_err, identity)
    else:
        den = max(1.0 + xs, ONE_AXIS_DENOMINATOR_FLOOR)                               # (21)
        sx = cross(s, xi)
        for i in range(3):
            y_star[i] = y_ref[i] + -alpha * sx[i] / den
        angle = axis_angle
    m_star = np.zeros(3)
    for i in range(3):
        m_star[i] = -k * (y[i] - y_star[i])                                      # (29) / (32)
        if use_ff:
            m_star[i] += m_ff[i]                                                          # (F1)
    bb = b_body[0] * b_body[0] + b_body[1] * b_body[1] + b_body[2] * b_body[2]
    l_star = cross(b_body, m_star)                                                    # (30)
    phi = 0.0
    for i in range(3):
        l_star[i] = l_star[i] / bb
        ratio = abs(l_star[i]) / max_dipole[i] if abs(l_star[i]) > 0.0 else 0.0
        phi = max(phi, ratio)
    sigma = 1.0
    dipole = l_star.copy()
    if phi > 1.0:                                                                     # (31)
        sigma = 1.0 / phi
        for i in range(3):
            dipole[i] = min(max(sigma * l_star[i], -max_dipole[i]), max_dipole[i])
    torque = cross(dipole, b_body)                                                    # (4)
    for i in range(3):
        out[K_Y + i] = y[i]
        out[K_Y_STAR + i] = y_star[i]
        out[K_M_STAR + i] = m_star[i]
        out[K_L_STAR + i] = l_star[i]
        out[K_DIPOLE + i] = dipole[i]
        out[K_TORQUE + i] = torque[i]
    out[K_SIGMA] = sigma
    out[K_ANGLE] = angle
    out[K_AXIS_ANGLE] = axis_angle
    out[K_THREE_AXIS] = 1.0 if three_axis else 0.0
    return out


@functools.cache
def warm_up() -> None:
    """Compile (or load from the numba cache) :func:`law_kernel` once per process, from the
    constructor: the first compilation (1-2 s) never falls inside a frame."""
    q, v = np.array([0.0, 0.0, 0.0, 1.0]), np.array([1e-5, 0.0, 2e-5])
    for three_axis in (True, False):
        law_kernel(q, v, 1e-3, q, v, v, v, 1e-3, 0.2, v, three_axis, not three_axis, 0.1, 0.1,
                   v, three_axis)


class MagneticController:
    """Paper 000's magnetorquer laws: three-axis (29), one-axis (32), or two-stage.

    Parameters
    ----------
    mode : {'three_axis', 'one_axis', 'two_stage'}
        Control law.
    alpha : float
        Kinematic gain [1/s] of (16)/(21). Default 3e-3 (digest proposal, assumption).
    k : float
        Rate gain [N m s] of (27)/(32). Default 0.2 (digest proposal, assumption).
    max_dipole_Am2 : float or array_like, shape (3,)
        Coil limits ``l_i`` [A m^2], body axes, > 0. Default 40 (digest proposal).
    beta : float, optional
        Lyapunov weight of (25) [J], used only by the start-up check (28).
    sigma_star : float
        ``Sigma*`` in (0, 1] for the scaled gain condition; default 1 (no scaling assumed).
    switch_angle_deg : float
        Two-stage: angle between ``xi`` and ``s`` below which the three-axis law takes over
        [deg], in (0, 180). Default 15 (assumption).
    switch_rate_deg_s : float
        Two-stage: bound on ``|y - y_ref|`` for the switch [deg/s], > 0. Default 0.2.
    xi_body : array_like, shape (3,)
        Body axis of the one-axis law (normalised). Default body z (paper's two-stage variant).
    n_wheels : int
        Length of the (zero) wheel-torque vector in the command.
    b_min_T : float
        Field magnitude below which the dipole is zero [T], > 0. Default 1e-9.
    inertia : array_like, shape (3, 3), or None
        Inertia [kg m^2] for the feed-forward (F1); None: the paper's law.

    Raises
    ------
    ValueError
        On an unknown mode, bad gains (see :func:`check_gains`), limits or thresholds.
    """

    def __init__(self, mode: str = 'three_axis', alpha: float = 3e-3, k: float = 0.2,
                 max_dipole_Am2: ArrayLike = 40.0, beta: Optional[float] = None,
                 sigma_star: float = 1.0, switch_angle_deg: float = 15.0,
                 switch_rate_deg_s: float = 0.2, xi_body: ArrayLike = (0.0, 0.0, 1.0),
                 n_wheels: int = 0, b_min_T: float = B_MIN_DEFAULT_T,
                 inertia: Optional[ArrayLike] = None) -> None:
        if mode not in MODES:
            raise ValueError(f'mode must be one of {MODES}, got {mode!r}')
        check_gains(alpha, k, beta, sigma_star)
        self.mode = mode
        self.alpha = float(alpha)
        self.k = float(k)
        self.beta = None if beta is None else float(beta)
        self.sigma_star = float(sigma_star)
        self.max_dipole = limits_vector(max_dipole_Am2, 'max_dipole_Am2', 3,
                                        allow_zero=False, allow_inf=False)
        angle = positive(switch_angle_deg, 'switch_angle_deg', 'deg')
        if angle >= 180.0:
            raise ValueError(f'switch_angle_deg must be in (0, 180) deg, got {angle}')
        self.switch_angle = math.radians(angle)
        self.switch_rate = math.radians(positive(switch_rate_deg_s, 'switch_rate_deg_s',
                                                 'deg/s'))
        xi = finite_vector(xi_body, 'xi_body', (3,))
        if np.linalg.norm(xi) < 1e-9:
            raise ValueError(f'xi_body must be a non-zero vector, got {xi}')
        self.xi = xi / np.linalg.norm(xi)
        if int(n_wheels) != n_wheels or n_wheels < 0:
            raise ValueError(f'n_wheels must be an integer >= 0, got {n_wheels!r}')
        self.n_wheels = int(n_wheels)
        self.b_min = positive(b_min_T, 'b_min_T', 'T')
        self.inertia = None if inertia is None else np.array(inertia, dtype=float).reshape(3, 3)
        warm_up()
        self.stage = ''
        self.reset()

    def reset(self) -> None:
        """Back to the first stage (two-stage mode); the laws have no other state."""
        self.stage = 'three_axis' if self.mode == 'three_axis' else 'one_axis'

    def _zero(self, reason: str) -> Command:
        cmd = Command.zero(self.n_wheels, reason)
        cmd.info = {'stage': self.stage}
        return cmd

    def update(self, inputs: ControlInputs, t: float, dt: float) -> Command:
        """Registry interface: the law with the fresh field, else the onboard model field.

        Between magnetometer samples the field in body axes is the onboard model
        ``n* = R(q_orbit_body)^T B*`` (paper 000's alternative to the measured ``n``). A target
        in another frame is converted to the orbital frame with the estimate.
        """
        target = inputs.target
        if target is not None and target.frame != 'orbit':
            try:
                target = target.in_frame('orbit', inputs.estimate)
            except ValueError as exc:
                return self._zero(str(exc))
        return self.law(inputs.estimate, target, inputs.field_body(), t, dt)

    def feedforward(self, q_orbit_body: np.ndarray, omega_body_eci_body: np.ndarray,
                    omega0: float) -> np.ndarray:
        """(F1) ``omega x I omega - 3 omega0^2 e_R x I e_R`` (3,) [N m] of the estimate
        (zeros without an inertia)."""
        if self.inertia is None:
            return np.zeros(3)
        e_r, _ = orbit_axes_in_body(q_orbit_body)
        return (cross(omega_body_eci_body, self.inertia @ omega_body_eci_body)
                - 3.0 * omega0 ** 2 * cross(e_r, self.inertia @ e_r))

    def law(self, estimate: Optional[Estimate], target: Optional[Target],
            b_body: Optional[ArrayLike], t: float, dt: float) -> Command:
        """Dipole command for frame ``t`` (the laws are static: ``t``, ``dt`` are unused).

        Parameters
        ----------
        estimate : Estimate or None
            Attitude ``q_orbit_body`` and rate ``omega_body_eci_body``; invalid -> zero.
        target : Target or None
            Target relative to the orbital frame; ``None`` is the orbital frame itself (11).
        b_body : array_like, shape (3,), or None
            Measured field, body axes [T]; missing, non-finite or ``|B| < b_min_T`` -> zero.
        t, dt : float
            Frame time and period [s].

        Returns
        -------
        Command
            ``dipole_body`` = ``sigma L*`` [A m^2], zero wheel and body torques; ``info`` holds
            ``stage``, ``y``, ``y_star``, ``torque_demand``, ``dipole_demand``, ``sigma``,
            ``torque_applied`` (``L x B``), ``angle_rad`` (attitude error of the active law),
            ``axis_angle_rad`` (angle between ``xi`` and ``s``, the one-axis error).
        """
        if estimate is None or not estimate.is_usable():
            return self._zero('no valid attitude estimate')
        if b_body is None:
            return self._zero('no magnetic field measurement')
        b = np.asarray(b_body, dtype=float)
        if b.shape != (3,) or not all_finite(b):
            return self._zero(f'magnetic field measurement not finite or not (3,): {b}')
        b_norm = math.sqrt(b @ b)
        if b_norm < self.b_min:
            return self._zero(f'|B| = {b_norm:.3g} T below {self.b_min:.3g} T: dipole set to '
                              f'zero (pseudo-inverse of eq. (30) guarded)')
        if target is None:
            q_ref, y_ref = _ORBIT_Q_REF, _ZERO_RATE                    # the orbital frame (11)
        else:
            q_ref = np.asarray(target.q_orbit_body_ref, dtype=float)
            y_ref = np.asarray(target.omega_body_ref_body, dtype=float)
            if (q_ref.shape != (4,) or y_ref.shape != (3,) or not all_finite(q_ref, y_ref)
                    or math.sqrt(q_ref @ q_ref) < 1e-9):
                return self._zero('target not finite or malformed')
            if not math.isfinite(q_ref @ q_ref):                 # |q| overflows: scaled first
                q_ref = q_ref / np.max(np.abs(q_ref))

        q_est = np.asarray(estimate.q_orbit_body, dtype=float)
        w_est = np.asarray(estimate.omega_body_eci_body, dtype=float)
        out = law_kernel(q_est, w_est, float(estimate.omega0), q_ref, y_ref, b, self.xi,
                         self.alpha, self.k, self.max_dipole, self.stage == 'three_axis',
                         self.stage == 'one_axis' and self.mode == 'two_stage',
                         self.switch_angle, self.switch_rate,       # (7), (16)/(21), (29)-(31)
                         self.feedforward(q_est, w_est, float(estimate.omega0)),
                         self.inertia is not None)
        angle = float(out[K_ANGLE])
        if out[K_THREE_AXIS] == 1.0:
            self.stage = 'three_axis'
            angle = float(2.0 * np.arccos(angle))      # attitude.angle_between(q_err, identity)
        cmd = Command(out[K_DIPOLE:K_DIPOLE + 3].copy(), np.zeros(self.n_wheels), np.zeros(3))
        cmd.info = {'stage': self.stage, 'y': out[K_Y:K_Y + 3],
                    'y_star': out[K_Y_STAR:K_Y_STAR + 3],
                    'torque_demand': out[K_M_STAR:K_M_STAR + 3],
                    'dipole_demand': out[K_L_STAR:K_L_STAR + 3], 'sigma': float(out[K_SIGMA]),
                    'torque_applied': out[K_TORQUE:K_TORQUE + 3],
                    'angle_rad': angle,
                    'axis_angle_rad': float(out[K_AXIS_ANGLE])}
        return cmd
