"""Actuator models of the simulated spacecraft: magnetorquers and a reaction-wheel cluster.

Equations
---------
Magnetorquers (paper 000, eqs. (4)-(6))::

    tau_body = m_body x b_body                                                          (A1)
    m_i      = clip(m_cmd_i, -m_max_i, +m_max_i),  i = x, y, z                           (A2)

(A2) is the hardware (each coil saturates on its own axis); keeping the dipole's direction by
scaling (paper 000 eq. (31)) is the controller's job.

Reaction wheels (paper 001, eq. (6); ``a_k`` = unit spin axis of wheel k in body axes, the
columns of ``A = [a_1 ... a_n]`` (3, n))::

    h_body     = A h_w                     wheel momentum in body axes                   (W1)
    dh_w/dt    = tau_w                     motor torque acting on each wheel             (W2)
    tau_body   = -A tau_w                  reaction of the motors on the body            (W3)
    tau_w,k    = clip(tau_cmd,k, -tau_max,k, +tau_max,k)                                  (W4)

``h_w`` is the wheel's inertial axial momentum ``J_k (Omega_k + a_k . omega_body_eci_body)``,
so (W2) is exact and the rotor's axial inertia is not in the spacecraft inertia. After (W4) a
torque that would drive ``|h_w,k|`` past ``h_max,k`` within the hold time ``dt`` is reduced so
that ``h_w,k + tau_w,k dt`` lands on the limit (without ``dt``: cut to zero at the limit).

Momentum control error (paper 001: 0.01 N m s, 3-sigma), redrawn every period ``T``
(``j = floor(t / T)``), not accumulated, realised as a torque held over period ``j``, so
``h_w(j T) = h_cmd(j T) + e_{j-1}``; ``e_j`` from ``default_rng([seed, j])``::

    delta_tau_j = (e_j - e_{j-1}) / T,   e_j ~ N(0, sigma^2),  e_{-1} = 0                 (W5)
"""
from __future__ import annotations

import numpy as np

from adcs_nodes.core.control import integer, positive


def _vector(value, name: str, shape: tuple | None = None) -> np.ndarray:
    """``value`` as a finite float array (optionally of ``shape``), else ``ValueError``."""
    arr = np.array(value, dtype=float)
    if shape is not None and arr.shape != shape:
        raise ValueError(f'{name} must have shape {shape}, got {arr.shape}')
    if np.any(np.isnan(arr)):
        raise ValueError(f'{name} contains NaN: {arr}')
    return arr


def _limits(value, name: str, shape: tuple) -> np.ndarray:
    """Non-negative limits (``inf`` allowed: no limit) broadcast to ``shape``."""
    arr = _vector(value, name)
    try:
        arr = np.broadcast_to(arr, shape).astype(float)
    except ValueError:
        raise ValueError(f'{name} must be a scalar or have shape {shape}, got {arr.shape}') \
            from None
    if np.any(arr < 0.0):
        raise ValueError(f'{name} must be >= 0, got {arr}')
    return arr


class Magnetorquer:
    """Three orthogonal magnetorquers along the body axes, saturating per axis (A2):
    ``max_dipole_Am2`` (3,) or scalar [A m^2] >= 0 (``ValueError`` if not)."""

    def __init__(self, max_dipole_Am2) -> None:
        self.max_dipole_Am2 = _limits(max_dipole_Am2, 'max_dipole_Am2', (3,))

    def apply(self, dipole_cmd) -> np.ndarray:
        """Applied dipole ``m_body`` (3,) [A m^2] of the finite request ``dipole_cmd`` (3,),
        body axes (A2)."""
        m = _vector(dipole_cmd, 'dipole_cmd', (3,))
        if not np.all(np.isfinite(m)):
            raise ValueError(f'dipole_cmd is not finite: {m}')
        return np.clip(m, -self.max_dipole_Am2, self.max_dipole_Am2)

    @staticmethod
    def torque(dipole_body, b_body) -> np.ndarray:
        """``tau_body = m_body x b_body`` (A1) [N m] of the dipole [A m^2] and field [T], all
        (3,) body axes."""
        m = _vector(dipole_body, 'dipole_body', (3,))
        b = _vector(b_body, 'b_body', (3,))
        return np.cross(m, b)


