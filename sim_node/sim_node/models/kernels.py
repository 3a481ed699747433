"""Compiled world kernels: one frame of rigid body + wheels + orbit in fixed-step RK4 (numba).

Equations
---------
The kernel integrates (E1)-(E3), (E6) of :mod:`sim_node.models.dynamics` with the torques of
(E4) and the field of (E7), ``s = t - t_k`` the time since the frame start::

    dq_eci_body/dt = 1/2 q_eci_body (x) [omega, 0]                                       (E1)
    I domega/dt    = -omega x (I omega + A h_w) + tau_gg + m x b_body + tau_held         (E2)
    dh_w/dt        = tau_w                                                               (E3)
    (E2) with flexible appendages (paper 001 Sec. 6; ``sim_node.models.flexible`` (H1)-(H2)):
    I domega/dt + F eta_ddot = -omega x (I omega + F eta_dot + A h_w) + tau_gg + ...     (E2f)
    eta_ddot + 2 zeta Lambda eta_dot + Lambda^2 eta + F^T domega/dt = 0                  (E9)
    tau_gg         = 3 mu / |r|^5  r_body x (I r_body),   r_body = R(q)^T r_eci          (D1)
    dr_eci/dt = v_eci,   dv_eci/dt = -mu r_eci / |r_eci|^3                               (E6)
    b_eci(t_k + s) = c0 + c1 s + c2 s^2 + c3 s^3                                         (E7)
    c2 = (2 b_dot_k + b_dot_p) / tau - 3 D / tau^2,  c3 = (b_dot_k + b_dot_p) / tau^2 - 2 D / tau^3
        (E8: cubic Hermite through (b_p, b_dot_p) at -tau and (b_k, b_dot_k) at 0, D = b_k - b_p)
    m = clip(m_cmd, -m_max, m_max)                                                       (A2)
    tau_w = clip(clip(tau_cmd, -tau_max, tau_max), lower, upper)                         (W4)
    upper = max((h_max - h_w) / dt, 0),   lower = min((-h_max - h_w) / dt, 0)

    tau_w <- clip(tau_w + delta_tau_w, max(lower, -tau_max), min(upper, tau_max))      (W5)
        (the momentum control error, inside the torque and momentum limits: the torque stops
        at the momentum limit as hardware does)

(D1), (A2), (W4) are ``disturbances`` and ``actuators``' equations; ``tau_held = tau_ideal -
A tau_w + tau_dist`` is held over a substep (disturbance sampled at its midpoint). (E2f), (E9)
use the inverse of the constant mass matrix ``M = [[I, F], [F^T, E_m]]`` (``mass_inv``); with
no modes it is ``I^-1`` and the arithmetic is the rigid one, operation for operation.

State: one float64 array ``x`` of :func:`state_size` entries, a named slice per part::

    x[Q]  q_eci_body (4, scalar last)        x[W]  omega_body_eci_body [rad/s] (3)
    x[R]  r_eci [m] (3)                      x[V]  v_eci [m/s] (3)
    x[H0:H0 + n_wheels]  h_wheels [N m s]
    x[H0 + n : H0 + n + m]          eta, modal coordinates [kg^1/2 m] (paper 001 (32) units)
    x[H0 + n + m : H0 + n + 2 m]    eta_dot [kg^1/2 m / s]

A new part is the next slice (grow :func:`state_size`, fill it in
``Spacecraft._frame_inputs``, its equations in :func:`rhs`; :func:`frame_step` integrates the
whole array). Plain Python compiled by ``numba.njit(cache=True)`` at the first call
(:func:`adcs_nodes.core.kernels.jit`; no fastmath); with ``NUMBA_DISABLE_JIT=1`` the same
functions run as Python (``test_kernels.py``).
"""
from __future__ import annotations

import math

import numpy as np

from adcs_nodes.core.kernels import jit

#: Slices of the kernel state (see module docstring).
Q = slice(0, 4)
W = slice(4, 7)
R = slice(7, 10)
V = slice(10, 13)
#: First wheel momentum entry; wheels occupy ``H0 : H0 + n_wheels``.
H0 = 13


def state_size(n_wheels: int, n_modes: int = 0) -> int:
    """Length of the kernel state for ``n_wheels`` wheels and ``n_modes`` flexible modes."""
    return H0 + int(n_wheels) + 2 * int(n_modes)


