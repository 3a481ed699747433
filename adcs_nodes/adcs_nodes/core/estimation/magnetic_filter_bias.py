"""Paper 000's magnetometer-only filter plus an estimate of a constant magnetometer bias.

Beyond the paper (which leaves the bias, up to 120 nT, out of the estimation): the paper's
filter (:class:`~adcs_nodes.core.estimation.magnetic_filter.MagneticFilter`, (33)-(39),
unchanged) on bias-corrected readings, with an attitude-independent recursive bias estimator on
the field magnitude (scalar checking, Gambhir 1975; TWOSTEP, Alonso-Shuster 2002).

Equations
---------
Reading ``n = C B + b + v`` (body axes [T]: ``C`` orbit -> body, ``B`` true field, ``b`` the
constant bias, ``v`` noise). A rotation keeps lengths, so with the onboard model ``B*`` (orbit
axes) ``|n - b|^2 = |B*|^2`` up to noise and model error, whatever the attitude::

    y   = |n|^2 - |B*|^2 = 2 n^T b - |b|^2 + e                                          (B1)
    H   = 2 (n - b^)^T                    (1, 3) [T], the Jacobian of (B1) at b^        (B2)
    nu  = y - (2 n^T b^ - |b^|^2)
    R   = 4 |n - b^|^2 sigma_m^2          [T^4], sigma_m: std of |n - b| - |B*|         (B3)
    S   = H P_b H^T + R,  K = P_b H^T / S,  b^ += K nu                                   (B4)
    P_b = (I - K H) P_b (I - K H)^T + K R K^T          (Joseph form)
    P_b += q_b^2 dt I   at each prediction            (slow bias drift, default q_b = 0)

A reading with ``|nu| > gate sqrt(S)`` does not update ``b^`` (it still goes to the attitude
filter, which runs (36)-(39) on ``n - b^``). The bias is observable when ``n`` takes several
directions (a tumble, or an orbit of a held attitude); a misalignment is not (the magnitude
carries nothing about a rotation). The bias states stay outside the paper's 9-state error
vector: (B1) does not depend on attitude, rate or disturbance, so the two exchange only ``b^``
(a divergence reset keeps it). Model error in ``|B*|`` enters (B1) like a bias along ``n`` and
must be covered by ``sigma_m``.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core.control import positive
from adcs_nodes.core.estimation.algorithms import MagneticFilterEstimator
from adcs_nodes.core.estimation.magnetic_filter import THETA_DEFAULT, MagneticFilter

BIAS_STD0_DEFAULT = 2e-7
"""Default prior std of each bias component [T] (paper 000: bias up to 120 nT)."""
MAGNITUDE_STD_DEFAULT = math.sqrt(THETA_DEFAULT)
"""Default ``sigma_m`` [T] of (B3): the filter's ``sqrt(theta)`` (0.3 uT)."""
MAX_BIAS_DEFAULT = 5e-6
"""Default guard on ``|b^|`` [T]."""
GATE_DEFAULT = 5.0
"""Default innovation gate of (B4) [std]."""


