"""Reference rest-to-rest eigenaxis slew: bang-bang rate profile with a PD end (pure numpy).

The comparison controller of paper 003 (digest ``papers/fuzzy-eigenaxis-slew.md``, section 10)
is not given by the paper; this is our stand-in (ASSUMPTION): a near time-optimal eigenaxis
slew under the same per-axis torque limit, as a rate-profile tracker.

Law (``phi``, ``e_phi`` from (6), (7); ``omega`` the body rate relative to the target)::

    a_max   = f_a min_i l_i / |(J e_phi)_i|        eigenaxis acceleration that fits the box
    w_prof  = min(sqrt(2 a_max phi), lambda phi, w_max)      bang-bang switching curve,
                                                             linear (PD) near the target
    omega_d = -w_prof e_phi
    M       = J k (omega_d - omega) + omega x J omega          rate tracking + gyroscopic
    M       <- M / max(1, max_i |M_i| / l_i)                   same limit as the fuzzy law

Below ``phi = 2 a / lambda^2`` it is the PD law ``M ~ -J k (lambda phi e + omega)``; ``f_a < 1``
leaves torque for the gyroscopic term. Defaults (ASSUMPTION): ``f_a = 0.9``, ``k = 2 1/s``,
``lambda = 0.5 1/s`` (within 1 % of the bang-bang time on the paper's case).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core.control import cross3, inertia_matrix, limits_vector, scale_to_limits
from adcs_nodes.core.control import eigenaxis as ea

__all__ = ['ReferenceSlewController']


class ReferenceSlewController(ea.EigenaxisTorqueLaw):
    """Near time-optimal eigenaxis slew (interface of :mod:`adcs_nodes.core.control`).

    ``inertia_kgm2`` (3, 3) or (3,) [kg m^2] body axes; ``max_torque_Nm`` per axis [N m];
    ``accel_fraction`` ``f_a`` in (0, 1]; ``rate_gain_per_s`` ``k``; ``linear_gain_per_s``
    ``lambda``; ``max_rate_deg_s`` ``w_max`` (``inf``: none); ``gyroscopic_compensation``:
    add ``omega x J omega`` (off: the classical law on the paper's assumption (10));
    ``wheel_axes_body``, ``wheel_max_torque_Nm`` as the fuzzy controller's.
    ``ValueError`` on a bad configuration.
    """

    def __init__(self, inertia_kgm2: ArrayLike, max_torque_Nm: ArrayLike = 1.0,
                 accel_fraction: float = 0.9, rate_gain_per_s: float = 2.0,
                 linear_gain_per_s: float = 0.5, max_rate_deg_s: float = math.inf,
                 gyroscopic_compensation: bool = True,
                 wheel_axes_body: Optional[ArrayLike] = None,
                 wheel_max_torque_Nm: Optional[ArrayLike] = None) -> None:
        self.J = inertia_matrix(inertia_kgm2)
        self.limit = limits_vector(max_torque_Nm, 'max_torque_Nm', 3, allow_zero=False,
                                   allow_inf=False)
        for name, v in (('accel_fraction', accel_fraction),
                        ('rate_gain_per_s', rate_gain_per_s),
                        ('linear_gain_per_s', linear_gain_per_s),
                        ('max_rate_deg_s', max_rate_deg_s)):
            if math.isnan(float(v)) or not float(v) > 0.0:
                raise ValueError(f'{name} must be > 0, got {v}')
        if float(accel_fraction) > 1.0 or math.isinf(float(rate_gain_per_s)) \
                or math.isinf(float(linear_gain_per_s)):
            raise ValueError('accel_fraction must be <= 1 and the gains finite')
        self.f_a = float(accel_fraction)
        self.k = float(rate_gain_per_s)
        self.lam = float(linear_gain_per_s)
        self.w_max = math.radians(float(max_rate_deg_s))
        self.gyro = bool(gyroscopic_compensation)
        self._set_wheels(wheel_axes_body, wheel_max_torque_Nm)
        self._axis: Optional[np.ndarray] = None

    def reset(self) -> None:
        """Forget the previous eigenaxis."""
        self._axis = None

    def law(self, q_target_body: ArrayLike, omega_rel_body: ArrayLike,
            omega_body_eci_body: Optional[ArrayLike] = None) -> dict:
        """Torque [N m] (body axes, within the box) and diagnostics for one error state.

        ``omega_body_eci_body`` (inertial rate, for the gyroscopic term) defaults to
        ``omega_rel_body``.
        """
        w = np.asarray(omega_rel_body, dtype=float)
        w_abs = w if omega_body_eci_body is None else np.asarray(omega_body_eci_body, float)
        phi, e = ea.eigen_from_quaternion(q_target_body, self._axis)
        if not np.any(e):
            e = np.array([1.0, 0.0, 0.0])
        self._axis = e
        je = np.abs(self.J @ e)
        with np.errstate(divide='ignore'):
            a_max = self.f_a * float(np.min(np.where(je > 0.0, self.limit / je, np.inf)))
        w_prof = min(math.sqrt(2.0 * a_max * phi), self.lam * phi, self.w_max)
        omega_d = -w_prof * e
        m = self.J @ (self.k * (omega_d - w))
        if self.gyro:
            m = m + cross3(w_abs, self.J @ w_abs)
        m_out, sigma = scale_to_limits(m, self.limit)
        return dict(torque_body=m_out, phi=phi, phi_dot=float(e @ w), e_phi=e, a_max=a_max,
                    w_prof=w_prof, sigma=sigma)

    def _torque_law(self, q_err: np.ndarray, w_rel: np.ndarray, w_abs: np.ndarray,
                    dt: float) -> dict:
        return self.law(q_err, w_rel, w_abs)