class WheelCluster:
    """Reaction wheels with arbitrary spin axes, torque and momentum limits (W1)-(W4).

    ``axes_body`` (n, 3): spin axes in body axes (normalised here; positive torque and momentum
    along them); per wheel, (n,) or scalar: ``max_torque`` [N m] >= 0, ``max_momentum``
    [N m s] >= 0 (``inf``: none), rotor ``inertia`` [kg m^2] > 0 (for the speed only).
    ``ValueError`` on no wheel, a zero axis, a bad limit or inertia, or disagreeing shapes.
    """

    def __init__(self, axes_body, max_torque, max_momentum, inertia) -> None:
        axes = _vector(axes_body, 'axes_body')
        if axes.ndim == 1 and axes.shape == (3,):
            axes = axes[np.newaxis, :]
        if axes.ndim != 2 or axes.shape[1] != 3 or axes.shape[0] == 0:
            raise ValueError(f'axes_body must have shape (n, 3) with n >= 1, got {axes.shape}')
        if not np.all(np.isfinite(axes)):
            raise ValueError(f'axes_body is not finite: {axes}')
        norms = np.linalg.norm(axes, axis=1)
        if np.any(norms < 1e-9):
            rows = np.flatnonzero(norms < 1e-9).tolist()
            raise ValueError(f'wheel axis has zero length: axes_body rows {rows}')
        n = axes.shape[0]
        self.axes_body = axes / norms[:, np.newaxis]
        self.max_torque = _limits(max_torque, 'max_torque', (n,))
        self.max_momentum = _limits(max_momentum, 'max_momentum', (n,))
        self.inertia = _limits(inertia, 'inertia', (n,))
        if np.any(self.inertia <= 0.0) or not np.all(np.isfinite(self.inertia)):
            raise ValueError(f'wheel inertia must be > 0 and finite, got {self.inertia}')
        # (3, n): column k is the spin axis of wheel k, the matrix A of (W1), (W3).
        self.A = np.ascontiguousarray(self.axes_body.T)

    @property
    def n(self) -> int:
        """Number of wheels."""
        return self.axes_body.shape[0]

    def _per_wheel(self, value, name: str) -> np.ndarray:
        arr = _vector(value, name, (self.n,))
        if not np.all(np.isfinite(arr)):
            raise ValueError(f'{name} is not finite: {arr}')
        return arr

    def apply(self, torque_cmd, h_wheels, dt: float | None = None) -> np.ndarray:
        """Applied motor torque (n,) [N m] per wheel, (W4) and the momentum limit over the
        hold time ``dt`` [s] (module docstring), of ``torque_cmd`` (n,) [N m] and the wheel
        momenta ``h_wheels`` (n,) [N m s] at the start of the hold."""
        tau = np.clip(self._per_wheel(torque_cmd, 'torque_cmd'), -self.max_torque,
                      self.max_torque)
        h = self._per_wheel(h_wheels, 'h_wheels')
        if dt is None:
            blocked = ((h >= self.max_momentum) & (tau > 0.0)) | \
                      ((h <= -self.max_momentum) & (tau < 0.0))
            return np.where(blocked, 0.0, tau)
        if not (dt > 0.0 and np.isfinite(dt)):
            raise ValueError(f'dt must be > 0 and finite, got {dt}')
        upper = np.maximum((self.max_momentum - h) / dt, 0.0)   # inf when unlimited
        lower = np.minimum((-self.max_momentum - h) / dt, 0.0)
        return np.clip(tau, lower, upper)

    def h_body(self, h_wheels) -> np.ndarray:
        """Total wheel momentum in body axes ``A h_w`` (W1) [N m s], shape (3,)."""
        return self.A @ self._per_wheel(h_wheels, 'h_wheels')

    def torque_body(self, wheel_torque) -> np.ndarray:
        """Reaction torque of the motors on the body ``-A tau_w`` (W3) [N m], shape (3,)."""
        return -(self.A @ self._per_wheel(wheel_torque, 'wheel_torque'))

    def speed(self, h_wheels, omega_body_eci_body=None) -> np.ndarray:
        """Wheel speed (n,) [rad/s] of ``h_wheels`` (n,) [N m s]: ``h / J - a . omega``
        relative to the body given ``omega_body_eci_body`` (3,) [rad/s], else ``h / J``."""
        spin = self._per_wheel(h_wheels, 'h_wheels') / self.inertia
        if omega_body_eci_body is None:
            return spin
        w = _vector(omega_body_eci_body, 'omega_body_eci_body', (3,))
        return spin - self.axes_body @ w


class WheelMomentumError:
    """Seeded momentum control error (W5) of ``n`` wheels: ``std_Nms`` ``sigma`` (n,) or scalar
    [N m s] >= 0 (paper 001: 0.01 / 3), ``period_s`` ``T`` [s] > 0, ``seed`` >= 0."""

    def __init__(self, std_Nms, period_s: float, n: int, seed: int) -> None:
        self.n = integer(n, 'n')
        self.std_Nms = _limits(std_Nms, 'std_Nms', (self.n,))
        if not np.all(np.isfinite(self.std_Nms)):
            raise ValueError(f'std_Nms must be finite, got {self.std_Nms}')
        period = positive(period_s, 'period_s', 's')
        self.seed = integer(seed, 'seed', 0)
        self.period_s = period

    def error(self, j: int) -> np.ndarray:
        """``e_j`` [N m s], shape (n,); zero for ``j < 0``."""
        if j < 0:
            return np.zeros(self.n)
        return self.std_Nms * np.random.default_rng([self.seed, int(j)]).standard_normal(self.n)

    def torque(self, t: float) -> np.ndarray:
        """Extra motor torque (W5) [N m] per wheel over the period containing ``t`` [s]."""
        j = int(np.floor(t / self.period_s + 1e-9))
        return (self.error(j) - self.error(j - 1)) / self.period_s
