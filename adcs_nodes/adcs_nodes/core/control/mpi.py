"""MPI (model prediction + inversion) attitude control with reaction wheels (paper 001).

Tan Tian-le, "State transition control of satellite attitude" (seed paper 001; digest
``papers/mpi-state-transition-control.md``). Equation numbers are the paper's; (derived) marks
what is not printed in it. Pure numpy (scipy only for the optional exact transition).

Frames at the boundary (converted ONCE, in :func:`paper_state_from_project`)
----------------------------------------------------------------------------
The paper's reference frame is LVLH (x along-track, y negative orbit normal, z nadir), its
attitude the passive DCM ``C_bo = R_o2b`` (``v_body = C_bo v_lvlh``) or 3-1-2 Euler angles
``[phi, theta, psi]`` (yaw about z, then roll about x, then pitch about y)::

    R_o2b(phi, theta, psi) = Ry(theta) Rx(phi) Rz(psi)      (passive elementary rotations)
    phi = asin(R[1,2]), theta = atan2(-R[0,2], R[2,2]), psi = atan2(-R[1,0], R[1,1])

The project's orbit frame (x along-track, y orbit normal, z zenith) is LVLH turned half a turn
about x, ``D = R(q_orbit_lvlh) = diag(1, -1, -1)``, so::

    C_bo = R(q_orbit_body)^T D,      R(q_orbit_body) = D C_bo^T                          (F1)
    omega_bo (body rate w.r.t. LVLH, body axes) = omega_body_orbit_body                    (F2)
                 = omega_body_eci_body - R(q_orbit_body)^T [0, omega0, 0]

(the two reference frames do not move w.r.t. each other). Inside this module everything is the
paper's; outside, the project's.

Error state in the temporary frame (eqs. (1)-(4), (7))
------------------------------------------------------
``R_o2r``, ``omega_r``: current attitude and rate; ``R_o2f``, ``omega_f``: desired ones::

    R_t = R_o2f^T R_o2r,   [phi, theta, psi] = euler312(R_t)          (paper q_o2r q_o2f^-1)
    omega'_r = R_o2f^T omega_r                                                            (4)
    phi_dot   = w'x cos th + w'z sin th
    theta_dot = (w'x sin th sin ph + w'y cos ph - w'z cos th sin ph) / cos ph              (3)
    psi_dot   = (-w'x sin th + w'z cos th) / cos ph
    x  = [phi, theta, psi, phi_dot, theta_dot, psi_dot]^T
    x* = [0, 0, 0, R_o2f^T omega_f]^T
    I  = R_o2f^T I_b R_o2f = [[Ix, -Ixy, -Ixz], [-Ixy, Iy, -Iyz], [-Ixz, -Iyz, Iz]]      (2)
    h  = R_o2f^T h_b                                                                      (7)

Feedback-linearised model (eqs. (5), (6), (8)-(16))
---------------------------------------------------
``omega = [phi_dot - w0 psi, theta_dot - w0, psi_dot + w0 phi]`` (5) in
``I omega_dot + omega x (I omega + h) = -h_dot`` (6) gives, with ``p = phi_dot - w0 psi``,
``r = psi_dot + w0 phi``::

    x_dot = A x + B u,   A = [[0, E3], [I^-1 A1, I^-1 A2]],  B = [0; E3]             (9)-(11)
    u = I^-1 (-h_dot + K1 v1 + K2 v2 + c)                                             (12)
    v1 = [Ix - Iy, Iy - Iz, Iz - Ix],  v2 = [Ixy, Ixz, Iyz]
    A1, A2, K1, K2 as printed                                                       (13)-(16)
    c  = [w0 hz, 0, -w0 hx]                        (derived: constant part of -omega x h)

The paper drops ``c`` (digest P2); it is kept here unless ``literal_model=True``.

Prediction and inversion (eqs. (18)-(29))
-----------------------------------------
::

    Phi = sum_{k=0..N} A^k tau^k / k!                                                    (19)
    Q   = [sum_{k=1..N} A^(k-1) tau^k / k!] B                                         (20), (21)
    Q u = x* - Phi x  ->  u = Q^+ (x* - Phi x)                                   (22)-(26)
    h_dot   = -I u + K1 v1 + K2 v2 (+ c)                                                 (27)
    h_dot_b = R_o2f h_dot                                                                 (28)

``N = 5`` (the paper's "order 5"). Horizon ``tau``: the time left in a maneuver (shrinking
horizon, 5.1), one control period when stabilising or tracking (5.2). The body feels
``-h_dot_b``; wheel motor torques ``tau_w`` solve ``A_w tau_w = h_dot_b`` (minimum norm, (A1) of
:mod:`adcs_nodes.core.control.wheel_allocation`) and are then limited by ONE factor that keeps
the direction ((A2), paper 000 (31)) or, with ``saturation='clip'``, per wheel ((A3), digest
P17), then to the momentum headroom over one control period (A4).

Assumptions (not in the paper)
------------------------------
* ASSUMPTION: horizon floor ``tau = max(t_f - t0, min_horizon_s)``, default one control
  period (digest P5): otherwise ``Q -> 0`` at the deadline.
* ASSUMPTION: a Q without full column rank (e.g. zero horizon) is retried with one control
  period; if that fails too, the command is zero with the reason.
* ASSUMPTION: the desired state is the target at ``t0`` (digest P15, reproduces the paper's
  tracking lag); ``reference_time='t0_plus_tau'`` propagates it to ``t0 + tau``.

DEPARTURE (off by default), the two-wing variant: ``hold_horizon_s = 0.4`` with
``reference_time='t0_plus_tau'`` (digest P14, P15; ``docs/paper001.md``).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import Command, ControlInputs, Target, finite_vector, positive
from adcs_nodes.core.control.wheel_allocation import SATURATION, WheelAllocator
from adcs_nodes.core.orbit import Q_ORBIT_LVLH

__all__ = ['MPIController', 'euler312_to_dcm', 'dcm_to_euler312', 'body_rate_from_euler312',
           'euler312_rates_from_body_rate', 'body_accel_from_euler312',
           'paper_state_from_project', 'project_state_from_paper', 'lvlh_euler312_of',
           'q_orbit_body_of_lvlh_euler312', 'model', 'feedforward', 'transition',
           'transition_exact', 'solve_u', 'wheel_momentum_rate', 'error_state']

#: ``R(q_orbit_lvlh)``: LVLH axes in the project's orbit frame (half turn about x).
D_ORBIT_LVLH = att.to_matrix(Q_ORBIT_LVLH)
E3 = np.eye(3)
B_MATRIX = np.vstack([np.zeros((3, 3)), E3])                                          # (11)


# ------------------------------------------------------------------ 3-1-2 Euler angles
def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def euler312_to_dcm(euler: ArrayLike) -> np.ndarray:
    """Passive DCM (3, 3) ``R_o2b = Ry(theta) Rx(phi) Rz(psi)`` (``v_body = R v_ref``) of the
    3-1-2 angles ``[phi, theta, psi]`` (3,) [rad] (roll, pitch, yaw: the paper's order)."""
    phi, theta, psi = (float(v) for v in euler)
    return _ry(theta) @ _rx(phi) @ _rz(psi)


def dcm_to_euler312(dcm: ArrayLike) -> np.ndarray:
    """3-1-2 angles ``[phi, theta, psi]`` [rad] of a passive DCM (valid for ``|phi| < 90 deg``)."""
    r = np.asarray(dcm, dtype=float)
    phi = math.asin(min(1.0, max(-1.0, r[1, 2])))
    theta = math.atan2(-r[0, 2], r[2, 2])
    psi = math.atan2(-r[1, 0], r[1, 1])
    return np.array([phi, theta, psi])


def body_rate_from_euler312(euler: ArrayLike, euler_rate: ArrayLike) -> np.ndarray:
    """Body rate w.r.t. the reference frame, body axes [rad/s], from 3-1-2 Euler rates.

    ``wx = phid c_th - psid s_th c_ph``, ``wy = thd + psid s_ph``,
    ``wz = phid s_th + psid c_th c_ph`` (derived: the inverse of (3)).
    """
    phi, theta, _ = (float(v) for v in euler)
    dphi, dth, dpsi = (float(v) for v in euler_rate)
    cp, sp, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    return np.array([dphi * ct - dpsi * st * cp, dth + dpsi * sp, dphi * st + dpsi * ct * cp])


def euler312_rates_from_body_rate(euler: ArrayLike, omega: ArrayLike) -> np.ndarray:
    """Euler rates ``[phi_dot, theta_dot, psi_dot]`` [rad/s] from the body rate, eq. (3).

    Singular at ``cos(phi) = 0``; the caller keeps ``|phi|`` away from 90 deg.
    """
    phi, theta, _ = (float(v) for v in euler)
    wx, wy, wz = (float(v) for v in omega)
    cp, sp, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    return np.array([wx * ct + wz * st,
                     (wx * st * sp + wy * cp - wz * ct * sp) / cp,
                     (-wx * st + wz * ct) / cp])                                          # (3)


def body_accel_from_euler312(euler: ArrayLike, euler_rate: ArrayLike,
                             euler_acc: ArrayLike) -> np.ndarray:
    """Time derivative of :func:`body_rate_from_euler312` [rad/s^2], body axes (derived)."""
    phi, theta, _ = (float(v) for v in euler)
    dphi, dth, dpsi = (float(v) for v in euler_rate)
    aphi, ath, apsi = (float(v) for v in euler_acc)
    cp, sp, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    return np.array([
        aphi * ct - dphi * dth * st - apsi * st * cp - dpsi * (dth * ct * cp - dphi * st * sp),
        ath + apsi * sp + dpsi * dphi * cp,
        aphi * st + dphi * dth * ct + apsi * ct * cp - dpsi * (dth * st * cp + dphi * ct * sp)])


# ------------------------------------------------------------------ the boundary (F1), (F2)
def paper_state_from_project(q_orbit_body: ArrayLike,
                             omega_body_orbit_body: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """THE conversion from the project's frames to the paper's, (F1)-(F2): ``q_orbit_body``
    (4,) and ``omega_body_orbit_body`` (3,) [rad/s, body axes] -> ``(c_bo (3, 3), the paper's
    R_o2b: v_body = c_bo v_lvlh; omega_bo_body (3,) [rad/s], equal to the input)``."""
    c_bo = att.to_matrix(q_orbit_body).T @ D_ORBIT_LVLH                                  # (F1)
    return c_bo, np.array(omega_body_orbit_body, dtype=float)                            # (F2)


def project_state_from_paper(c_bo: ArrayLike,
                             omega_bo_body: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`paper_state_from_project`: ``(q_orbit_body, omega_body_orbit_body)``."""
    r_orbit_body = D_ORBIT_LVLH @ np.asarray(c_bo, dtype=float).T                        # (F1)
    return att.from_matrix(r_orbit_body), np.array(omega_bo_body, dtype=float)


def lvlh_euler312_of(q_orbit_body: ArrayLike) -> np.ndarray:
    """The paper's 3-1-2 Euler angles [rad] (w.r.t. LVLH) of a project attitude."""
    return dcm_to_euler312(paper_state_from_project(q_orbit_body, np.zeros(3))[0])


def q_orbit_body_of_lvlh_euler312(euler: ArrayLike) -> np.ndarray:
    """Project attitude ``q_orbit_body`` of the paper's 3-1-2 Euler angles [rad] w.r.t. LVLH."""
    return project_state_from_paper(euler312_to_dcm(euler), np.zeros(3))[0]


# ------------------------------------------------------------------ model (8)-(16)
def _inertia_parts(inertia_t: np.ndarray) -> tuple:
    """``Ix, Iy, Iz, Ixy, Ixz, Iyz`` of (2) (products with the minus-sign convention)."""
    return (inertia_t[0, 0], inertia_t[1, 1], inertia_t[2, 2],
            -inertia_t[0, 1], -inertia_t[0, 2], -inertia_t[1, 2])


def model(inertia_t: np.ndarray, h_t: np.ndarray, omega0: float) -> np.ndarray:
    """State matrix ``A`` (6, 6) of (10) with ``A1`` (13) and ``A2`` (14): ``inertia_t``
    (3, 3) [kg m^2] (2) and wheel momentum ``h_t`` (3,) [N m s] (7), temporary axes; orbit
    rate ``omega0`` [rad/s]."""
    ix, iy, iz, ixy, ixz, iyz = _inertia_parts(inertia_t)
    hx, hy, hz = h_t
    w0 = omega0
    a1 = np.array([[w0 * w0 * (iz - iy) + w0 * hy, 0.0, w0 * w0 * ixz],
                   [-w0 * w0 * ixy - w0 * hx, 0.0, -w0 * w0 * iyz - w0 * hz],
                   [w0 * w0 * ixz, 0.0, w0 * w0 * (ix - iy) + w0 * hy]])                   # (13)
    a2 = np.array([[0.0, -2.0 * w0 * iyz - hz, hy - w0 * (iy - ix - iz)],
                   [2.0 * w0 * iyz + hz, 0.0, -(2.0 * w0 * ixy + hx)],
                   [w0 * (iy - ix - iz) - hy, 2.0 * w0 * ixy + hx, 0.0]])                  # (14)
    inv = np.linalg.inv(inertia_t)
    a = np.zeros((6, 6))
    a[:3, 3:] = E3
    a[3:, :3] = inv @ a1
    a[3:, 3:] = inv @ a2                                                                  # (10)
    return a


def feedforward(x: np.ndarray, inertia_t: np.ndarray, h_t: np.ndarray, omega0: float,
                literal_model: bool = False) -> np.ndarray:
    """``K1 v1 + K2 v2 (+ c)`` of (12)/(27) [N m], temporary axes, at the state ``x``.

    ``c = [w0 hz, 0, -w0 hx]`` (derived, digest P2) is left out when ``literal_model``.
    """
    ix, iy, iz, ixy, ixz, iyz = _inertia_parts(inertia_t)
    phi, _, psi, dphi, dth, dpsi = x
    w0 = omega0
    p = dphi - w0 * psi
    r = dpsi + w0 * phi
    k1 = np.array([[0.0, r * dth, 0.0], [0.0, 0.0, r * p], [p * dth, 0.0, 0.0]])          # (15)
    k2 = np.array([[-p * r, dth * p, dth * dth + w0 * w0 - r * r],
                   [dth * r, r * r - p * p, -dth * p],
                   [p * p - dth * dth - w0 * w0, -dth * r, p * r]])                        # (16)
    out = k1 @ np.array([ix - iy, iy - iz, iz - ix]) + k2 @ np.array([ixy, ixz, iyz])
    if not literal_model:
        out = out + np.array([w0 * h_t[2], 0.0, -w0 * h_t[0]])                            # c
    return out


def transition(a: np.ndarray, tau: float, order: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Power-series ``Phi`` (6, 6) (19) and ``Q`` (6, 3) (20)-(21), truncated after
    ``tau^order``."""
    n = a.shape[0]
    phi = np.eye(n)
    integral = np.zeros((n, n))
    term = np.eye(n)                 # A^(k-1) tau^(k-1) / (k-1)!
    for k in range(1, order + 1):
        integral = integral + term * (tau / k)                                            # (21)
        term = term @ a * (tau / k)
        phi = phi + term                                                                  # (19)
    return phi, integral @ B_MATRIX                                                       # (20)


def transition_exact(a: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ``Phi = expm(A tau)`` and ``Q`` from the augmented matrix (Van Loan)."""
    from scipy.linalg import expm
    aug = np.zeros((9, 9))
    aug[:6, :6] = a
    aug[:6, 6:] = B_MATRIX
    m = expm(aug * tau)
    return m[:6, :6], m[:6, 6:]


def solve_u(q: np.ndarray, dx: np.ndarray, rcond: float = 1e-12) -> Optional[np.ndarray]:
    """``u = Q^+ dx`` (26), or None when ``Q`` lacks full column rank or is not finite."""
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dx))):
        return None
    s = np.linalg.svd(q, compute_uv=False)
    if s[0] <= 0.0 or s[-1] <= rcond * s[0]:
        return None
    u = np.linalg.lstsq(q, dx, rcond=None)[0]                                            # (25)
    return u if np.all(np.isfinite(u)) else None


def wheel_momentum_rate(u: np.ndarray, x: np.ndarray, inertia_t: np.ndarray, h_t: np.ndarray,
                        omega0: float, literal_model: bool = False) -> np.ndarray:
    """Inversion (27): ``h_dot = -I u + K1 v1 + K2 v2 (+ c)`` [N m], temporary axes."""
    return -inertia_t @ u + feedforward(x, inertia_t, h_t, omega0, literal_model)          # (27)


def error_state(c_or: np.ndarray, omega_r: np.ndarray, c_of: np.ndarray,
                omega_f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Temporary-frame state ``x`` and desired state ``x*`` (6,) (eqs. (1)-(4)) of the current
    and desired passive DCMs from LVLH ``c_or``, ``c_of`` (3, 3) and body rates w.r.t. LVLH
    ``omega_r``, ``omega_f`` (3,) [rad/s], each in its body axes."""
    e = dcm_to_euler312(c_of.T @ c_or)                                      # R_t, (q_o2r q_o2f^-1)
    de = euler312_rates_from_body_rate(e, c_of.T @ omega_r)                             # (3), (4)
    return np.concatenate([e, de]), np.concatenate([np.zeros(3), c_of.T @ omega_f])


# ------------------------------------------------------------------ the controller
class MPIController:
    """Paper 001's MPI law with reaction wheels (module docstring).

    ``inertia_kgm2`` (3, 3) [kg m^2] the controller's own, body axes (paper (31): 5 % off);
    ``wheel_axes_body`` (n, 3) spanning 3-D; ``wheel_max_torque_Nm``,
    ``wheel_max_momentum_Nms`` (n,) (``inf`` momentum: none); ``period_s`` [s] the control
    period (the horizon when stabilising or tracking, 5.2); ``series_order`` N of (19), (21)
    (the paper's 5); ``literal_model`` drops the derived ``c`` as the paper does;
    ``min_horizon_s`` [s] the horizon floor in a maneuver (ASSUMPTION; 0: one period);
    ``hold_horizon_s`` [s] the horizon when holding (0: one period, the paper's; DEPARTURE
    when > 0, digest P14); ``saturation`` ``'scale'`` (one factor) or ``'clip'`` (per wheel);
    ``reference_time`` ``'t0'`` (the paper, P15) or ``'t0_plus_tau'`` (DEPARTURE: no lag);
    ``exact_transition``: ``expm`` instead of the series (digest P6). ``ValueError`` on a bad
    inertia, wheel geometry, limit, period or option.
    """

    SATURATION = SATURATION
    REFERENCE_TIME = ('t0', 't0_plus_tau')

    def __init__(self, inertia_kgm2: ArrayLike, wheel_axes_body: ArrayLike,
                 wheel_max_torque_Nm: ArrayLike, wheel_max_momentum_Nms: ArrayLike,
                 period_s: float, series_order: int = 5, literal_model: bool = False,
                 min_horizon_s: float = 0.0, hold_horizon_s: float = 0.0,
                 saturation: str = 'scale',
                 reference_time: str = 't0', exact_transition: bool = False) -> None:
        inertia = finite_vector(inertia_kgm2, 'inertia_kgm2', (3, 3))
        if np.max(np.abs(inertia - inertia.T)) > 1e-9 * np.max(np.abs(inertia)) or \
                np.linalg.eigvalsh(0.5 * (inertia + inertia.T))[0] <= 0.0:
            raise ValueError(f'inertia_kgm2 must be symmetric positive definite, got '
                             f'{inertia.tolist()}')
        self.inertia = 0.5 * (inertia + inertia.T)
        self.period = positive(period_s, 'period_s', 's')
        if isinstance(series_order, bool) or not isinstance(series_order, (int, np.integer)) \
                or not 1 <= series_order <= 30:
            raise ValueError(f'series_order must be an integer in [1, 30], got {series_order!r}')
        self.order = int(series_order)
        self.literal = bool(literal_model)
        self.min_horizon = positive(min_horizon_s, 'min_horizon_s', 's', zero=True) or self.period
        self.hold_horizon = positive(hold_horizon_s, 'hold_horizon_s', 's', zero=True) \
            or self.period
        if saturation not in self.SATURATION:
            raise ValueError(f'saturation must be one of {self.SATURATION}, got {saturation!r}')
        if reference_time not in self.REFERENCE_TIME:
            raise ValueError(f'reference_time must be one of {self.REFERENCE_TIME}, got '
                             f'{reference_time!r}')
        self.saturation = saturation
        self.reference_time = reference_time
        self.exact = bool(exact_transition)
        # (A1)-(A4) of core/control/wheel_allocation.py: A_w^+ h_dot_b, the torque limit of
        # ``saturation`` and the momentum headroom over one control period.
        self.wheels = WheelAllocator(wheel_axes_body, wheel_max_torque_Nm, saturation,
                                     max_momentum_Nms=wheel_max_momentum_Nms,
                                     period_s=self.period)
        self.a_w = self.wheels.A_w                                                   # (3, n)

    @property
    def n_wheels(self) -> int:
        """Number of wheels."""
        return self.a_w.shape[1]

    def reset(self) -> None:
        """No internal state (the law is memoryless)."""

    # ------------------------------------------------------------------ pieces
    def horizon(self, target: Target) -> float:
        """``tau`` [s]: time left in a maneuver (floored), else one control period (5.1, 5.2)."""
        ttg = float(target.time_to_go_s)
        if math.isfinite(ttg) and ttg > 0.0:
            return max(ttg, self.min_horizon)
        return self.hold_horizon

    def update(self, inputs: ControlInputs, t: float, dt: float) -> Command:
        """Wheel torques for frame time ``t`` [s] (see the module docstring).

        Never raises on bad data: an unusable estimate or target, or a singular ``Q`` twice,
        give a zero command with ``reason``.
        """
        n = self.n_wheels
        est = inputs.estimate
        if est is None or not est.is_usable():
            return Command.zero(n, 'no usable estimate')
        target = inputs.target if inputs.target is not None else Target()
        try:
            tgt = target.in_frame('orbit', est)
            q_ref = att.normalize(tgt.q_ref_body)
            w_ref = finite_vector(tgt.omega_body_ref_body, 'omega_body_ref_body', (3,))
            wd_ref = finite_vector(tgt.omega_dot_body_ref_body, 'omega_dot_body_ref_body', (3,))
        except ValueError as exc:
            return Command.zero(n, f'unusable target: {exc}')
        q_ob = att.normalize(est.q_orbit_body)
        omega0 = float(est.omega0)
        r_ob = att.to_matrix(q_ob)
        orbit_rate = np.array([0.0, omega0, 0.0])
        w_bo = np.asarray(est.omega_body_eci_body, dtype=float) - r_ob.T @ orbit_rate    # (F2)
        if target.frame == 'eci':    # an inertial target's rate: relative to ECI -> to orbit
            w_ref = w_ref - att.to_matrix(q_ref).T @ orbit_rate
        reason = ''
        h_w = inputs.wheel_momentum_Nms
        h_w = None if h_w is None else np.asarray(h_w, dtype=float)
        if h_w is None or h_w.shape != (n,) or not np.all(np.isfinite(h_w)):
            h_w = np.zeros(n)
            reason = 'no valid wheel momentum: h taken as 0'
        tau = self.horizon(tgt)
        maneuver = math.isfinite(float(tgt.time_to_go_s)) and float(tgt.time_to_go_s) > 0.0
        if self.reference_time == 't0_plus_tau' and not maneuver:   # a maneuver's is at t_f
            q_ref = att.normalize(att.multiply(
                q_ref, att.from_rotation_vector(w_ref * tau + 0.5 * wd_ref * tau * tau)))
            w_ref = w_ref + wd_ref * tau
        c_or, w_r = paper_state_from_project(q_ob, w_bo)                                  # (F1)
        c_of, w_f = paper_state_from_project(q_ref, w_ref)
        c_err = c_of.T @ c_or
        if abs(c_err[1, 2]) > 0.999:
            return Command.zero(n, 'attitude error at the 3-1-2 Euler singularity '
                                '(|roll error| near 90 deg): no MPI command')
        x, x_star = error_state(c_or, w_r, c_of, w_f)
        inertia_t = c_of.T @ self.inertia @ c_of                                          # (2)
        h_t = c_of.T @ (self.a_w @ h_w)                                                   # (7)
        a = model(inertia_t, h_t, omega0)
        u = None
        for horizon in (tau, self.period):
            phi, q = (transition_exact(a, horizon) if self.exact
                      else transition(a, horizon, self.order))
            u = solve_u(q, x_star - phi @ x)                                        # (22)-(26)
            if u is not None:
                if horizon != tau:
                    reason = (f'singular Q at horizon {tau:g} s: used one control period '
                              f'{self.period:g} s')
                tau = horizon
                break
        if u is None:
            return Command.zero(n, f'singular Q at horizon {tau:g} s and at one control '
                                'period: zero command')
        h_dot = wheel_momentum_rate(u, x, inertia_t, h_t, omega0, self.literal)           # (27)
        h_dot_b = c_of @ h_dot                                                            # (28)
        if not np.all(np.isfinite(h_dot_b)):
            return Command.zero(n, 'non-finite wheel torque demand: zero command')
        out, dipole, sigma, tau_w, refusal = self.wheels.allocate_healthy(      # (A1)-(A5)
            h_dot_b, h_w, inputs.wheel_ok, inputs.field_body(), inputs.backup_dipole_Am2)
        if refusal:
            return Command.zero(n, refusal, refused=True)
        info = {'horizon_s': tau, 'x': x, 'x_star': x_star, 'u': u,
                'h_dot_body_demand': h_dot_b, 'sigma': sigma,
                'saturated': bool(np.any(np.abs(out - tau_w) > 1e-12))}
        return Command(dipole, out, np.zeros(3), reason, info)