def modal_slices(n_wheels: int, n_modes: int) -> tuple[slice, slice]:
    """Slices of ``eta`` and ``eta_dot`` in the kernel state (after the wheels)."""
    e0 = H0 + int(n_wheels)
    m = int(n_modes)
    return slice(e0, e0 + m), slice(e0 + m, e0 + 2 * m)


@jit(loads_numba=True)
def external_torques(s, x, inertia, mu, use_gg, use_mtq, dipole, b_coef, out):
    """Gravity-gradient (D1) and magnetic (A1) torques [N m], body axes, at ``t_k + s`` [s],
    written to ``out`` (6,) (``tau_gg_body``, ``tau_magnetic_body``; zero when ``use_gg``,
    ``use_mtq`` are off). ``x`` the kernel state, ``inertia`` (3, 3) [kg m^2], ``mu``
    [m^3/s^2], ``dipole`` (3,) [A m^2], ``b_coef`` (4, 3) the field polynomial (E7) [T/s^j],
    ECI."""
    qx, qy, qz, qw = x[0], x[1], x[2], x[3]
    # R(q / |q|)^T: ECI components to body components
    k = 2.0 / (qx * qx + qy * qy + qz * qz + qw * qw)
    c00 = 1.0 - k * (qy * qy + qz * qz)
    c01 = k * (qx * qy + qz * qw)
    c02 = k * (qx * qz - qy * qw)
    c10 = k * (qx * qy - qz * qw)
    c11 = 1.0 - k * (qx * qx + qz * qz)
    c12 = k * (qy * qz + qx * qw)
    c20 = k * (qx * qz + qy * qw)
    c21 = k * (qy * qz - qx * qw)
    c22 = 1.0 - k * (qx * qx + qy * qy)
    for i in range(6):
        out[i] = 0.0
    if use_gg:
        rx, ry, rz = x[7], x[8], x[9]
        bx = c00 * rx + c01 * ry + c02 * rz
        by = c10 * rx + c11 * ry + c12 * rz
        bz = c20 * rx + c21 * ry + c22 * rz
        r2 = bx * bx + by * by + bz * bz
        kg = 3.0 * mu / (r2 * r2 * math.sqrt(r2))            # (D1) with r unnormalised
        ix = inertia[0, 0] * bx + inertia[0, 1] * by + inertia[0, 2] * bz
        iy = inertia[1, 0] * bx + inertia[1, 1] * by + inertia[1, 2] * bz
        iz = inertia[2, 0] * bx + inertia[2, 1] * by + inertia[2, 2] * bz
        out[0] = kg * (by * iz - bz * iy)
        out[1] = kg * (bz * ix - bx * iz)
        out[2] = kg * (bx * iy - by * ix)
    if use_mtq:
        ex = b_coef[0, 0] + s * (b_coef[1, 0] + s * (b_coef[2, 0] + s * b_coef[3, 0]))  # (E7)
        ey = b_coef[0, 1] + s * (b_coef[1, 1] + s * (b_coef[2, 1] + s * b_coef[3, 1]))
        ez = b_coef[0, 2] + s * (b_coef[1, 2] + s * (b_coef[2, 2] + s * b_coef[3, 2]))
        bx = c00 * ex + c01 * ey + c02 * ez
        by = c10 * ex + c11 * ey + c12 * ez
        bz = c20 * ex + c21 * ey + c22 * ez
        out[3] = dipole[1] * bz - dipole[2] * by                 # (A1)
        out[4] = dipole[2] * bx - dipole[0] * bz
        out[5] = dipole[0] * by - dipole[1] * bx


