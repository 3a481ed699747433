"""Attitude dynamics of the simulated spacecraft: rigid body, reaction wheels, flexible modes.

State ``x = [q_eci_body (4, scalar last), omega_body_eci_body (3), h_wheels (n)]``; ``I`` the
inertia without the rotors' axial inertia, ``A`` (3, n) the wheel spin axes, body axes::

    dq_eci_body/dt = 1/2 q_eci_body (x) [omega, 0]                                       (E1)
    I domega/dt    = -omega x (I omega + A h_w) + tau_ext - A tau_w                      (E2)
    dh_w/dt        = tau_w                                                               (E3)
    tau_ext        = tau_gg + m x b_body + tau_ideal + sum(tau_disturbance)              (E4)

(E2) is paper 001 eq. (6) and paper 000 eq. (1) with wheels; (E4) uses
``disturbances.gravity_gradient_torque`` (D1) and ``actuators`` (A1).

Flexible appendages (optional, :class:`FlexibleModes`; the hybrid form (H1)-(H2) of
``sim_node.models.flexible``): ``I`` is the whole spacecraft's ``I_b``, ``F`` (3, m) the
coupling, ``eta`` (m,) the modal coordinates [kg^1/2 m], ``Lambda = 2 pi diag(f)``::

    I domega/dt + F eta_ddot = -omega x (I omega + F eta_dot + A h_w) + tau_ext - A tau_w  (E2f)
    eta_ddot + 2 zeta Lambda eta_dot + Lambda^2 eta + F^T domega/dt = 0                    (E9)

solved with the constant mass matrix ``[[I, F], [F^T, E_m]]``. Without damping and torques the
energy and ``R(q) (I omega + F eta_dot + A h_w)`` are conserved. The wheel momentum control
error (``actuators.WheelMomentumError`` (W5)) is added after the limits (W4), clipped again.

Frame step (DESIGN section 6): the command is held from ``t_k`` to ``t_k + dt``; with
``s = t - t_k`` the orbit is integrated with the attitude in the same RK4 stages (E6) and the
field follows a cubic (E7), whose higher terms come from the cubic Hermite polynomial through
``(b, b_dot)`` at ``t_{k-1}`` and ``t_k`` when frames are consecutive (E8), else the line::

    dr_eci/dt = v_eci,   dv_eci/dt = -mu r_eci / |r_eci|^3                             (E6)
    b_eci(t_k + s) = b + b_dot s + b_ddot s^2 / 2 + b_dddot s^3 / 6                    (E7)
    tau = t_k - t_{k-1},  D = b_k - b_{k-1}                                             (E8)
    b_ddot  = 2 [(2 b_dot_k + b_dot_{k-1}) / tau - 3 D / tau^2]
    b_dddot = 6 [(b_dot_k + b_dot_{k-1}) / tau^2 - 2 D / tau^3]

Integration: fixed-step RK4 with ``substeps`` substeps in one compiled call
(``kernels.frame_step``), the quaternion renormalised after each substep, disturbances sampled
at each substep's midpoint. Inputs are validated once per frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from adcs_nodes.core.control import integer
from sim_node.models import kernels
from sim_node.models.actuators import Magnetorquer, WheelCluster, WheelMomentumError
from sim_node.models.disturbances import (MU_EARTH, ConstantTorque, Disturbance, RandomTorque,
                                          check_inertia)


def _zeros3() -> np.ndarray:
    return np.zeros(3)


@dataclass
class SpacecraftState:
    """Dynamic state: ``q_eci_body`` (4,) scalar last (body -> ECI components),
    ``omega_body_eci_body`` (3,) [rad/s] body axes, ``h_wheels`` (n_wheels,) [N m s] about each
    spin axis, ``eta``, ``eta_dot`` (n_modes,) [kg^1/2 m], [kg^1/2 m/s] modal coordinates
    (:class:`FlexibleModes`); the last three have length 0 without wheels or modes."""

    q_eci_body: np.ndarray
    omega_body_eci_body: np.ndarray
    h_wheels: np.ndarray = field(default_factory=lambda: np.zeros(0))
    eta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    eta_dot: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        self.q_eci_body = np.asarray(self.q_eci_body, dtype=float)
        self.omega_body_eci_body = np.asarray(self.omega_body_eci_body, dtype=float)
        self.h_wheels = np.asarray(self.h_wheels, dtype=float).reshape(-1)
        self.eta = np.asarray(self.eta, dtype=float).reshape(-1)
        self.eta_dot = np.asarray(self.eta_dot, dtype=float).reshape(-1)


@dataclass
class FlexibleModes:
    """Flexible appendages as modes in hybrid coordinates, (E2f), (E9): ``coupling`` ``F``
    (3, m) [kg^1/2 m] body axes, constrained-hub ``frequencies_hz`` (m,) > 0, ``damping``
    ratios ``zeta`` (m,) in [0, 1) (a scalar is broadcast). ``ValueError`` if not."""

    coupling: np.ndarray
    frequencies_hz: np.ndarray
    damping: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        f = np.array(self.coupling, dtype=float)
        if f.ndim != 2 or f.shape[0] != 3 or not np.all(np.isfinite(f)):
            raise ValueError(f'coupling must be a finite (3, m) array, got shape {f.shape}')
        m = f.shape[1]
        freq = np.array(self.frequencies_hz, dtype=float).reshape(-1)
        if freq.shape != (m,) or not np.all(np.isfinite(freq)) or np.any(freq <= 0.0):
            raise ValueError(f'frequencies_hz must be {m} finite values > 0, got {freq}')
        zeta = np.array(self.damping, dtype=float)
        if zeta.size == 0:
            zeta = np.zeros(m)
        try:
            zeta = np.broadcast_to(zeta, (m,)).astype(float)
        except ValueError:
            raise ValueError(f'damping must be a scalar or {m} values, got {zeta}') from None
        if not np.all(np.isfinite(zeta)) or np.any(zeta < 0.0) or np.any(zeta > 1.0):
            raise ValueError(f'damping must be in [0, 1], got {zeta}')
        self.coupling, self.frequencies_hz, self.damping = f, freq, zeta

    @property
    def n(self) -> int:
        """Number of modes ``m``."""
        return self.coupling.shape[1]


@dataclass
class FrameEnvironment:
    """Environment at the start ``t_k`` of a frame, (E6), (E7), all (3,) ECI: ``r_eci`` [m],
    ``v_eci`` [m/s], ``b_eci`` [T], ``b_dot_eci`` [T/s] along the trajectory, optional
    ``b_ddot_eci`` [T/s^2], ``b_dddot_eci`` [T/s^3] (``None``: from the previous frame (E8))."""

    r_eci: np.ndarray
    v_eci: np.ndarray = field(default_factory=_zeros3)
    b_eci: np.ndarray = field(default_factory=_zeros3)
    b_dot_eci: np.ndarray = field(default_factory=_zeros3)
    b_ddot_eci: Optional[np.ndarray] = None
    b_dddot_eci: Optional[np.ndarray] = None


@dataclass
class ActuatorCommand:
    """Actuator request held over a frame: ``dipole_body`` (3,) [A m^2], ``wheel_torque``
    (n_wheels,) [N m] motor torques (length 0: zero), ``torque_body`` (3,) [N m] ideal
    external torque (thrusters, test torques), body axes."""

    dipole_body: np.ndarray = field(default_factory=_zeros3)
    wheel_torque: np.ndarray = field(default_factory=lambda: np.zeros(0))
    torque_body: np.ndarray = field(default_factory=_zeros3)


def hermite_field_derivatives(b_prev, b_dot_prev, b, b_dot, tau: float
                              ) -> tuple[np.ndarray, np.ndarray]:
    """``(b_ddot [T/s^2], b_dddot [T/s^3])`` (3,) each, at ``t``, of the cubic Hermite
    polynomial (E8) through the field [T] and its rate [T/s] (3,) ECI at ``t - tau`` and ``t``
    (``tau > 0`` [s])."""
    tau = float(tau)
    if not (tau > 0.0 and math.isfinite(tau)):
        raise ValueError(f'tau must be > 0 and finite, got {tau}')
    c = np.empty((2, 3))
    kernels.hermite_terms(_vec(b_prev, 'b_prev'), _vec(b_dot_prev, 'b_dot_prev'),
                          _vec(b, 'b'), _vec(b_dot, 'b_dot'), tau, c)
    return 2.0 * c[0], 6.0 * c[1]


def propagate_environment(env: FrameEnvironment, ds: float,
                          mu: float = MU_EARTH) -> FrameEnvironment:
    """``env`` moved by ``ds`` [s] (a late sample): ``r, v`` along the two-body orbit (E6),
    RK4 steps of at most 1 s; ``b`` along ``b + b_dot ds``."""
    r = np.asarray(env.r_eci, dtype=float)
    v = np.asarray(env.v_eci, dtype=float)
    if ds and r.any():
        r, v = kernels.propagate_two_body(r, v, float(ds), float(mu),
                                          max(1, int(math.ceil(abs(ds)))))
    b_dot = np.asarray(env.b_dot_eci, dtype=float)
    return FrameEnvironment(r_eci=r, v_eci=v, b_eci=np.asarray(env.b_eci, float) + b_dot * ds,
                            b_dot_eci=b_dot)


def _vec(value, name: str, n: int = 3) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n,):
        raise ValueError(f'{name} must have shape ({n},), got {arr.shape}')
    if not np.isfinite(arr).all():
        raise ValueError(f'{name} is not finite: {arr}')
    return arr


_kernel_loaded = False


def _load_kernel() -> None:
    """Compile ``kernels.frame_step`` (or load it from numba's cache) once per process, when
    the first :class:`Spacecraft` is built: at start-up, not in the first frame."""
    global _kernel_loaded
    if _kernel_loaded:
        return
    x = np.zeros(kernels.state_size(0))
    x[3], x[7] = 1.0, 7.0e6
    eye = np.eye(3)
    kernels.frame_step(x, 1.0, 1, eye, eye, np.zeros((3, 0)), np.zeros((3, 0)), np.zeros(0),
                       np.zeros(0), MU_EARTH, True, np.zeros(3), np.zeros(0), np.zeros(0),
                       np.zeros(6), np.zeros(0), np.zeros((1, 3)), np.zeros((4, 3)),
                       np.zeros((2, 3)), 0.0, np.empty(kernels.OUT_TAU_W))
    _kernel_loaded = True


class Spacecraft:
    """Spacecraft with optional magnetorquers, reaction wheels, flexible modes, disturbances.

    ``inertia`` (3, 3) [kg m^2] about the centre of mass, body axes, SPD, without the rotors'
    axial inertia (with ``flexible``, (E2f), (E9), the whole ``I_b``, and ``I_b - F F^T`` SPD);
    ``magnetorquer`` (none: zero dipole), ``wheels``, ``wheel_error`` (W5) per wheel;
    ``disturbances``: ``torque(t) -> (3,)`` [N m] body axes; ``gravity_gradient``: (D1) on;
    ``mu`` [m^3/s^2] of (D1) and (E6); ``field_history``: the previous frame's field for the
    cubic (E8), else the line. ``ValueError`` on an invalid argument.
    """

    def __init__(self, inertia, magnetorquer: Magnetorquer | None = None,
                 wheels: WheelCluster | None = None, disturbances: Sequence = (),
                 gravity_gradient: bool = True, mu: float = MU_EARTH,
                 field_history: bool = True, flexible: FlexibleModes | None = None,
                 wheel_error: WheelMomentumError | None = None) -> None:
        self.inertia = check_inertia(inertia)
        self.inertia_inv = np.linalg.inv(self.inertia)
        if flexible is not None and not isinstance(flexible, FlexibleModes):
            raise ValueError(f'flexible must be FlexibleModes or None, got {flexible!r}')
        self.flexible = flexible
        self.n_modes = flexible.n if flexible is not None else 0
        m = self.n_modes
        coupling = flexible.coupling if flexible is not None else np.zeros((3, 0))
        hub = self.inertia - coupling @ coupling.T
        if m and np.linalg.eigvalsh(0.5 * (hub + hub.T))[0] <= 0.0:
            raise ValueError('hub inertia I_b - F F^T is not positive definite: the modal '
                             'coupling is too large for this inertia')
        mass = np.eye(3 + m)
        mass[:3, :3] = self.inertia
        mass[:3, 3:] = coupling
        mass[3:, :3] = coupling.T
        self.mass = mass
        self._mass_inv_c = np.ascontiguousarray(
            np.linalg.inv(mass) if m else self.inertia_inv)
        self._coupling_c = np.ascontiguousarray(coupling)
        lam = (2.0 * math.pi * flexible.frequencies_hz if flexible is not None else np.zeros(0))
        self._modal_k = np.ascontiguousarray(lam ** 2)
        self._modal_c = np.ascontiguousarray(
            2.0 * flexible.damping * lam if flexible is not None else np.zeros(0))
        if wheel_error is not None:
            if not isinstance(wheel_error, WheelMomentumError):
                raise ValueError(f'wheel_error must be a WheelMomentumError, got {wheel_error!r}')
            if wheels is None or wheel_error.n != wheels.n:
                raise ValueError('wheel_error needs wheels and one entry per wheel')
        self.wheel_error = wheel_error
        if magnetorquer is not None and not isinstance(magnetorquer, Magnetorquer):
            raise ValueError(f'magnetorquer must be a Magnetorquer or None, got {magnetorquer!r}')
        if wheels is not None and not isinstance(wheels, WheelCluster):
            raise ValueError(f'wheels must be a WheelCluster or None, got {wheels!r}')
        for d in disturbances:
            if not isinstance(d, Disturbance):
                raise ValueError(f'disturbance {d!r} has no torque(t) method')
        if not (mu > 0.0 and math.isfinite(mu)):
            raise ValueError(f'mu must be > 0 and finite, got {mu}')
        self.magnetorquer = magnetorquer
        self.wheels = wheels
        self.disturbances = list(disturbances)
        self.gravity_gradient = bool(gravity_gradient)
        self.mu = float(mu)
        self.field_history = bool(field_history)
        self.n_wheels = wheels.n if wheels is not None else 0
        self._A = np.ascontiguousarray(wheels.A if wheels is not None else np.zeros((3, 0)))
        # kernel constants (contiguous float64: one compiled specialisation)
        self._inertia_c = np.ascontiguousarray(self.inertia)
        self._inertia_inv_c = np.ascontiguousarray(self.inertia_inv)
        self._dipole_max = (np.array(magnetorquer.max_dipole_Am2, dtype=float)
                            if magnetorquer is not None else np.zeros(3))
        if wheels is not None:
            self._wheel_max_torque = np.array(wheels.max_torque, dtype=float)
            self._wheel_max_momentum = np.array(wheels.max_momentum, dtype=float)
        else:
            self._wheel_max_torque = self._wheel_max_momentum = np.zeros(0)
        self._no_dist: dict[int, np.ndarray] = {}
        self._field_prev: Optional[tuple] = None     # (t, dt, [b, b_dot]) of the last frame
        self._zero_wheels = np.zeros(self.n_wheels)
        self._x_shape = (kernels.state_size(self.n_wheels, self.n_modes),)
        self._part_lens = (4, 3, 3, 3, self.n_wheels, m, m, 3, 3, self.n_wheels, 3, 3)
        self._eta_sl, self._eta_dot_sl = kernels.modal_slices(self.n_wheels, m)
        self._u_shape = (6 + self.n_wheels,)
        _load_kernel()

    # ----------------------------------------------------------------- validation (edges)
    def check_state(self, state: SpacecraftState) -> None:
        """Raise ``ValueError`` unless ``state`` is finite, shaped for this spacecraft and
        has a non-zero quaternion."""
        q = _vec(state.q_eci_body, 'q_eci_body', 4)
        if q @ q < 1e-12:
            raise ValueError('q_eci_body has zero norm')
        _vec(state.omega_body_eci_body, 'omega_body_eci_body')
        _vec(state.h_wheels, 'h_wheels', self.n_wheels)
        _vec(state.eta, 'eta', self.n_modes)
        _vec(state.eta_dot, 'eta_dot', self.n_modes)

    def zero_state(self, q_eci_body, omega_body_eci_body, h_wheels=None) -> SpacecraftState:
        """A state with the given attitude, rate and wheel momenta (zero if omitted) and the
        modes at rest (``eta = eta_dot = 0``), sized for this spacecraft."""
        h = np.zeros(self.n_wheels) if h_wheels is None else h_wheels
        return SpacecraftState(q_eci_body, omega_body_eci_body, h, np.zeros(self.n_modes),
                               np.zeros(self.n_modes))

    def zero_command(self) -> ActuatorCommand:
        """An all-zero :class:`ActuatorCommand` sized for this spacecraft."""
        return ActuatorCommand(wheel_torque=np.zeros(self.n_wheels))

    def reset_field_history(self) -> None:
        """Forget the previous frame's field: the next frame uses the line (E7)."""
        self._field_prev = None

    def _check_env(self, r_eci, v_eci, b_eci, b_dot_eci) -> tuple:
        env = (_vec(r_eci, 'r_eci'), _vec(v_eci, 'v_eci'), _vec(b_eci, 'b_eci'),
               _vec(b_dot_eci, 'b_dot_eci'))
        if self.gravity_gradient and not env[0].any():
            raise ValueError('r_eci must not be zero with gravity gradient on')
        return env

    def _wheel_command(self, command: ActuatorCommand) -> np.ndarray:
        cmd_w = np.asarray(command.wheel_torque, dtype=float).reshape(-1)
        if cmd_w.size == 0:
            return np.zeros(self.n_wheels)
        return _vec(cmd_w, 'wheel_torque', self.n_wheels)

    def _state_of(self, x: np.ndarray) -> SpacecraftState:
        """:class:`SpacecraftState` of a kernel state (copies)."""
        return SpacecraftState(x[kernels.Q].copy(), x[kernels.W].copy(),
                               x[kernels.H0:kernels.H0 + self.n_wheels].copy(),
                               x[self._eta_sl].copy(), x[self._eta_dot_sl].copy())

    def _frame_inputs(self, state: SpacecraftState, env: FrameEnvironment,
                      command: ActuatorCommand) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Validated kernel state (N,), command ``u`` (6 + n,) and field ``[b, b_dot]`` (2, 3).

        One finiteness check over everything; only when it fails (or a shape is wrong) the
        per-item checks run, to name the culprit in the ``ValueError``.
        """
        wheel_cmd = command.wheel_torque
        if np.size(wheel_cmd) == 0:
            wheel_cmd = self._zero_wheels
        parts = (state.q_eci_body, state.omega_body_eci_body, env.r_eci, env.v_eci,
                 state.h_wheels, state.eta, state.eta_dot, command.dipole_body,
                 command.torque_body, wheel_cmd, env.b_eci, env.b_dot_eci)
        try:
            ok = tuple(map(len, parts)) == self._part_lens
            if ok:
                flat = np.concatenate(parts, dtype=float)
                ok = flat.ndim == 1 and bool(np.isfinite(flat).all())
        except (ValueError, TypeError):
            ok = False
        if not ok:                                   # find and name the bad item
            self.check_state(state)
            self._check_env(env.r_eci, env.v_eci, env.b_eci, env.b_dot_eci)
            _vec(command.dipole_body, 'dipole_body')
            _vec(command.torque_body, 'torque_body')
            self._wheel_command(command)
            raise ValueError('inputs of wrong shape or type')      # pragma: no cover
        n_x, n_u = self._x_shape[0], self._u_shape[0]
        x, u = flat[:n_x], flat[n_x:n_x + n_u]
        field = flat[n_x + n_u:].reshape(2, 3)
        q = x[kernels.Q]
        if q @ q < 1e-12:
            raise ValueError('q_eci_body has zero norm')
        if self.gravity_gradient and not x[kernels.R].any():
            raise ValueError('r_eci must not be zero with gravity gradient on')
        return x, u, field

    def _field_terms(self, t: float, dt: float, env: FrameEnvironment,
                     field: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Kernel field arguments ``(b_coef (4, 3), b_prev (2, 3), tau_prev)`` of (E7), (E8):
        explicit higher terms from ``env``, else the previous frame's field when this frame
        follows it, else the line."""
        coef = np.zeros((4, 3))
        coef[0:2] = field
        prev, self._field_prev = self._field_prev, (t, dt, field)
        if env.b_ddot_eci is not None or env.b_dddot_eci is not None:
            if env.b_ddot_eci is not None:
                coef[2] = 0.5 * _vec(env.b_ddot_eci, 'b_ddot_eci')
            if env.b_dddot_eci is not None:
                coef[3] = _vec(env.b_dddot_eci, 'b_dddot_eci') / 6.0
        elif self.field_history and prev is not None:
            t_prev, tau, field_prev = prev
            if abs(t_prev + tau - t) <= 1e-9 * tau:          # consecutive frames only
                return coef, field_prev, tau
        return coef, field, 0.0

    def _disturbance_table(self, t: float, h: float, substeps: int) -> np.ndarray:
        """Disturbance torque of each substep, sampled at its midpoint (substeps, 3) [N m]."""
        if not self.disturbances:
            table = self._no_dist.get(substeps)
            if table is None:
                table = self._no_dist[substeps] = np.zeros((substeps, 3))
            return table
        table = np.zeros((substeps, 3))
        for d in self.disturbances:
            if type(d) is ConstantTorque:
                table += d.torque_body
            elif type(d) is RandomTorque:          # one draw per hold period, compiled
                d.add_to(table, t, h)
            else:
                for i in range(substeps):
                    table[i] += d.torque(t + i * h + 0.5 * h)
        return table

    def step(self, state: SpacecraftState, t: float, dt: float, env: FrameEnvironment,
             command: ActuatorCommand, substeps: int = 1) -> tuple[SpacecraftState, dict]:
        """Integrate one frame from ``t`` to ``t + dt`` [s] (``> 0``) with ``command`` held.

        The command is saturated once, at ``t`` (the wheel torque so that no wheel passes its
        momentum limit within ``dt``); the orbit follows (E6), the field (E7), (E8); RK4 with
        ``substeps`` (>= 1) substeps. ``env`` is the environment at ``t``.

        Returns the state at ``t + dt`` and what acted, body axes: ``dipole_body`` (3,)
        [A m^2] and ``wheel_torque`` (n,) [N m] (with (W5)) after the limits, held;
        ``torque_ideal_body``, ``torque_wheels_body`` (``-A tau_w``), ``torque_disturbance_body``
        (the first substep's); at ``t``: ``torque_gg_body``, ``torque_magnetic_body``,
        ``torque_external_body`` (all but the wheels), ``torque_body`` [N m]; with wheels the
        driver status (n,) bool ``torque_limited`` (W4) and ``momentum_limited``.
        """
        t, dt = float(t), float(dt)
        if not (math.isfinite(t) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f't must be finite and dt > 0, got t={t}, dt={dt}')
        substeps = integer(substeps, 'substeps')
        x, u, field = self._frame_inputs(state, env, command)
        coef, b_prev, tau_prev = self._field_terms(t, dt, env, field)
        tau_dist = self._disturbance_table(t, dt / substeps, substeps)
        n = self.n_wheels
        out = np.empty(kernels.OUT_TAU_W + 2 * n)
        wheel_extra = (self.wheel_error.torque(t) if self.wheel_error is not None
                       else self._zero_wheels)
        kernels.frame_step(x, dt, substeps, self._inertia_c, self._mass_inv_c, self._A,
                           self._coupling_c, self._modal_c, self._modal_k, self.mu,
                           self.gravity_gradient, self._dipole_max, self._wheel_max_torque,
                           self._wheel_max_momentum, u, wheel_extra, tau_dist, coef, b_prev,
                           tau_prev, out)
        return self._state_of(x), self._applied(u, tau_dist, out)

    def _applied(self, u: np.ndarray, tau_dist: np.ndarray, out: np.ndarray) -> dict:
        """The ``applied`` dict of :meth:`step` from the kernel's outputs ``out``."""
        n = self.n_wheels
        tau_ideal = u[3:6]
        tau_dist_first = tau_dist[0].copy()
        tau_wheels = out[kernels.OUT_WHEELS_BODY]
        tau_external = tau_ideal + tau_dist_first + out[kernels.OUT_GG] + out[kernels.OUT_MAG]
        applied = {
            'dipole_body': out[kernels.OUT_DIPOLE],
            'wheel_torque': out[kernels.OUT_TAU_W:kernels.OUT_TAU_W + n],
            'torque_ideal_body': tau_ideal,
            'torque_wheels_body': tau_wheels,
            'torque_disturbance_body': tau_dist_first,
            'torque_gg_body': out[kernels.OUT_GG],
            'torque_magnetic_body': out[kernels.OUT_MAG],
            'torque_external_body': tau_external,
            'torque_body': tau_external + tau_wheels,
        }
        if n:
            cmd_w = u[6:6 + n]
            limited = out[kernels.OUT_TAU_W + n:]              # after (W4) and the h limit
            clipped = np.minimum(np.maximum(cmd_w, -self._wheel_max_torque),
                                 self._wheel_max_torque)
            applied['torque_limited'] = np.abs(cmd_w) > self._wheel_max_torque
            applied['momentum_limited'] = limited != clipped
        return applied
