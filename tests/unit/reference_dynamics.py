"""Independent reference models for the dynamics tests (test code, not the product).

* :class:`FlexibleSpacecraft`: paper 001's hybrid rigid-flexible spacecraft with wheels,
  (H1)-(H4) of ``sim_node.models.flexible``, written directly in numpy (its own RK4 loop, its
  own derivative), against which the compiled kernel is checked.
* :func:`rk4_step`, :func:`pack_state`, :func:`unpack_state`: the classical RK4 step and the
  flat state ``[q (4), omega (3), h_wheels (n), eta (m), eta_dot (m)]``.
"""
from __future__ import annotations

import math
from typing import Callable, Optional, Sequence

import numpy as np

from sim_node.models.actuators import WheelCluster, WheelMomentumError
from sim_node.models.disturbances import MU_EARTH, Disturbance, check_inertia
from sim_node.models.dynamics import SpacecraftState
from sim_node.models.flexible import DEFAULT_DAMPING


def rk4_step(f: Callable[[float, np.ndarray], np.ndarray], t: float, x: np.ndarray,
             h: float) -> np.ndarray:
    """One classical Runge-Kutta step of ``dx/dt = f(t, x)`` from ``t`` to ``t + h``."""
    half = 0.5 * h
    k1 = f(t, x)
    k2 = f(t + half, x + half * k1)
    k3 = f(t + half, x + half * k2)
    k4 = f(t + h, x + h * k3)
    return x + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


def pack_state(state: SpacecraftState) -> np.ndarray:
    """Flat state ``[q (4), omega (3), h_wheels (n), eta (m), eta_dot (m)]``."""
    return np.concatenate((state.q_eci_body, state.omega_body_eci_body, state.h_wheels,
                           state.eta, state.eta_dot))


def unpack_state(x: np.ndarray, n_modes: int = 0) -> SpacecraftState:
    """Inverse of :func:`pack_state` (copies) for ``n_modes`` flexible modes."""
    m = int(n_modes)
    end = len(x) - 2 * m
    return SpacecraftState(x[0:4].copy(), x[4:7].copy(), x[7:end].copy(),
                           x[end:end + m].copy(), x[end + m:].copy())