@jit(loads_numba=True)
def rhs(s, x, inertia, mass_inv, axes, coupling, modal_c, modal_k, mu, use_gg, use_mtq, dipole,
        b_coef, tau_held, tau_w, work, xdot):
    """Right-hand side (E1)-(E3), (E2f), (E6), (E9) at ``t_k + s``; writes ``xdot`` (N,).

    ``mass_inv`` (3 + m, 3 + m) is the inverse mass matrix ``[[I, F], [F^T, E]]^-1`` (``I^-1``
    without modes), ``axes`` (3, n) the wheel spin axes (columns), ``coupling`` (3, m) the
    modal coupling ``F`` [kg^1/2 m], ``modal_c`` = ``2 zeta Lambda`` [1/s] and ``modal_k`` =
    ``Lambda^2`` [1/s^2] (m,), ``tau_held`` (3,) [N m] the torques held over the substep,
    ``tau_w`` (n,) [N m] the motor torques, ``work`` (9 + m,) scratch; the other arguments as
    in :func:`external_torques`.
    """
    external_torques(s, x, inertia, mu, use_gg, use_mtq, dipole, b_coef, work)
    tx = tau_held[0] + work[0] + work[3]
    ty = tau_held[1] + work[1] + work[4]
    tz = tau_held[2] + work[2] + work[5]
    qx, qy, qz, qw = x[0], x[1], x[2], x[3]
    wx, wy, wz = x[4], x[5], x[6]
    hx = inertia[0, 0] * wx + inertia[0, 1] * wy + inertia[0, 2] * wz
    hy = inertia[1, 0] * wx + inertia[1, 1] * wy + inertia[1, 2] * wz
    hz = inertia[2, 0] * wx + inertia[2, 1] * wy + inertia[2, 2] * wz
    n_wheels = axes.shape[1]
    for j in range(n_wheels):
        hw = x[H0 + j]
        hx += axes[0, j] * hw
        hy += axes[1, j] * hw
        hz += axes[2, j] * hw
        xdot[H0 + j] = tau_w[j]                                              # (E3)
    n_modes = coupling.shape[1]
    e0 = H0 + n_wheels
    d0 = e0 + n_modes
    for i in range(n_modes):
        eta_d = x[d0 + i]
        hx += coupling[0, i] * eta_d                                         # F eta_dot in h
        hy += coupling[1, i] * eta_d
        hz += coupling[2, i] * eta_d
        xdot[e0 + i] = eta_d
        work[9 + i] = -modal_c[i] * eta_d - modal_k[i] * x[e0 + i]          # (E9) rhs
    work[6] = tx - (wy * hz - wz * hy)                                      # (E2f) rhs
    work[7] = ty - (wz * hx - wx * hz)
    work[8] = tz - (wx * hy - wy * hx)
    xdot[0] = 0.5 * (qw * wx + qy * wz - qz * wy)                           # (E1)
    xdot[1] = 0.5 * (qw * wy + qz * wx - qx * wz)
    xdot[2] = 0.5 * (qw * wz + qx * wy - qy * wx)
    xdot[3] = -0.5 * (qx * wx + qy * wy + qz * wz)
    n_acc = 3 + n_modes
    for r in range(n_acc):            # [domega/dt; eta_ddot] = M^-1 rhs  (E2), (E2f), (E9)
        acc = 0.0
        for c in range(n_acc):
            acc += mass_inv[r, c] * work[6 + c]
        if r < 3:
            xdot[4 + r] = acc
        else:
            xdot[d0 + r - 3] = acc
    rx, ry, rz = x[7], x[8], x[9]
    r2 = rx * rx + ry * ry + rz * rz
    ko = -mu / (r2 * math.sqrt(r2)) if r2 > 0.0 else 0.0                     # (E6)
    xdot[7] = x[10]
    xdot[8] = x[11]
    xdot[9] = x[12]
    xdot[10] = ko * rx
    xdot[11] = ko * ry
    xdot[12] = ko * rz


@jit(loads_numba=True)
def saturate(dt, dipole_cmd, dipole_max, wheel_cmd, wheel_max_torque, wheel_max_momentum,
             h_wheels):
    """Applied dipole (A2) [A m^2] (3,) and wheel torque (W4) [N m] (n,) of a command held
    for ``dt`` [s] from wheel momenta ``h_wheels`` (n,) [N m s]; limits ``>= 0`` (``inf``:
    none; a zero dipole limit means no magnetorquer)."""
    dipole = np.empty(3)
    for i in range(3):
        lim = dipole_max[i]
        dipole[i] = min(max(dipole_cmd[i], -lim), lim)
    n = wheel_cmd.shape[0]
    tau_w = np.empty(n)
    for j in range(n):
        lim = wheel_max_torque[j]
        tau = min(max(wheel_cmd[j], -lim), lim)
        upper = max((wheel_max_momentum[j] - h_wheels[j]) / dt, 0.0)
        lower = min((-wheel_max_momentum[j] - h_wheels[j]) / dt, 0.0)
        tau_w[j] = min(max(tau, lower), upper)
    return dipole, tau_w


