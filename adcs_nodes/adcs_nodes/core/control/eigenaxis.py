"""Eigenaxis (Euler axis) geometry of an attitude error (paper 003; pure numpy).

Alekseev, Malyavin, Shadyan, "Extensive attitude control of a near-Earth satellite based on
fuzzy logic" (seed paper 003; digest ``papers/fuzzy-eigenaxis-slew.md``, sections 2-3).
Equation numbers are the paper's (it has no (11), (12)).

Also the frame both eigenaxis torque laws share (:class:`EigenaxisTorqueLaw`: the fuzzy
controller and the reference slew): the error state in the target's frame
(:func:`error_state`) and the torque realised as ideal body torque or on the wheels
(:func:`realise`).

Direction cosine matrix ``A`` (1): rows are body axes in the reference axes, ``v_body = A
v_ref``; Euler-Krylov angles ``psi, theta, gamma`` (3-2-1), ``A = R1(gamma) R2(theta)
R3(psi)``. The printed row 3 swaps ``sin psi`` and ``cos psi`` in its first products (a typo:
the printed matrix is not orthogonal); the corrected row is::

    a31 = cg st cp + sg sp,   a32 = cg st sp - sg cp,   a33 = cg ct                       (1)

In our convention ``A = R(q_ref_body)^T`` (``q_ref_body`` rotates body vectors into the
reference frame). For a target other than the reference axes the error DCM
``A_err = A A_T^T`` (ASSUMPTION, digest section 3) replaces ``A``; it is
``R(q_target_body)^T`` with ``q_target_body = q_ref_target^* q_ref_body``.

Eigenangle and eigenaxis::

    phi = arccos((tr A - 1) / 2)                                                          (7)
    V_i = (a_{i+1,i+2} - a_{i+2,i+1}) / (2 sin phi),   i = 1..3 cyclic                     (6)

``e_phi = V`` is the rotation axis of ``A^T`` and ``d phi / dt = e_phi . omega`` (``omega``
relative to the target, body axes). Numerically (digest pitfalls 1-3): ``phi = atan2(|v| / 2,
(tr A - 1) / 2)`` with ``v = 2 sin phi e_phi``; near 180 deg the axis comes from the symmetric
part ``A + A^T = 2 cos phi I + 2 (1 - cos phi) e e^T`` and its free sign is kept from the
previous axis (hysteresis).

Torque directions (``J`` the inertia matrix; the paper's principal ``J_i`` are its diagonal)::

    e_k  = J e_phi / J_k,   J_k  = |J e_phi| = sqrt(sum_i (J_i V_i)^2)                    (4)
    e_gk = J e_g / J_gk,    J_gk = |J e_g|   = sqrt(sum_i (J_i mu_i)^2)                    (5)

so a torque ``M_k e_k`` gives ``omega_dot = (M_k / J_k) e_phi`` (gyroscopic term aside).
Parasitic (gyroscopic) rate and its direction::

    phi_dot   = e_phi . omega
    phidot_g  = omega - phi_dot e_phi                                                     (9)
    e_g       = phidot_g / |phidot_g|                                                     (8)

and the backward difference of its modulus (signed, despite the notation)::

    |phiddot_g|_n = (|phidot_g|_n - |phidot_g|_{n-1}) / tau                              (15)
"""
from __future__ import annotations

import math
from typing import Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude
from adcs_nodes.core.control import Command, ControlInputs, Target, finite_vector
from adcs_nodes.core.control.wheel_allocation import WheelAllocator

__all__ = ['dcm_euler_321', 'eigen_from_dcm', 'eigen_from_quaternion', 'torque_direction',
           'gyroscopic_rate', 'RateModulusDerivative']

#: Below this |v| = 2 sin(phi) the axis from (6) is not trusted (near 0 or 180 deg).
_SIN_EPS = 1e-9
#: Default hysteresis band below 180 deg in which the previous axis sign is kept [rad].
HYSTERESIS_RAD = math.radians(1.0)


