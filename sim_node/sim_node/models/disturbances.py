"""Environmental and residual disturbance torques on the simulated spacecraft.

Equations
---------
Gravity gradient of a central Newtonian field (paper 000, eq. (3), written for any orbit
instead of ``3 w0^2 e_R x I e_R``, which is its circular-orbit form since
``w0^2 = mu / |r|^3``)::

    r_hat_body = R(q_eci_body)^T r_eci / |r_eci|
    tau_gg_body = 3 mu / |r_eci|^3  r_hat_body x (I r_hat_body)                          (D1)

It vanishes when a principal axis of ``I`` points along ``r`` (the gravity-gradient
equilibria, paper 000 section 2).

Residual torques, body axes (paper 000 section 4: constant ``M_r`` and a Gaussian torque of
std up to 1e-5 N m)::

    tau_const_body(t) = M_r                                                              (D2)
    tau_rand_body(t)  = sigma * n_j,  j = floor(t / T),  n_j ~ N(0, I3)                  (D3)

(D3) is a zero-order hold redrawn every period ``T``. ``n_j`` comes from
``numpy.random.default_rng([seed, j])``: it depends only on ``(seed, j)``, never on how often
or in which order the torque is queried, so a trajectory does not depend on the number of
integrator substeps. The spacecraft model samples every disturbance once per RK4 substep, at
the substep midpoint, and holds it over the substep; with ``T`` a multiple of the substep this
is exact for (D3).
"""
from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from adcs_nodes.core import attitude
from adcs_nodes.core.orbit import MU_EARTH  # one value for the whole project

_INDEX_TOL = 1e-9   # [periods]: t = j T minus a rounding error still belongs to period j


@runtime_checkable
class Disturbance(Protocol):
    """Anything with ``torque(t) -> (3,)`` [N m], body axes, ``t`` in s since the epoch."""

    def torque(self, t: float) -> np.ndarray:
        ...


def check_inertia(inertia, name: str = 'inertia') -> np.ndarray:
    """Validate a rigid-body inertia matrix and return it as a (3, 3) float array.

    Parameters
    ----------
    inertia : array_like, shape (3, 3)
        Inertia about the centre of mass, body axes [kg m^2].

    Raises
    ------
    ValueError
        If it is not finite, not symmetric (relative 1e-9), not positive definite, or its
        principal moments break the triangle inequality ``I1 + I2 >= I3`` of a real body.
    """
    m = np.array(inertia, dtype=float)
    if m.shape != (3, 3):
        raise ValueError(f'{name} must have shape (3, 3), got {m.shape}')
    if not np.all(np.isfinite(m)):
        raise ValueError(f'{name} is not finite: {m.tolist()}')
    scale = np.max(np.abs(m))
    if scale == 0.0 or np.max(np.abs(m - m.T)) > 1e-9 * scale:
        raise ValueError(f'{name} must be symmetric and non-zero, got {m.tolist()}')
    m = 0.5 * (m + m.T)
    moments = np.linalg.eigvalsh(m)
    if moments[0] <= 0.0:
        raise ValueError(f'{name} must be positive definite, principal moments {moments}')
    if moments[0] + moments[1] < moments[2] * (1.0 - 1e-9):
        raise ValueError(f'{name} principal moments {moments} break the triangle inequality '
                         'I1 + I2 >= I3 of a rigid body')
    return m


def gravity_gradient_torque(q_eci_body, r_eci, inertia, mu: float = MU_EARTH) -> np.ndarray:
    """Gravity-gradient torque (D1) [N m], body axes.

    Parameters
    ----------
    q_eci_body : array_like, shape (4,)
        Attitude, scalar last; rotates body components into ECI.
    r_eci : array_like, shape (3,)
        Position of the centre of mass, ECI [m]; non-zero.
    inertia : array_like, shape (3, 3)
        Inertia, body axes [kg m^2].
    mu : float
        Gravitational parameter [m^3/s^2].

    Returns
    -------
    numpy.ndarray, shape (3,)
        ``tau_gg_body`` [N m].
    """
    inertia = check_inertia(inertia)
    r = np.array(r_eci, dtype=float)
    if r.shape != (3,) or not np.all(np.isfinite(r)):
        raise ValueError(f'r_eci must be a finite (3,) vector, got {r}')
    radius = math.sqrt(float(r @ r))
    if radius == 0.0:
        raise ValueError('r_eci must not be zero')
    if not (mu > 0.0 and math.isfinite(mu)):
        raise ValueError(f'mu must be > 0 and finite, got {mu}')
    r_hat_body = attitude.to_matrix(q_eci_body).T @ (r / radius)
    return 3.0 * mu / radius ** 3 * np.cross(r_hat_body, inertia @ r_hat_body)


class ConstantTorque:
    """Constant body-fixed disturbance torque (D2).

    Parameters
    ----------
    torque_body : array_like, shape (3,)
        Torque [N m], body axes; finite.
    """

    def __init__(self, torque_body) -> None:
        tau = np.array(torque_body, dtype=float)
        if tau.shape != (3,) or not np.all(np.isfinite(tau)):
            raise ValueError(f'torque_body must be a finite (3,) vector, got {tau}')
        self.torque_body = tau

    def torque(self, t: float) -> np.ndarray:
        """Torque [N m], body axes, shape (3,), at any time ``t`` [s]."""
        return self.torque_body.copy()


class RandomTorque:
    """Gaussian body-fixed disturbance torque, zero-order hold redrawn every period (D3).

    Parameters
    ----------
    std_Nm : float or array_like, shape (3,)
        Standard deviation per body axis [N m], ``>= 0``.
    period_s : float
        Hold period ``T`` [s], ``> 0``.
    seed : int
        Non-negative seed; with the period index it fully determines every draw.
    """

    def __init__(self, std_Nm, period_s: float, seed: int) -> None:
        std = np.array(std_Nm, dtype=float)
        if std.shape not in ((), (3,)) or not np.all(np.isfinite(std)) or np.any(std < 0.0):
            raise ValueError(f'std_Nm must be a finite scalar or (3,) vector >= 0, got {std}')
        period = float(period_s)
        if not (math.isfinite(period) and period > 0.0):
            raise ValueError(f'period_s must be > 0 and finite, got {period_s}')
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f'seed must be a non-negative integer, got {seed!r}')
        self.std_Nm = np.broadcast_to(std, (3,)).copy()
        self.period_s = period
        self.seed = int(seed)
        self._last_index: int | None = None
        self._last_value = np.zeros(3)

    def index(self, t: float) -> int:
        """Period index ``j = floor(t / T)`` of time ``t`` [s] (rounding-tolerant)."""
        return math.floor(t / self.period_s + _INDEX_TOL)

    def draw(self, j: int) -> np.ndarray:
        """Torque of period ``j`` [N m], body axes, shape (3,); a pure function of (seed, j)."""
        # SeedSequence entropy must be non-negative: map ..., -2, -1, 0, 1, ... one-to-one.
        key = 2 * j if j >= 0 else -2 * j - 1
        return self.std_Nm * np.random.default_rng([self.seed, key]).standard_normal(3)

    def torque(self, t: float) -> np.ndarray:
        """Torque [N m], body axes, shape (3,), held over the period containing ``t`` [s]."""
        j = self.index(t)
        if j != self._last_index:   # cache only: the value is the same either way
            self._last_value = self.draw(j)
            self._last_index = j
        return self._last_value.copy()