class FlexibleSpacecraft:
    """Hybrid rigid-flexible spacecraft with reaction wheels, (H1)-(H4).

    Parameters
    ----------
    inertia : array_like, shape (3, 3)
        ``I_b``, body axes [kg m^2], rotors locked; the hub ``I_b - F F^T`` must stay positive
        definite.
    coupling : array_like, shape (3, m)
        ``F`` [kg^1/2 m] (m >= 0).
    frequencies_hz : array_like, shape (m,)
        Constrained-hub modal frequencies [Hz], > 0.
    damping : float or array_like, shape (m,)
        Modal damping ratios ``zeta`` in [0, 1).
    wheels : WheelCluster, optional
        Reaction wheels (their torque and momentum limits act in :meth:`step`).
    disturbances : sequence of Disturbance
        Body-fixed torques ``torque(t) -> (3,)`` [N m].
    gravity_gradient : bool
        Add the gravity-gradient torque of ``I_b`` (needs ``r_eci`` in :meth:`step`).
    wheel_error : WheelMomentumError, optional
        Momentum control error (W5), added to the limited wheel torque.

    Raises
    ------
    ValueError
        On bad shapes, non-finite values, non-positive frequencies, damping outside [0, 1),
        or a hub inertia that is not positive definite.
    """

    def __init__(self, inertia, coupling, frequencies_hz, damping=DEFAULT_DAMPING,
                 wheels: Optional[WheelCluster] = None, disturbances: Sequence = (),
                 gravity_gradient: bool = False, mu: float = MU_EARTH,
                 wheel_error: Optional[WheelMomentumError] = None) -> None:
        self.inertia = check_inertia(inertia)
        f = np.array(coupling, dtype=float)
        if f.ndim != 2 or f.shape[0] != 3 or not np.all(np.isfinite(f)):
            raise ValueError(f'coupling must be a finite (3, m) array, got shape {f.shape}')
        m = f.shape[1]
        freq = np.array(frequencies_hz, dtype=float).reshape(-1)
        if freq.shape != (m,) or not np.all(np.isfinite(freq)) or np.any(freq <= 0.0):
            raise ValueError(f'frequencies_hz must be {m} finite values > 0, got {freq}')
        zeta = np.broadcast_to(np.array(damping, dtype=float), (m,)).copy()
        if not np.all(np.isfinite(zeta)) or np.any(zeta < 0.0) or np.any(zeta >= 1.0):
            raise ValueError(f'damping must be in [0, 1), got {zeta}')
        hub = self.inertia - f @ f.T
        if np.linalg.eigvalsh(0.5 * (hub + hub.T))[0] <= 0.0:
            raise ValueError('hub inertia I_b - F F^T is not positive definite: the coupling '
                             'is too large for this inertia')
        if wheels is not None and not isinstance(wheels, WheelCluster):
            raise ValueError(f'wheels must be a WheelCluster or None, got {wheels!r}')
        for d in disturbances:
            if not isinstance(d, Disturbance):
                raise ValueError(f'disturbance {d!r} has no torque(t) method')
        self.coupling = f
        self.m = m
        self.lam = 2.0 * math.pi * freq
        self.zeta = zeta
        self.wheels = wheels
        self.n = wheels.n if wheels is not None else 0
        self.a_w = wheels.A if wheels is not None else np.zeros((3, 0))
        self.disturbances = list(disturbances)
        if wheel_error is not None and (self.n == 0 or wheel_error.n != self.n):
            raise ValueError('wheel_error needs wheels and must have one entry per wheel')
        self.wheel_error = wheel_error
        self.gravity_gradient = bool(gravity_gradient)
        self.mu = float(mu)
        mass = np.zeros((3 + m, 3 + m))
        mass[:3, :3] = self.inertia
        mass[:3, 3:] = f
        mass[3:, :3] = f.T
        mass[3:, 3:] = np.eye(m)
        self.mass = mass
        self.mass_inv = np.linalg.inv(mass)
        self._c = 2.0 * self.zeta * self.lam
        self._k = self.lam ** 2

    # ------------------------------------------------------------------ state helpers
    @property
    def size(self) -> int:
        """Length of the flat state vector, ``7 + 2 m + n``."""
        return 7 + 2 * self.m + self.n

    def pack(self, q_eci_body, omega_body_eci_body, eta=None, eta_dot=None,
             h_wheels=None) -> np.ndarray:
        """Flat state from its parts (missing modal/wheel parts are zero)."""
        x = np.zeros(self.size)
        x[0:4] = np.asarray(q_eci_body, dtype=float) / np.linalg.norm(q_eci_body)
        x[4:7] = omega_body_eci_body
        m, n = self.m, self.n
        if eta is not None:
            x[7:7 + m] = eta
        if eta_dot is not None:
            x[7 + m:7 + 2 * m] = eta_dot
        if h_wheels is not None:
            x[7 + 2 * m:7 + 2 * m + n] = h_wheels
        return x

    def unpack(self, x: np.ndarray) -> dict:
        """Parts of a flat state: ``q_eci_body``, ``omega_body_eci_body``, ``eta``,
        ``eta_dot``, ``h_wheels`` (copies)."""
        m = self.m
        return {'q_eci_body': x[0:4].copy(), 'omega_body_eci_body': x[4:7].copy(),
                'eta': x[7:7 + m].copy(), 'eta_dot': x[7 + m:7 + 2 * m].copy(),
                'h_wheels': x[7 + 2 * m:].copy()}

    # ------------------------------------------------------------------ the model
    def derivative(self, x: np.ndarray, wheel_torque: np.ndarray,
                   torque_ext_body: np.ndarray) -> np.ndarray:
        """``dx/dt`` of (H1)-(H4) with the wheel and external torques given (held).

        Parameters
        ----------
        x : numpy.ndarray, shape (size,)
            Flat state ``[q (4), w (3), eta (m), eta_dot (m), h_w (n)]``.
        wheel_torque : numpy.ndarray, shape (n,)
            Motor torque applied to each wheel [N m] (already limited).
        torque_ext_body : numpy.ndarray, shape (3,)
            External torque, body axes [N m].
        """
        m = self.m
        q = x[0:4]
        w = x[4:7]
        eta = x[7:7 + m]
        eta_d = x[7 + m:7 + 2 * m]
        h_w = x[7 + 2 * m:]
        h_tot = self.inertia @ w + self.coupling @ eta_d + self.a_w @ h_w
        rhs = np.empty(3 + m)
        rhs[:3] = torque_ext_body - self.a_w @ wheel_torque - np.cross(w, h_tot)          # (H1)
        rhs[3:] = -self._c * eta_d - self._k * eta                                       # (H2)
        acc = self.mass_inv @ rhs
        qx, qy, qz, qw = q
        wx, wy, wz = w
        out = np.empty_like(x)
        out[0:4] = (0.5 * (qw * wx + qy * wz - qz * wy), 0.5 * (qw * wy + qz * wx - qx * wz),
                    0.5 * (qw * wz + qx * wy - qy * wx), -0.5 * (qx * wx + qy * wy + qz * wz))
        out[4:7] = acc[:3]                                                                # (H4)
        out[7:7 + m] = eta_d
        out[7 + m:7 + 2 * m] = acc[3:]
        out[7 + 2 * m:] = wheel_torque                                                    # (H3)
        return out

    def external_torque(self, x: np.ndarray, t: float,
                        r_eci: Optional[np.ndarray]) -> np.ndarray:
        """Gravity gradient of ``I_b`` (D1) plus every disturbance at ``t`` [N m], body axes."""
        tau = np.zeros(3)
        for d in self.disturbances:
            tau += d.torque(t)
        if self.gravity_gradient and r_eci is not None:
            q = x[0:4] / np.linalg.norm(x[0:4])
            qx, qy, qz, qw = q
            c = np.array([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy + qz * qw),
                           2 * (qx * qz - qy * qw)],
                          [2 * (qx * qy - qz * qw), 1 - 2 * (qx * qx + qz * qz),
                           2 * (qy * qz + qx * qw)],
                          [2 * (qx * qz + qy * qw), 2 * (qy * qz - qx * qw),
                           1 - 2 * (qx * qx + qy * qy)]])          # R(q)^T: ECI -> body
            r = c @ r_eci
            r2 = float(r @ r)
            tau += 3.0 * self.mu / (r2 * r2 * math.sqrt(r2)) * np.cross(r, self.inertia @ r)
        return tau

    def step(self, x: np.ndarray, t: float, dt: float, wheel_torque_cmd=None,
             torque_body=None, r_eci=None, v_eci=None,
             substeps: int = 1) -> tuple[np.ndarray, dict]:
        """Integrate one frame ``[t, t + dt]`` with the command held (RK4, ``substeps``).

        The wheel command is limited once at ``t`` by the cluster (torque limit, and the
        momentum limit over ``dt``: the torque stops at the limit as hardware does);
        disturbances and gravity gradient are sampled at each substep's midpoint and held over
        it; ``r_eci(t + s) = r_eci + v_eci s``.

        Parameters
        ----------
        x : numpy.ndarray, shape (size,)
            State at ``t``.
        t, dt : float
            Frame start [s] and length [s] (> 0).
        wheel_torque_cmd : array_like, shape (n,), optional
            Requested motor torques [N m] (None: zero).
        torque_body : array_like, shape (3,), optional
            Extra ideal torque [N m], body axes (None: zero).
        r_eci, v_eci : array_like, shape (3,), optional
            Position [m] and velocity [m/s] at ``t`` for the gravity gradient.
        substeps : int
            RK4 substeps (>= 1).

        Returns
        -------
        x : numpy.ndarray
            State at ``t + dt`` (quaternion renormalised).
        applied : dict
            ``wheel_torque`` (n,) applied [N m]; ``torque_limited``, ``momentum_limited``
            (n,) bool status flags; ``torque_ext_body`` (3,) at the first substep [N m].

        Raises
        ------
        ValueError
            On a non-finite state or command, or ``dt <= 0``.
        """
        if not (math.isfinite(dt) and dt > 0.0) or not math.isfinite(t):
            raise ValueError(f't must be finite and dt > 0, got t={t}, dt={dt}')
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) \
                or substeps < 1:
            raise ValueError(f'substeps must be an integer >= 1, got {substeps!r}')
        x = np.array(x, dtype=float)
        if x.shape != (self.size,) or not np.all(np.isfinite(x)):
            raise ValueError(f'state must be a finite ({self.size},) vector')
        cmd = np.zeros(self.n) if wheel_torque_cmd is None else \
            np.array(wheel_torque_cmd, dtype=float).reshape(-1)
        if cmd.size == 0:
            cmd = np.zeros(self.n)
        if cmd.shape != (self.n,) or not np.all(np.isfinite(cmd)):
            raise ValueError(f'wheel_torque_cmd must be a finite ({self.n},) vector')
        ideal = np.zeros(3) if torque_body is None else np.array(torque_body, dtype=float)
        if ideal.shape != (3,) or not np.all(np.isfinite(ideal)):
            raise ValueError('torque_body must be a finite (3,) vector')
        h_w = x[7 + 2 * self.m:]
        if self.wheels is not None:
            tau_w = self.wheels.apply(cmd, h_w, dt)
            clipped = np.clip(cmd, -self.wheels.max_torque, self.wheels.max_torque)
            status = {'torque_limited': np.abs(cmd) > self.wheels.max_torque,     # (W4)
                      'momentum_limited': np.abs(tau_w - clipped) > 0.0}
            if self.wheel_error is not None:       # (W5), still inside the torque limit
                tau_w = np.clip(tau_w + self.wheel_error.torque(t), -self.wheels.max_torque,
                                self.wheels.max_torque)
        else:
            tau_w = cmd
            status = {'torque_limited': np.zeros(0, bool), 'momentum_limited': np.zeros(0, bool)}
        r0 = None if r_eci is None else np.array(r_eci, dtype=float)
        v0 = np.zeros(3) if v_eci is None else np.array(v_eci, dtype=float)
        h = dt / substeps
        tau_first = None
        for i in range(substeps):
            t_i = t + i * h
            r_mid = None if r0 is None else r0 + v0 * (i * h + 0.5 * h)
            tau_ext = self.external_torque(x, t_i + 0.5 * h, r_mid) + ideal
            if tau_first is None:
                tau_first = tau_ext
            k1 = self.derivative(x, tau_w, tau_ext)
            k2 = self.derivative(x + 0.5 * h * k1, tau_w, tau_ext)
            k3 = self.derivative(x + 0.5 * h * k2, tau_w, tau_ext)
            k4 = self.derivative(x + h * k3, tau_w, tau_ext)
            x = x + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
            x[0:4] /= math.sqrt(float(x[0:4] @ x[0:4]))
        applied = {'wheel_torque': tau_w, 'torque_ext_body': tau_first}
        applied.update(status)
        return x, applied

    # ------------------------------------------------------------------ diagnostics
    def energy(self, x: np.ndarray) -> float:
        """Kinetic + modal strain energy [J] (rotor spin energy excluded)."""
        m = self.m
        v = np.concatenate([x[4:7], x[7 + m:7 + 2 * m]])
        eta = x[7:7 + m]
        return 0.5 * float(v @ self.mass @ v) + 0.5 * float(eta @ (self._k * eta))

    def angular_momentum_eci(self, x: np.ndarray) -> np.ndarray:
        """``R(q) (I_b w + F eta_dot + A h_w)`` [N m s], ECI, shape (3,)."""
        m = self.m
        h_body = (self.inertia @ x[4:7] + self.coupling @ x[7 + m:7 + 2 * m]
                  + self.a_w @ x[7 + 2 * m:])
        qx, qy, qz, qw = x[0:4] / np.linalg.norm(x[0:4])
        r = np.array([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw),
                       2 * (qx * qz + qy * qw)],
                      [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz),
                       2 * (qy * qz - qx * qw)],
                      [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw),
                       1 - 2 * (qx * qx + qy * qy)]])
        return r @ h_body

    def free_free_frequencies_hz(self) -> np.ndarray:
        """Modal frequencies [Hz] of the free spacecraft linearised at rest (the
        constrained-hub ones raised by the coupling): ``K v = w^2 M v``, rigid modes dropped."""
        from scipy.linalg import eigh
        stiff = np.zeros_like(self.mass)
        stiff[3:, 3:] = np.diag(self._k)
        lam = eigh(stiff, self.mass, eigvals_only=True)
        return np.sqrt(np.clip(lam[3:], 0.0, None)) / (2.0 * math.pi)