def dcm_euler_321(psi: float, theta: float, gamma: float) -> np.ndarray:
    """The DCM ``A`` (3, 3) of eq. (1), row 3 corrected, ``v_body = A v_ref``, of the 3-2-1
    Euler-Krylov angles [rad] (yaw, pitch, roll); ``R(from_euler_321(gamma, theta, psi))^T``."""
    cp, sp = math.cos(psi), math.sin(psi)
    ct, st = math.cos(theta), math.sin(theta)
    cg, sg = math.cos(gamma), math.sin(gamma)
    return np.array([
        [cp * ct, sp * ct, -st],                                                         # (1)
        [sg * st * cp - cg * sp, sg * st * sp + cg * cp, sg * ct],
        [cg * st * cp + sg * sp, cg * st * sp - sg * cp, cg * ct],   # row 3 typo corrected
    ])


def _keep_sign(phi: float, e: np.ndarray, axis_prev: Optional[np.ndarray],
               hysteresis_rad: float) -> Tuple[float, np.ndarray]:
    """Near 180 deg keep the previous axis: ``(phi, e) -> (2 pi - phi, -e)`` if flipped."""
    if (axis_prev is not None and phi > math.pi - hysteresis_rad
            and float(np.dot(e, axis_prev)) < 0.0):
        return 2.0 * math.pi - phi, -e
    return phi, e


def eigen_from_dcm(A: ArrayLike, axis_prev: Optional[ArrayLike] = None,
                   hysteresis_rad: float = HYSTERESIS_RAD) -> Tuple[float, np.ndarray]:
    """``(phi [rad], e_phi (3,))``, eigenangle (7) and unit eigenaxis (6) of the rotation
    ``A`` (3, 3), ``v_body = A v_ref``, robust near 0 and 180 deg.

    ``axis_prev`` (3,) is returned at ``phi = 0`` (zeros without one) and keeps the axis sign
    within ``hysteresis_rad`` of 180 deg (``phi`` may then exceed pi by up to that band).
    """
    a = np.asarray(A, dtype=float)
    v = np.array([a[1, 2] - a[2, 1], a[2, 0] - a[0, 2], a[0, 1] - a[1, 0]])   # 2 sin phi e
    c = 0.5 * (np.trace(a) - 1.0)
    nv = float(np.linalg.norm(v))
    phi = math.atan2(0.5 * nv, c)                                            # (7), robust
    prev = None if axis_prev is None else np.asarray(axis_prev, dtype=float)
    if c < -0.5:
        # Near 180 deg: the symmetric part gives |e_i| accurately; (6) only its sign.
        d = np.clip((np.diag(a) - c) / (1.0 - c), 0.0, None)
        i = int(np.argmax(d))
        e = np.empty(3)
        e[i] = math.sqrt(d[i])
        for j in range(3):
            if j != i:                                        # a_ij + a_ji = 2(1-c) e_i e_j
                e[j] = (a[i, j] + a[j, i]) / (2.0 * (1.0 - c) * e[i])
        e /= np.linalg.norm(e)
        if nv > _SIN_EPS:
            e = e if float(np.dot(e, v)) >= 0.0 else -e                         # (6) sign
        elif prev is not None and float(np.dot(e, prev)) < 0.0:
            e = -e
        return _keep_sign(phi, e, prev, hysteresis_rad)
    if nv > 0.0:
        return phi, v / nv                                              # (6), normalised
    return 0.0, (prev.copy() if prev is not None else np.zeros(3))


def eigen_from_quaternion(q_target_body: ArrayLike, axis_prev: Optional[ArrayLike] = None,
                          hysteresis_rad: float = HYSTERESIS_RAD) -> Tuple[float, np.ndarray]:
    """As :func:`eigen_from_dcm` for the error quaternion ``q_target_body`` (4,), scalar last,
    body -> target axes (``A_err = R(q)^T``), normalised here."""
    q = np.asarray(q_target_body, dtype=float)
    q = q / np.linalg.norm(q)
    if q[3] < 0.0:
        q = -q
    s = float(np.linalg.norm(q[:3]))
    prev = None if axis_prev is None else np.asarray(axis_prev, dtype=float)
    if s == 0.0:
        return 0.0, (prev.copy() if prev is not None else np.zeros(3))
    phi = 2.0 * math.atan2(s, float(q[3]))
    return _keep_sign(phi, q[:3] / s, prev, hysteresis_rad)