class MagneticFilterBias(MagneticFilter):
    """Paper 000's filter (33)-(39) on bias-corrected readings, bias from (B1)-(B4).

    Beside :class:`MagneticFilter`'s parameters (``**filter_args``): ``bias0_T`` (3,) [T] body
    axes, the initial estimate; ``bias_std0_T`` [T] in (0, 1e-4], its prior std per axis;
    ``magnitude_std_T`` [T] in (0, 1e-4], ``sigma_m`` of (B3); ``bias_walk_T_sqrt_s``
    [T/sqrt(s)] >= 0, ``q_b``; ``max_bias_T`` [T], the guard on ``|b^|``; ``bias_gate_sigma``
    [std], the gate of (B4). A bad value is a ``ValueError`` naming it.
    """

    def __init__(self, inertia: ArrayLike, bias0_T: ArrayLike = (0.0, 0.0, 0.0),
                 bias_std0_T: float = BIAS_STD0_DEFAULT,
                 magnitude_std_T: float = MAGNITUDE_STD_DEFAULT,
                 bias_walk_T_sqrt_s: float = 0.0, max_bias_T: float = MAX_BIAS_DEFAULT,
                 bias_gate_sigma: float = GATE_DEFAULT, **filter_args) -> None:
        self.bias_std0 = positive(bias_std0_T, 'bias_std0_T', 'T', upper=1e-4)
        self.magnitude_std = positive(magnitude_std_T, 'magnitude_std_T', 'T', upper=1e-4)
        self.bias_walk = positive(bias_walk_T_sqrt_s, 'bias_walk_T_sqrt_s', 'T/sqrt(s)', zero=True)
        self.max_bias = positive(max_bias_T, 'max_bias_T', 'T')
        self.gate = positive(bias_gate_sigma, 'bias_gate_sigma', 'std')
        b0 = np.asarray(bias0_T, dtype=float)
        if b0.shape != (3,) or not np.all(np.isfinite(b0)) \
                or float(np.linalg.norm(b0)) > self.max_bias:
            raise ValueError(f'bias0_T must be 3 finite values with norm <= max_bias_T, got '
                             f'{bias0_T!r}')
        self.bias0 = b0.copy()
        self.reset_bias()
        super().__init__(inertia, **filter_args)

    # ------------------------------------------------------------------ bias state
    def reset_bias(self) -> None:
        """Bias estimate back to ``bias0_T`` with the prior covariance."""
        self._b = self.bias0.copy()
        self._pb = np.eye(3) * self.bias_std0 ** 2
        self.bias_updates = 0
        self.bias_rejections = 0

    @property
    def bias_body_T(self) -> np.ndarray:
        """``b^`` (3,) [T]: estimated magnetometer bias, body axes."""
        return self._b.copy()

    @property
    def bias_covariance(self) -> np.ndarray:
        """``P_b`` (3, 3) [T^2] of the bias estimate."""
        return self._pb.copy()

    # ------------------------------------------------------------------ filter steps
    def predict(self, dt: float, omega0: float, dipole_body: ArrayLike = (0.0, 0.0, 0.0),
                b_body_for_torque: Optional[ArrayLike] = None,
                b_orbit_for_torque: Optional[ArrayLike] = None) -> bool:
        """:meth:`MagneticFilter.predict`, plus the bias drift ``P_b += q_b^2 dt I``."""
        ok = super().predict(dt, omega0, dipole_body, b_body_for_torque, b_orbit_for_torque)
        if self.bias_walk > 0.0:
            self._pb = self._pb + np.eye(3) * self.bias_walk ** 2 * float(dt)
        return ok

    def update_bias(self, b_meas_body: ArrayLike, b_ref_orbit: ArrayLike) -> bool:
        """One magnitude update (B1)-(B4) of the bias from the reading ``n`` (3,) [T], body
        axes, and the model field ``B*`` (3,) [T] (its magnitude); True if applied."""
        n = np.asarray(b_meas_body, dtype=float)
        b_ref = np.asarray(b_ref_orbit, dtype=float)
        finite = bool(np.all(np.isfinite(n)) and np.all(np.isfinite(b_ref)))
        if n.shape != (3,) or b_ref.shape != (3,) or not finite:
            self.bias_rejections += 1
            return False
        b = self._b
        y = float(n @ n - b_ref @ b_ref)                                             # (B1)
        h = 2.0 * (n - b)                                                           # (B2)
        nu = y - (2.0 * float(n @ b) - float(b @ b))
        r = 4.0 * float((n - b) @ (n - b)) * self.magnitude_std ** 2                  # (B3)
        ph = self._pb @ h
        s = float(h @ ph) + r
        if not (math.isfinite(s) and s > 0.0) or abs(nu) > self.gate * math.sqrt(s):
            self.bias_rejections += 1
            return False
        k = ph / s                                                                    # (B4)
        b_new = b + k * nu
        if not np.all(np.isfinite(b_new)) or float(np.linalg.norm(b_new)) > self.max_bias:
            self.bias_rejections += 1
            return False
        ikh = np.eye(3) - np.outer(k, h)
        pb = ikh @ self._pb @ ikh.T + r * np.outer(k, k)
        self._b, self._pb = b_new, 0.5 * (pb + pb.T)
        self.bias_updates += 1
        return True

    def update(self, b_meas_body: ArrayLike, b_ref_orbit: ArrayLike,
               theta_axes: Optional[ArrayLike] = None) -> dict:
        """Bias update (B1)-(B4), then :meth:`MagneticFilter.update` on ``n - b^``.

        Returns the dict of :meth:`MagneticFilter.update` plus ``bias`` (3,) [T] (the estimate
        used) and ``bias_updated`` (bool). A reading the paper's filter rejects does not update
        the bias either.
        """
        try:
            n = np.asarray(b_meas_body, dtype=float)
            b_ref = np.asarray(b_ref_orbit, dtype=float)
            usable = (n.shape == (3,) and b_ref.shape == (3,) and np.all(np.isfinite(n))
                      and np.all(np.isfinite(b_ref))
                      and self.b_limits[0] <= float(np.linalg.norm(n)) <= self.b_limits[1])
        except (TypeError, ValueError):
            usable = False
        if not usable:
            out = self._paper_update(b_meas_body, b_ref_orbit, theta_axes)
            out.update({'bias': self.bias_body_T, 'bias_updated': False})
            return out
        saved = (self._b.copy(), self._pb.copy(), self.bias_updates, self.bias_rejections)
        updated = self.update_bias(n, b_ref)
        out = self._paper_update(n - self._b, b_ref, theta_axes)
        if not out.get('accepted', False) and updated:
            self._b, self._pb, self.bias_updates, self.bias_rejections = saved
            updated = False
        out.update({'bias': self.bias_body_T, 'bias_updated': updated})
        return out

    def residual(self, b_meas_body: ArrayLike, b_ref_orbit: ArrayLike) -> np.ndarray:
        """``z`` (3,) [T] of a reading before the update, bias and misalignment removed."""
        return super().residual(np.asarray(b_meas_body, dtype=float) - self._b, b_ref_orbit)

    def _paper_update(self, b_meas_body, b_ref_orbit, theta_axes) -> dict:
        """The paper's update (36)-(39) (``theta_axes`` passed only when given)."""
        if theta_axes is None:
            return super().update(b_meas_body, b_ref_orbit)
        return super().update(b_meas_body, b_ref_orbit, theta_axes)


class MagneticFilterBiasEstimator(MagneticFilterEstimator):
    """:class:`MagneticFilterBias` behind the estimator interface (``magnetic_filter_bias``);
    ``max_rate_rad_s`` is also the wrapper's divergence limit. A divergence reset restarts the
    attitude filter and keeps the bias estimate."""

    def __init__(self, inertia: ArrayLike, max_rate_rad_s: float = 1.0, **filter_args) -> None:
        super().__init__(inertia, max_rate_rad_s=max_rate_rad_s,
                         **{k: v for k, v in filter_args.items()
                            if k not in _BIAS_KEYS})
        for key in _WRAPPER_KEYS:                          # the wrapper's options
            filter_args.pop(key, None)
        self.filter = MagneticFilterBias(inertia, max_rate_rad_s=max_rate_rad_s, **filter_args)


_BIAS_KEYS = ('bias0_T', 'bias_std0_T', 'magnitude_std_T', 'bias_walk_T_sqrt_s', 'max_bias_T',
              'bias_gate_sigma')
_WRAPPER_KEYS = ('use_sensor_covariance', 'theta_interval_s', 'hypotheses', 'hypothesis_window_s')
