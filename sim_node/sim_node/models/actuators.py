"""Actuator models of the simulated spacecraft: magnetorquers and a reaction-wheel cluster.

Equations
---------
Magnetorquers (paper 000, eqs. (4)-(6))::

    tau_body = m_body x b_body                                                          (A1)
    m_i      = clip(m_cmd_i, -m_max_i, +m_max_i),  i = x, y, z                           (A2)

(A2) is what the *hardware* does: each coil driver saturates on its own axis. Scaling the
whole dipole by ``sigma = 1 / max_i(|m_i| / m_max_i)`` to keep its direction (paper 000,
eq. (31)) is the *controller's* job; a controller that does it never reaches (A2).

Reaction wheels (paper 001, eq. (6); ``a_k`` = unit spin axis of wheel k in body axes, the
columns of ``A = [a_1 ... a_n]`` (3, n))::

    h_body     = A h_w                     wheel momentum in body axes                   (W1)
    dh_w/dt    = tau_w                     motor torque acting on each wheel             (W2)
    tau_body   = -A tau_w                  reaction of the motors on the body            (W3)
    tau_w,k    = clip(tau_cmd,k, -tau_max,k, +tau_max,k)                                  (W4)

``h_w`` is the wheel's angular momentum about its own axis in inertial space,
``J_k (Omega_k + a_k . omega_body_eci_body)``; with it (W2) holds exactly and the rotor's axial
inertia is not part of the spacecraft inertia. (W4) is followed by the momentum limit: a
torque that would drive ``|h_w,k|`` past ``h_max,k`` is cut to zero at the limit, or, when the
hold time ``dt`` is known, reduced so that ``h_w,k + tau_w,k dt`` lands on the limit;
:meth:`WheelCluster.saturation_status` says which wheels are torque- or momentum-limited.

Momentum control error (paper 001: 0.01 N m s, 3-sigma), :class:`WheelMomentumError`::

    delta_tau_j = (e_j - e_{j-1}) / T,   e_j ~ N(0, sigma^2) per wheel and period j       (W5)
"""
from __future__ import annotations

import numpy as np


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
    """Three orthogonal magnetorquers along the body axes, saturating per axis (A2).

    Parameters
    ----------
    max_dipole_Am2 : array_like, shape (3,) or scalar
        Largest dipole magnitude of each coil [A m^2], body x, y, z; ``>= 0``.

    Raises
    ------
    ValueError
        If a limit is negative, NaN or of the wrong shape.
    """

    def __init__(self, max_dipole_Am2) -> None:
        self.max_dipole_Am2 = _limits(max_dipole_Am2, 'max_dipole_Am2', (3,))

    def apply(self, dipole_cmd) -> np.ndarray:
        """Dipole the coils produce for a requested dipole (per-axis clipping, A2).

        Parameters
        ----------
        dipole_cmd : array_like, shape (3,)
            Requested dipole, body axes [A m^2]; must be finite.

        Returns
        -------
        numpy.ndarray, shape (3,)
            Applied dipole ``m_body``, body axes [A m^2].
        """
        m = _vector(dipole_cmd, 'dipole_cmd', (3,))
        if not np.all(np.isfinite(m)):
            raise ValueError(f'dipole_cmd is not finite: {m}')
        return np.clip(m, -self.max_dipole_Am2, self.max_dipole_Am2)

    @staticmethod
    def torque(dipole_body, b_body) -> np.ndarray:
        """Magnetic torque ``tau_body = m_body x b_body`` (A1) [N m], body axes.

        Parameters
        ----------
        dipole_body : array_like, shape (3,)
            Dipole [A m^2], body axes (already saturated).
        b_body : array_like, shape (3,)
            Geomagnetic field [T], body axes.
        """
        m = _vector(dipole_body, 'dipole_body', (3,))
        b = _vector(b_body, 'b_body', (3,))
        return np.cross(m, b)