@jit(loads_numba=True)
def hermite_terms(b_prev, b_dot_prev, b, b_dot, tau, out):
    """Coefficients ``c2``, ``c3`` of (E7) from the cubic Hermite polynomial (E8) through
    ``(b_prev, b_dot_prev)`` at ``-tau`` and ``(b, b_dot)`` at 0 (ECI, (3,) each, [T], [T/s]),
    ``tau > 0`` [s]; written to ``out[0]``, ``out[1]`` (rows of shape (3,))."""
    tau2 = tau * tau
    for i in range(3):
        d = b[i] - b_prev[i]
        out[0, i] = (2.0 * b_dot[i] + b_dot_prev[i]) / tau - 3.0 * d / tau2
        out[1, i] = (b_dot[i] + b_dot_prev[i]) / tau2 - 2.0 * d / (tau2 * tau)


#: Layout of the ``applied`` output of :func:`frame_step` (body axes): applied dipole
#: [A m^2], gravity-gradient and magnetic torque at ``t_k`` [N m], wheels' reaction
#: ``-A tau_w`` [N m], then the applied motor torques (n) [N m], then the motor torques after
#: the limits (W4) but before the momentum control error (W5) (n) [N m].
OUT_DIPOLE = slice(0, 3)
OUT_GG = slice(3, 6)
OUT_MAG = slice(6, 9)
OUT_WHEELS_BODY = slice(9, 12)
OUT_TAU_W = 12