def torque_direction(inertia: ArrayLike, e: ArrayLike) -> Tuple[np.ndarray, float]:
    """``(e_k = J e / |J e| (3,), J_k = |J e| [kg m^2])``, eq. (4) or (5), of the inertia
    (3,) or (3, 3) [kg m^2] and the unit direction ``e`` (3,), body axes (zeros if ``e = 0``)."""
    J = np.asarray(inertia, dtype=float)
    je = (J @ np.asarray(e, dtype=float)) if J.ndim == 2 else J * np.asarray(e, dtype=float)
    jk = float(np.linalg.norm(je))                                              # (4), (5)
    if jk == 0.0:
        return np.zeros(3), 0.0
    return je / jk, jk


def gyroscopic_rate(omega: ArrayLike, e_phi: ArrayLike) -> Tuple[float, np.ndarray, float]:
    """``(phi_dot = e_phi . omega, phidot_g = omega - phi_dot e_phi (3,), g = |phidot_g|)``
    [rad/s], eq. (9), of the relative rate ``omega`` (3,) [rad/s] and the unit ``e_phi``, body
    axes."""
    w = np.asarray(omega, dtype=float)
    e = np.asarray(e_phi, dtype=float)
    phi_dot = float(np.dot(e, w))
    wg = w - phi_dot * e                                                                  # (9)
    return phi_dot, wg, float(np.linalg.norm(wg))


class RateModulusDerivative:
    """Backward difference of ``|phidot_g|``, eq. (15); 0 on the first sample (pitfall 5)."""

    def __init__(self) -> None:
        self._prev: Optional[float] = None

    def reset(self) -> None:
        """Forget the previous sample."""
        self._prev = None

    def update(self, g: float, tau: float) -> float:
        """``(g - g_prev) / tau`` [rad/s^2] for ``g = |phidot_g|`` [rad/s], period ``tau`` [s].

        Returns 0 for the first sample, a non-positive or non-finite ``tau`` or a non-finite
        ``g`` (which is then not stored).
        """
        if not math.isfinite(g):
            return 0.0
        prev, self._prev = self._prev, float(g)
        if prev is None or not (math.isfinite(tau) and tau > 0.0):
            return 0.0
        return (float(g) - prev) / float(tau)                                           # (15)


# ---------------------------------------------------------------------- the torque-law frame
class EigenaxisTorqueLaw:
    """Frame shared by the eigenaxis torque laws (:class:`FuzzyEigenaxisController` and
    :class:`~adcs_nodes.core.control.reference_slew.ReferenceSlewController`).

    ``update`` takes the error state (:func:`error_state`), asks the subclass's
    ``_torque_law(q_target_body, omega_rel_body, omega_body_eci_body, dt)`` for a dict with
    ``torque_body`` (3,) [N m, body axes] and diagnostics, and realises the torque as ideal
    body torque or on the reaction wheels (:func:`realise`). A subclass calls
    :meth:`_set_wheels` in its constructor.
    """

    A_w: Optional[np.ndarray] = None

    def _set_wheels(self, wheel_axes_body: Optional[ArrayLike],
                    wheel_max_torque_Nm: Optional[ArrayLike]) -> None:
        """``wheels``, a :class:`WheelAllocator` scaling onto the torque limits (A2), and
        ``A_w`` (3, n) its unit spin axes, body axes (``None``: ideal body torque)."""
        if wheel_axes_body is not None and np.size(wheel_axes_body) > 0:
            self.wheels = WheelAllocator(wheel_axes_body, wheel_max_torque_Nm, 'scale')
            self.A_w = self.wheels.A_w                                        # (3, n)
        else:
            self.A_w = None

    @property
    def n_wheels(self) -> int:
        return 0 if self.A_w is None else self.A_w.shape[1]

    def _torque_law(self, q_err: np.ndarray, w_rel: np.ndarray, w_abs: np.ndarray,
                    dt: float) -> dict:
        raise NotImplementedError

    def update(self, inputs: ControlInputs, t: float, dt: float) -> Command:
        """Command for frame time ``t`` (see :mod:`adcs_nodes.core.control`)."""
        err = error_state(inputs)
        if isinstance(err, str):
            return Command.zero(self.n_wheels, err)
        q_err, w_rel, w_abs = err
        out = self._torque_law(q_err, w_rel, w_abs, dt)
        torque = out.pop('torque_body')
        if not np.all(np.isfinite(torque)):
            return Command.zero(self.n_wheels, 'non-finite torque')
        return realise(torque, w_abs, inputs, self, out)


