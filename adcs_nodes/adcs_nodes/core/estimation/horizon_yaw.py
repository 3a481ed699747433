"""Yaw from an Earth (horizon) sensor and a magnetometer, paper 004 (Ryzhkov, Holembiovskyi 2022).

The horizon sensor gives roll ``phi`` and pitch ``theta`` of the body w.r.t. the orbit frame
(x along-track, y orbit normal, z zenith); the magnetometer gives the field in body axes
``a = (a_x, a_y, a_z)``; the onboard model gives it in orbit axes ``a0 = (a_x0, a_y0, a_z0)``.

Equations (paper 004 numbers)
-----------------------------
3-2-1 Euler angles (yaw ``psi`` about z0, pitch about the new y, roll about the new x),
``a = C a0`` with ``C = R1(phi) R2(theta) R3(psi) = R(q_orbit_body)^T``::

    a_x = a_x0 cpsi ctheta + a_y0 spsi ctheta - a_z0 stheta                               (1)
    a_y = a_x0 (-spsi cphi + cpsi sphi stheta) + a_y0 (cpsi cphi + spsi sphi stheta)
          + a_z0 ctheta sphi
    a_z = a_x0 (spsi sphi + cpsi cphi stheta) + a_y0 (-cpsi sphi + spsi cphi stheta)
          + a_z0 ctheta cphi

The zenith z0 seen in body axes (what the horizon sensor measures) is column 3 of ``C``::

    z_body = (-stheta, ctheta sphi, ctheta cphi)                                          (H1)

Yaw, paper formula (3), with ``mu1 = a_x + a_z0 stheta``, ``mu2 = a_z sphi - a_y cphi``::

    sin psi = (mu2 a_x0 ctheta + mu1 a_y0) / (ctheta (a_x0^2 + a_y0^2))                   (3)

The paper normalises every field component by ``lambda = M / r^3`` (its second form); any
common scale cancels, so this module uses tesla throughout (dividing by ``|a0|`` only for the
conditioning number). From (1), exactly (the ``a_z0`` terms cancel; digest section 4)::

    mu1 = ctheta (a_x0 cpsi + a_y0 spsi),   mu2 = a_x0 spsi - a_y0 cpsi                   (Y1)

so besides (3) (digest section 4, not printed in the paper)::

    cos psi = (mu1 a_x0 - mu2 a_y0 ctheta) / (ctheta (a_x0^2 + a_y0^2))                   (Y2)
    psi = atan2(sin psi, cos psi)   in (-pi, pi]                                          (Y3)

(Y3) is the default: the paper's ``psi = arcsin(sin psi)`` only recovers ``|psi| <= 90 deg``
and is kept as ``method='asin'``.

Degradation: the denominator vanishes when the model field is vertical or at ``theta =
+-90 deg``; for the direct dipole (paper 004 (2)), ``a_x0^2 + a_y0^2 = lambda^2 (cos^2 u
sin^2 i + cos^2 i)``, small in near-polar orbits near ``u = 90, 270 deg``, where TRIAD on the
vertical and the field degrades too. :func:`yaw_conditioning` returns::

    kappa = |ctheta| (a_x0^2 + a_y0^2) / |a0|^2   in [0, 1]                               (Y4)

and :func:`yaw_from_horizon_and_field` raises ``ValueError`` below a threshold.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude
from adcs_nodes.core.control import finite
from adcs_nodes.core.estimation.triad import MIN_SIN_ANGLE, triad

MIN_YAW_CONDITIONING = 1e-6
"""Default smallest ``kappa`` (Y4) accepted by :func:`yaw_from_horizon_and_field`."""


def zenith_body(roll: float, pitch: float) -> np.ndarray:
    """Unit zenith ``z_body`` (3,), body axes, of the 3-2-1 ``roll``, ``pitch`` [rad] of the
    body w.r.t. the orbit frame (H1)."""
    phi, theta = finite(roll, 'roll'), finite(pitch, 'pitch')
    return np.array([-math.sin(theta), math.cos(theta) * math.sin(phi),
                     math.cos(theta) * math.cos(phi)])  # (H1)


def yaw_conditioning(pitch: float, b_orbit: ArrayLike) -> float:
    """``kappa`` (Y4) in [0, 1] of ``pitch`` [rad] and the model field ``b_orbit`` (3,) [T],
    orbit axes; 0: yaw is unobservable."""
    a0 = attitude.as_vec3(b_orbit, 'b_orbit')
    n2 = float(a0 @ a0)
    if n2 == 0.0:
        return 0.0
    return abs(math.cos(finite(pitch, 'pitch'))) * float(a0[0] ** 2 + a0[1] ** 2) / n2


def yaw_from_horizon_and_field(roll: float, pitch: float, b_body: ArrayLike, b_orbit: ArrayLike,
                               method: str = 'atan2',
                               min_conditioning: float = MIN_YAW_CONDITIONING) -> float:
    """Yaw ``psi`` [rad], paper 004 formula (3), of the horizon sensor's 3-2-1 ``roll`` and
    ``pitch`` [rad], the reading ``b_body`` (3,) [T] in body axes and the model field
    ``b_orbit`` (3,) [T] in orbit axes.

    ``method`` 'atan2' (default): (3) with (Y2), yaw in (-pi, pi] (Y3); 'asin': the paper's
    literal ``arcsin`` of (3), valid only for ``|yaw| <= pi/2``. ``ValueError`` on non-finite
    input, an unknown method, or ``kappa`` (Y4) below ``min_conditioning``.
    """
    if method not in ('atan2', 'asin'):
        raise ValueError(f"method must be 'atan2' or 'asin', got {method!r}")
    phi, theta = finite(roll, 'roll'), finite(pitch, 'pitch')
    a, a0 = attitude.as_vec3(b_body, 'b_body'), attitude.as_vec3(b_orbit, 'b_orbit')
    kappa = yaw_conditioning(theta, a0)
    if kappa < min_conditioning:
        raise ValueError(f'yaw is unobservable: conditioning {kappa:.3g} < {min_conditioning:.3g}'
                         ' (model field nearly vertical or pitch near +-90 deg)')
    scale = 1.0 / math.sqrt(float(a0 @ a0))  # common scale: the paper's 1 / lambda
    ax, ay, az = a * scale
    ax0, ay0, az0 = a0 * scale
    st, ct, sp, cp = math.sin(theta), math.cos(theta), math.sin(phi), math.cos(phi)
    mu1 = ax + az0 * st
    mu2 = az * sp - ay * cp
    den = ct * (ax0 * ax0 + ay0 * ay0)
    s_num = mu2 * ax0 * ct + mu1 * ay0  # (3) numerator
    if method == 'asin':
        return math.asin(min(1.0, max(-1.0, s_num / den)))  # (3), paper: psi = arcsin
    c_num = mu1 * ax0 - mu2 * ay0 * ct  # (Y2) numerator
    sgn = 1.0 if den > 0.0 else -1.0
    return math.atan2(sgn * s_num, sgn * c_num)  # (Y3)


def attitude_from_horizon_and_yaw(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``q_orbit_body`` (4,), scalar last, of the 3-2-1 angles [rad] of paper 004 (1):
    ``R(q)^T = C = R1(roll) R2(pitch) R3(yaw)`` (orbit -> body)."""
    return attitude.from_euler_321(finite(roll, 'roll'), finite(pitch, 'pitch'),
                                   finite(yaw, 'yaw'))


def triad_from_horizon_and_field(roll: float, pitch: float, b_body: ArrayLike,
                                 b_orbit: ArrayLike,
                                 min_sin_angle: float = MIN_SIN_ANGLE) -> np.ndarray:
    """TRIAD ``q_orbit_body`` (4,), ``w >= 0``, from the horizon-sensor zenith (anchor, H1)
    of ``roll``, ``pitch`` [rad] and the field: ``b_body`` (3,) [T] body axes, ``b_orbit``
    (3,) [T] orbit axes. ``ValueError`` on non-finite or zero input or when the sine of the
    angle between zenith and field is below ``min_sin_angle``."""
    return triad(zenith_body(roll, pitch), b_body, np.array([0.0, 0.0, 1.0]), b_orbit,
                 min_sin_angle)