@jit(loads_numba=True)
def frame_step(x, dt, substeps, inertia, mass_inv, axes, coupling, modal_c, modal_k, mu,
               use_gg, dipole_max, wheel_max_torque, wheel_max_momentum, u, wheel_extra,
               tau_dist, b_coef, b_prev, tau_prev, applied):
    """One frame ``t_k -> t_k + dt``: saturate the command once, hold it, RK4 in ``substeps``.

    ``x`` (N,): the state at ``t_k`` (layout in the module docstring), overwritten with the
    state at ``t_k + dt``; ``dt`` [s] > 0; ``substeps`` >= 1 (the quaternion is renormalised
    first and after each). Body axes: ``inertia`` (3, 3) [kg m^2] (with modes ``I_b``),
    ``mass_inv`` (3 + m, 3 + m) ``[[I, F], [F^T, E_m]]^-1``, ``axes`` (3, n) the wheel spin
    axes, ``coupling`` ``F`` (3, m) [kg^1/2 m], ``modal_c``, ``modal_k`` (m,) ``2 zeta Lambda``
    [1/s] and ``Lambda^2`` [1/s^2] of (E9). ``mu`` [m^3/s^2]; ``use_gg``: (D1) on; limits
    ``dipole_max`` (3,) [A m^2], ``wheel_max_torque``, ``wheel_max_momentum`` (n,) [N m],
    [N m s]. ``u`` (6 + n,): requested dipole [A m^2], ideal torque [N m], motor torques [N m];
    ``wheel_extra`` (n,) [N m]: (W5); ``tau_dist`` (substeps, 3) [N m]. ``b_coef`` (4, 3)
    [T/s^j] ECI: (E7), rows 2, 3 replaced by (E8) from ``b_prev`` (2, 3) (field [T] and rate
    [T/s] at ``t_k - tau_prev``) if ``tau_prev`` [s] > 0. ``applied`` (12 + 2 n,) is written
    (see ``OUT_*``).
    """
    n_x = x.shape[0]
    n_wheels = axes.shape[1]
    n_modes = coupling.shape[1]
    coef = b_coef.copy()
    if tau_prev > 0.0:
        hermite_terms(b_prev[0], b_prev[1], coef[0], coef[1], tau_prev, coef[2:])
    norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
    for i in range(4):
        x[i] /= norm
    h_w = x[H0:H0 + n_wheels].copy()
    dipole, tau_w = saturate(dt, u[0:3], dipole_max, u[6:6 + n_wheels], wheel_max_torque,
                             wheel_max_momentum, h_w)
    for j in range(n_wheels):
        applied[OUT_TAU_W + n_wheels + j] = tau_w[j]          # after (W4), before (W5)
        if wheel_extra[j] != 0.0:            # (W5), then (W4) and the momentum limit again
            lim = wheel_max_torque[j]
            upper = min(max((wheel_max_momentum[j] - h_w[j]) / dt, 0.0), lim)
            lower = max(min((-wheel_max_momentum[j] - h_w[j]) / dt, 0.0), -lim)
            tau_w[j] = min(max(tau_w[j] + wheel_extra[j], lower), upper)
    use_mtq = dipole[0] != 0.0 or dipole[1] != 0.0 or dipole[2] != 0.0
    tau_fixed = np.empty(3)                 # ideal + wheels' reaction -A tau_w (W3)
    for i in range(3):
        acc = 0.0
        for j in range(n_wheels):
            acc += axes[i, j] * tau_w[j]
        applied[9 + i] = -acc
        tau_fixed[i] = u[3 + i] + -acc
        applied[i] = dipole[i]
    for j in range(n_wheels):
        applied[OUT_TAU_W + j] = tau_w[j]
    work = np.empty(9 + n_modes)
    external_torques(0.0, x, inertia, mu, use_gg, use_mtq, dipole, coef, work)
    for i in range(6):
        applied[3 + i] = work[i]

    h = dt / substeps
    half = 0.5 * h
    sixth = h / 6.0
    k1 = np.empty(n_x)
    k2 = np.empty(n_x)
    k3 = np.empty(n_x)
    k4 = np.empty(n_x)
    xt = np.empty(n_x)
    tau_held = np.empty(3)
    for i in range(substeps):
        s = i * h
        for c in range(3):
            tau_held[c] = tau_fixed[c] + tau_dist[i, c]
        rhs(s, x, inertia, mass_inv, axes, coupling, modal_c, modal_k, mu, use_gg, use_mtq,
            dipole, coef, tau_held, tau_w, work, k1)
        for j in range(n_x):
            xt[j] = x[j] + half * k1[j]
        rhs(s + half, xt, inertia, mass_inv, axes, coupling, modal_c, modal_k, mu, use_gg,
            use_mtq, dipole, coef, tau_held, tau_w, work, k2)
        for j in range(n_x):
            xt[j] = x[j] + half * k2[j]
        rhs(s + half, xt, inertia, mass_inv, axes, coupling, modal_c, modal_k, mu, use_gg,
            use_mtq, dipole, coef, tau_held, tau_w, work, k3)
        for j in range(n_x):
            xt[j] = x[j] + h * k3[j]
        rhs(s + h, xt, inertia, mass_inv, axes, coupling, modal_c, modal_k, mu, use_gg,
            use_mtq, dipole, coef, tau_held, tau_w, work, k4)
        for j in range(n_x):
            x[j] = x[j] + sixth * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
        norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
        for c in range(4):
            x[c] /= norm


@jit(loads_numba=True)
def propagate_two_body(r0, v0, dt, mu, steps):
    """Two-body orbit (E6) from ``r0`` [m], ``v0`` [m/s] (3,), ECI, over ``dt`` [s] (any
    sign) in ``steps`` RK4 steps; returns ``(r, v)``."""
    y = np.empty(6)
    for i in range(3):
        y[i] = r0[i]
        y[3 + i] = v0[i]
    h = dt / steps
    k = np.empty((4, 6))
    yt = np.empty(6)
    for _ in range(steps):
        for stage in range(4):
            if stage == 0:
                for i in range(6):
                    yt[i] = y[i]
            else:
                f = h if stage == 3 else 0.5 * h
                for i in range(6):
                    yt[i] = y[i] + f * k[stage - 1, i]
            r2 = yt[0] * yt[0] + yt[1] * yt[1] + yt[2] * yt[2]
            ko = -mu / (r2 * math.sqrt(r2)) if r2 > 0.0 else 0.0
            for i in range(3):
                k[stage, i] = yt[3 + i]
                k[stage, 3 + i] = ko * yt[i]
        for i in range(6):
            y[i] = y[i] + (h / 6.0) * (k[0, i] + 2.0 * (k[1, i] + k[2, i]) + k[3, i])
    return y[:3].copy(), y[3:].copy()