class WheelCluster:
    """Reaction wheels with arbitrary spin axes, torque and momentum limits (W1)-(W4).

    Parameters
    ----------
    axes_body : array_like, shape (n, 3)
        Spin axis of each wheel in body axes; normalised here. Positive wheel torque and
        momentum are along this axis.
    max_torque : array_like, shape (n,) or scalar
        Largest motor torque magnitude per wheel [N m], ``>= 0``.
    max_momentum : array_like, shape (n,) or scalar
        Largest wheel momentum magnitude per wheel [N m s], ``>= 0`` (``inf``: no limit).
    inertia : array_like, shape (n,) or scalar
        Rotor axial inertia per wheel [kg m^2], ``> 0``; used only for the wheel speed.

    Raises
    ------
    ValueError
        If there is no wheel, an axis is (near) zero or not finite, a limit is negative or
        NaN, an inertia is not positive and finite, or the shapes disagree.
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
        """Motor torque actually applied to each wheel, (W4) and the momentum limit.

        Parameters
        ----------
        torque_cmd : array_like, shape (n,)
            Requested motor torque per wheel [N m].
        h_wheels : array_like, shape (n,)
            Wheel momentum about each spin axis [N m s] at the start of the hold.
        dt : float, optional
            Hold time [s] of the torque. Without it, the torque of a wheel at (or past) its
            momentum limit is zero when it pushes further. With it, the torque is also reduced
            so that ``h_wheels + tau dt`` stays inside ``[-max_momentum, max_momentum]``.

        Returns
        -------
        numpy.ndarray, shape (n,)
            Applied motor torque per wheel [N m]; the body feels ``-A tau`` (W3).
        """
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

    def saturation_status(self, torque_cmd, h_wheels, dt: float | None = None) -> dict:
        """Which wheels :meth:`apply` limits, the status a wheel driver reports.

        Returns
        -------
        dict of numpy.ndarray, shape (n,), bool
            ``torque_limited``: the command exceeds the torque limit (W4);
            ``momentum_limited``: the torque is cut by the momentum limit (the wheel is at, or
            would pass within ``dt``, its ``max_momentum``).
        """
        cmd = self._per_wheel(torque_cmd, 'torque_cmd')
        clipped = np.clip(cmd, -self.max_torque, self.max_torque)
        applied = self.apply(cmd, h_wheels, dt)
        return {'torque_limited': np.abs(cmd) > self.max_torque,
                'momentum_limited': np.abs(applied - clipped) > 0.0}

    def h_body(self, h_wheels) -> np.ndarray:
        """Total wheel momentum in body axes ``A h_w`` (W1) [N m s], shape (3,)."""
        return self.A @ self._per_wheel(h_wheels, 'h_wheels')

    def torque_body(self, wheel_torque) -> np.ndarray:
        """Reaction torque of the motors on the body ``-A tau_w`` (W3) [N m], shape (3,)."""
        return -(self.A @ self._per_wheel(wheel_torque, 'wheel_torque'))

    def speed(self, h_wheels, omega_body_eci_body=None) -> np.ndarray:
        """Wheel speed [rad/s], shape (n,).

        Parameters
        ----------
        h_wheels : array_like, shape (n,)
            Wheel momentum about each spin axis [N m s].
        omega_body_eci_body : array_like, shape (3,), optional
            Body rate [rad/s]. Given, the result is the speed relative to the body,
            ``h / J - a . omega``; omitted, it is ``h / J`` (the inertial spin rate, equal to the
            relative speed up to the body rate, which is small against a wheel's).
        """
        spin = self._per_wheel(h_wheels, 'h_wheels') / self.inertia
        if omega_body_eci_body is None:
            return spin
        w = _vector(omega_body_eci_body, 'omega_body_eci_body', (3,))
        return spin - self.axes_body @ w


class WheelMomentumError:
    """Seeded momentum control error of a wheel cluster (paper 001: 0.01 N m s, 3-sigma).

    The wheel momentum deviates from the commanded integral by ``e_j ~ N(0, sigma^2)`` per
    wheel, redrawn every period ``T`` (index ``j = floor(t / T)``); it does not accumulate.
    Realised as an extra motor torque held over period ``j``::

        delta_tau_j = (e_j - e_{j-1}) / T,     e_{-1} = 0                                  (W5)

    so ``h_w(j T) = h_cmd(j T) + e_{j-1}`` exactly. ``e_j`` comes from
    ``numpy.random.default_rng([seed, j])`` (a pure function of the seed and the period, as
    :class:`~sim_node.models.disturbances.RandomTorque`).

    Parameters
    ----------
    std_Nms : float or array_like, shape (n,)
        ``sigma`` per wheel [N m s], ``>= 0`` (paper 001: 0.01 / 3).
    period_s : float
        ``T`` [s], ``> 0`` (the control period).
    n : int
        Number of wheels.
    seed : int
        Non-negative seed.
    """

    def __init__(self, std_Nms, period_s: float, n: int, seed: int) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f'n must be an integer >= 1, got {n!r}')
        self.std_Nms = _limits(std_Nms, 'std_Nms', (int(n),))
        if not np.all(np.isfinite(self.std_Nms)):
            raise ValueError(f'std_Nms must be finite, got {self.std_Nms}')
        period = float(period_s)
        if not (np.isfinite(period) and period > 0.0):
            raise ValueError(f'period_s must be > 0 and finite, got {period_s!r}')
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f'seed must be a non-negative integer, got {seed!r}')
        self.period_s = period
        self.n = int(n)
        self.seed = int(seed)

    def error(self, j: int) -> np.ndarray:
        """``e_j`` [N m s], shape (n,); zero for ``j < 0``."""
        if j < 0:
            return np.zeros(self.n)
        return self.std_Nms * np.random.default_rng([self.seed, int(j)]).standard_normal(self.n)

    def torque(self, t: float) -> np.ndarray:
        """Extra motor torque (W5) [N m] per wheel over the period containing ``t`` [s]."""
        j = int(np.floor(t / self.period_s + 1e-9))
        return (self.error(j) - self.error(j - 1)) / self.period_s