def error_state(inputs: ControlInputs):
    """``(q_target_body, omega_rel_body, omega_body_eci_body)`` or a reason string.

    The error is taken in the target's own frame: ``q_target_body = q_ref_target^*
    q_ref_body``; ``omega_rel`` is the rate relative to the target (orbit frame: minus the
    orbit rate about the orbit normal; then minus the target's feed-forward rate).
    """
    est = inputs.estimate
    if est is None or not est.is_usable():
        return 'no valid estimate'
    tgt = inputs.target if inputs.target is not None else Target()
    w = np.asarray(est.omega_body_eci_body, dtype=float)
    try:               # attitude.normalize: ValueError on a zero or non-finite quaternion
        q_t = attitude.normalize(tgt.q_ref_body)
        w_t = finite_vector(tgt.omega_body_ref_body, 'omega_body_ref_body', (3,))
        if tgt.frame not in ('eci', 'orbit'):
            return f'unknown target frame {tgt.frame!r}'
        if tgt.frame == 'eci' and est.q_eci_body is None:
            return 'target in eci but no inertial attitude estimate'
        q_b = np.asarray(est.q_eci_body if tgt.frame == 'eci' else est.q_orbit_body, float)
        w_frame = w if tgt.frame == 'eci' else \
            w - float(est.omega0) * (attitude.to_matrix(q_b).T @ np.array([0.0, 1.0, 0.0]))
        q_err = attitude.multiply(attitude.conjugate(q_t), attitude.normalize(q_b))
    except (TypeError, ValueError) as exc:
        return f'bad estimate or target: {exc}'
    return q_err, w_frame - w_t, w


def realise(torque: np.ndarray, omega: np.ndarray, inputs: ControlInputs, ctrl,
            info: dict) -> Command:
    """Command with ``torque`` as ideal body torque, or allocated to the wheels of ``ctrl``.

    ``ctrl`` has ``A_w`` (3, n) or None and ``wheels``
    (:class:`~adcs_nodes.core.control.wheel_allocation.WheelAllocator`). The wheels must give
    the body ``torque``: ``-A_w tau_w = torque + omega x A_w h_w``, so the demanded wheel
    momentum rate is ``h_dot_b = -(torque + omega x A_w h_w)`` (W3), allocated by (A1), (A2).
    """
    info = dict(info, torque_demand=torque)
    if ctrl.A_w is None:
        return Command(torque_body=torque, info=info)
    demand = torque.copy()
    h = inputs.wheel_momentum_Nms
    if h is not None:
        h = np.asarray(h, dtype=float)
        if h.shape == (ctrl.A_w.shape[1],) and np.all(np.isfinite(h)):
            demand = demand + np.cross(omega, ctrl.A_w @ h)   # cancel omega x h_wheels
    tau_w, dipole, _, _, refusal = ctrl.wheels.allocate_healthy(                 # (A1)-(A5)
        -demand, None, inputs.wheel_ok, inputs.field_body(), inputs.backup_dipole_Am2)
    if refusal:
        return Command.zero(ctrl.A_w.shape[1], refusal, refused=True)
    return Command(dipole_body=dipole, wheel_torque=tau_w, info=info)
