"""Attitude dynamics of the simulated spacecraft: rigid body, reaction wheels, flexible modes.

Equations
---------
State ``x = [q_eci_body (4, scalar last), omega_body_eci_body (3), h_wheels (n)]``.
``I`` is the inertia of the spacecraft without the rotors' axial inertia, ``A`` (3, n) the
wheel spin axes in body axes, ``h_w`` the wheels' axial momentum (see ``actuators``)::

    dq_eci_body/dt = 1/2 q_eci_body (x) [omega, 0]                                       (E1)
    I domega/dt    = -omega x (I omega + A h_w) + tau_ext - A tau_w                      (E2)
    dh_w/dt        = tau_w                                                               (E3)
    tau_ext        = tau_gg + m x b_body + tau_ideal + sum(tau_disturbance)              (E4)

(E2) is paper 001 eq. (6) and paper 000 eq. (1) with wheels; (E4) uses
``disturbances.gravity_gradient_torque`` (D1) and ``actuators`` (A1).
Without external torque the inertial angular momentum ``R(q) (I omega + A h_w)`` is constant,
and without wheels also the kinetic energy ``1/2 omega . I omega``.

Flexible appendages (optional, :class:`FlexibleModes`; paper 001 Sec. 6, the hybrid form of
``sim_node.models.flexible`` (H1)-(H2), ASSUMPTION: the paper writes no equations). ``I`` is
then the whole spacecraft's inertia ``I_b``, ``F`` (3, m) the rotational coupling of the
modes, ``eta`` (m,) the modal coordinates [kg^1/2 m], ``Lambda = 2 pi diag(f)``::

    I domega/dt + F eta_ddot = -omega x (I omega + F eta_dot + A h_w) + tau_ext - A tau_w  (E2f)
    eta_ddot + 2 zeta Lambda eta_dot + Lambda^2 eta + F^T domega/dt = 0                    (E9)

solved together with the constant mass matrix ``[[I, F], [F^T, E_m]]``. Without damping and
torques the energy ``1/2 [omega; eta_dot]^T M [omega; eta_dot] + 1/2 eta^T Lambda^2 eta`` and
``R(q) (I omega + F eta_dot + A h_w)`` are conserved.

Wheel momentum control error (optional, ``actuators.WheelMomentumError`` (W5), paper 001:
0.01 N m s 3-sigma): an extra motor torque held over the frame, added after the limits (W4)
and clipped to the torque and momentum limits again.

Frame step (DESIGN section 6): from ``t_k`` to ``t_k + dt`` the command is held (zero-order
hold). The environment at ``t_k`` (the orbit model's ``r, v`` and the field model's ``b`` and
``b_dot``) is carried through the frame, ``s = t - t_k``, as follows:

* Orbit: two-body motion integrated with the attitude in the same RK4 stages (E6), so the
  position at every stage lies on the orbit, not on the straight line ``r + v s``::

      dr_eci/dt = v_eci,   dv_eci/dt = -mu r_eci / |r_eci|^3                             (E6)

  For the Keplerian circular orbit this *is* the orbit model (RK4 truncation at a 0.1 s
  substep: < 1e-9 m per frame). For SGP4 it leaves out the perturbations inside one frame
  (J2 about 1e-2 m/s^2: < 1 m, 1e-7 rad of direction, over a 10 s frame); the next frame
  starts again from the orbit model.
* Field: a cubic in ``s`` (E7). With only ``b, b_dot`` it is the line ``b + b_dot s``. A
  straight line biases ``|b|``: the field seen on an orbit turns at about twice the orbit
  rate ``n``, so the line is off by ``(2 n s)^2 / 2`` relative at ``s`` (2e-4 at the end of a
  10 s frame, 7e-5 on average, always with the same sign). :class:`Spacecraft` therefore
  fits, when consecutive frames are stepped, the cubic Hermite polynomial through
  ``(b, b_dot)`` at ``t_{k-1}`` and ``t_k`` and extrapolates it over the frame (E8); its
  error is ``b''''/24 (s + tau)^2 s^2`` (about ``(2 n dt)^4 / 6`` relative at the frame end:
  3e-8 at 10 s, 3e-12 at 1 s frames)::

      b_eci(t_k + s) = b + b_dot s + b_ddot s^2 / 2 + b_dddot s^3 / 6                    (E7)
      tau = t_k - t_{k-1},  D = b_k - b_{k-1}                                             (E8)
      b_ddot  = 2 [(2 b_dot_k + b_dot_{k-1}) / tau - 3 D / tau^2]
      b_dddot = 6 [(b_dot_k + b_dot_{k-1}) / tau^2 - 2 D / tau^3]

  ASSUMPTION: the first frame and any frame after a gap (not consecutive with the previous
  step, or :meth:`Spacecraft.reset_field_history`) use the line. The dynamics node cannot
  see the field at ``t_{k+1}`` before it integrates frame k, so the cubic interpolates the
  past instead of interpolating between the frame's ends.

Integration: classical fixed-step RK4 with ``substeps`` equal substeps, compiled with numba in
``kernels.frame_step`` (one call per frame; the same function runs as Python with
``NUMBA_DISABLE_JIT=1``); the quaternion is renormalised after each substep; disturbance
torques are sampled at each substep's midpoint and held over it. Inputs are validated once per
frame, never inside the substep loop.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from sim_node.models import kernels
from sim_node.models.actuators import Magnetorquer, WheelCluster, WheelMomentumError
from sim_node.models.disturbances import (MU_EARTH, ConstantTorque, Disturbance, RandomTorque,
                                          check_inertia)


def _zeros3() -> np.ndarray:
    return np.zeros(3)


@dataclass
class SpacecraftState:
    """Dynamic state of the spacecraft.

    Attributes
    ----------
    q_eci_body : numpy.ndarray, shape (4,)
        Attitude, scalar last, rotates body components into ECI.
    omega_body_eci_body : numpy.ndarray, shape (3,)
        Rate of the body w.r.t. ECI, body axes [rad/s].
    h_wheels : numpy.ndarray, shape (n_wheels,)
        Wheel momentum about each spin axis [N m s]; length 0 without wheels.
    eta, eta_dot : numpy.ndarray, shape (n_modes,)
        Modal coordinates [kg^1/2 m] and their rates [kg^1/2 m/s] of the flexible
        appendages (:class:`FlexibleModes`); length 0 for a rigid spacecraft.
    """

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
    """Flexible appendages as modes in hybrid coordinates, (E2f), (E9).

    Attributes
    ----------
    coupling : numpy.ndarray, shape (3, m)
        Rotational coupling ``F`` of all modes, body axes [kg^1/2 m].
    frequencies_hz : numpy.ndarray, shape (m,)
        Constrained-hub modal frequencies [Hz], > 0.
    damping : numpy.ndarray, shape (m,)
        Modal damping ratios ``zeta`` in [0, 1) (a scalar is broadcast).

    Raises
    ------
    ValueError
        On bad shapes, non-finite values, frequencies <= 0 or damping outside [0, 1).
    """

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
        if not np.all(np.isfinite(zeta)) or np.any(zeta < 0.0) or np.any(zeta >= 1.0):
            raise ValueError(f'damping must be in [0, 1), got {zeta}')
        self.coupling, self.frequencies_hz, self.damping = f, freq, zeta

    @property
    def n(self) -> int:
        """Number of modes ``m``."""
        return self.coupling.shape[1]


@dataclass
class FrameEnvironment:
    """Environment at the start ``t_k`` of a frame, with the rates that carry it (E6), (E7).

    Attributes
    ----------
    r_eci : numpy.ndarray, shape (3,)
        Position [m], ECI.
    v_eci : numpy.ndarray, shape (3,)
        Velocity [m/s], ECI.
    b_eci : numpy.ndarray, shape (3,)
        Geomagnetic field [T], ECI.
    b_dot_eci : numpy.ndarray, shape (3,)
        Time derivative of ``b_eci`` along the trajectory [T/s], ECI.
    b_ddot_eci, b_dddot_eci : numpy.ndarray, shape (3,), optional
        Second and third derivatives [T/s^2], [T/s^3], ECI, for (E7). ``None`` (the default)
        lets :meth:`Spacecraft.step` take them from the previous frame (E8), or zero.
    """

    r_eci: np.ndarray
    v_eci: np.ndarray = field(default_factory=_zeros3)
    b_eci: np.ndarray = field(default_factory=_zeros3)
    b_dot_eci: np.ndarray = field(default_factory=_zeros3)
    b_ddot_eci: Optional[np.ndarray] = None
    b_dddot_eci: Optional[np.ndarray] = None


@dataclass
class ActuatorCommand:
    """Actuator request, held constant over a frame.

    Attributes
    ----------
    dipole_body : numpy.ndarray, shape (3,)
        Magnetorquer dipole [A m^2], body axes.
    wheel_torque : numpy.ndarray, shape (n_wheels,) or (0,)
        Motor torque on each wheel [N m]; length 0 means zero for every wheel.
    torque_body : numpy.ndarray, shape (3,)
        Ideal external torque [N m], body axes (thrusters, test torques).
    """

    dipole_body: np.ndarray = field(default_factory=_zeros3)
    wheel_torque: np.ndarray = field(default_factory=lambda: np.zeros(0))
    torque_body: np.ndarray = field(default_factory=_zeros3)


def hermite_field_derivatives(b_prev, b_dot_prev, b, b_dot, tau: float
                              ) -> tuple[np.ndarray, np.ndarray]:
    """``(b_ddot, b_dddot)`` at the right end of the cubic Hermite polynomial (E8).

    Parameters
    ----------
    b_prev, b_dot_prev : numpy.ndarray, shape (3,)
        Field [T] and its rate [T/s] at ``t - tau``, ECI.
    b, b_dot : numpy.ndarray, shape (3,)
        Field [T] and its rate [T/s] at ``t``, ECI.
    tau : float
        Time between the two samples [s], ``> 0``.

    Returns
    -------
    tuple of numpy.ndarray, shape (3,)
        Second [T/s^2] and third [T/s^3] derivative of the cubic at ``t``.
    """
    tau = float(tau)
    if not (tau > 0.0 and math.isfinite(tau)):
        raise ValueError(f'tau must be > 0 and finite, got {tau}')
    c = np.empty((2, 3))
    kernels.hermite_terms(_vec(b_prev, 'b_prev'), _vec(b_dot_prev, 'b_dot_prev'),
                          _vec(b, 'b'), _vec(b_dot, 'b_dot'), tau, c)
    return 2.0 * c[0], 6.0 * c[1]


def propagate_environment(env: FrameEnvironment, ds: float,
                          mu: float = MU_EARTH) -> FrameEnvironment:
    """``env`` moved by ``ds`` [s]: ``r, v`` along the two-body orbit (E6), ``b`` along its
    line ``b + b_dot ds`` (higher field terms dropped: they are not meant for long spans).

    For an environment sample that is late (a timeout, real-time mode); RK4 steps of at most
    1 s.
    """
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


def _body_from_eci(qx: float, qy: float, qz: float, qw: float) -> tuple:
    """``R(q / |q|)^T`` as a row-major 9-tuple: ECI components to body components."""
    k = 2.0 / (qx * qx + qy * qy + qz * qz + qw * qw)
    return (1.0 - k * (qy * qy + qz * qz), k * (qx * qy + qz * qw), k * (qx * qz - qy * qw),
            k * (qx * qy - qz * qw), 1.0 - k * (qx * qx + qz * qz), k * (qy * qz + qx * qw),
            k * (qx * qz + qy * qw), k * (qy * qz - qx * qw), 1.0 - k * (qx * qx + qy * qy))


_kernel_loaded = False


def _load_kernel() -> None:
    """Compile ``kernels.frame_step`` (or load it from numba's cache) now, once per process.

    Called when the first :class:`Spacecraft` is built, so a node pays the ~0.15 s CPU of
    loading the compiled frame while it starts (in parallel with the other nodes' start-up
    and discovery) rather than in its first frame, on the lockstep's critical path.
    """
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

    Parameters
    ----------
    inertia : array_like, shape (3, 3)
        Inertia about the centre of mass, body axes [kg m^2], without the rotors' axial
        inertia; symmetric positive definite. With ``flexible``: the whole spacecraft's
        ``I_b`` (appendages included, undeformed); ``I_b - F F^T`` must be positive definite.
    magnetorquer : Magnetorquer, optional
        Without it, dipole commands are ignored (the applied dipole is zero).
    wheels : WheelCluster, optional
        Without it, the state and commands have no wheel entries.
    disturbances : sequence of Disturbance
        Objects with ``torque(t) -> (3,)`` [N m], body axes (``ConstantTorque``,
        ``RandomTorque``...).
    gravity_gradient : bool
        Include the gravity-gradient torque (D1).
    mu : float
        Gravitational parameter [m^3/s^2] for (D1) and the orbit (E6).
    field_history : bool
        Use the previous frame's field for the cubic (E8) when frames are consecutive;
        ``False``: the line ``b + b_dot s`` in every frame.
    flexible : FlexibleModes, optional
        Modes of flexible appendages (E2f), (E9); without it the body is rigid.
    wheel_error : WheelMomentumError, optional
        Momentum control error of the wheels (W5) (needs ``wheels``, one entry per wheel).

    Raises
    ------
    ValueError
        On an invalid inertia, actuator, disturbance or modes object, or ``mu``, or a
        coupling too large for the inertia.
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

    def _kernel_state(self, state: SpacecraftState, r_eci, v_eci) -> np.ndarray:
        """Kernel state (``kernels`` layout) of ``state`` at the position ``r_eci``, ``v_eci``."""
        x = np.empty(self._x_shape[0])
        x[kernels.Q] = state.q_eci_body
        x[kernels.W] = state.omega_body_eci_body
        x[kernels.R] = r_eci
        x[kernels.V] = v_eci
        x[kernels.H0:kernels.H0 + self.n_wheels] = state.h_wheels
        x[self._eta_sl] = state.eta
        x[self._eta_dot_sl] = state.eta_dot
        return x

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

    def _disturbance_torque(self, t: float) -> np.ndarray:
        tau = np.zeros(3)
        for d in self.disturbances:
            tau += d.torque(t)
        return tau

    # ---------------------------------------------------------------------- the model
    def derivative(self, t: float, state: SpacecraftState, env_at_t: tuple,
                   applied: ActuatorCommand) -> SpacecraftState:
        """Right-hand side (E1)-(E4) at one instant.

        Parameters
        ----------
        t : float
            Time [s] since the scenario epoch (for the disturbances).
        state : SpacecraftState
            State at ``t``.
        env_at_t : tuple of numpy.ndarray
            ``(r_eci [m], b_eci [T])`` at ``t``, ECI.
        applied : ActuatorCommand
            Actuation taken as applied as given (no saturation): dipole [A m^2], motor torque
            per wheel [N m], ideal torque [N m].

        Returns
        -------
        SpacecraftState
            The derivative: ``q_eci_body`` holds ``dq/dt`` [1/s], ``omega_body_eci_body``
            holds ``domega/dt`` [rad/s^2], ``h_wheels`` holds ``dh_w/dt`` [N m], ``eta`` and
            ``eta_dot`` hold ``d eta/dt`` and ``d^2 eta/dt^2``.
        """
        self.check_state(state)
        r_eci, b_eci = env_at_t
        r_eci, _, b_eci, _ = self._check_env(r_eci, np.zeros(3), b_eci, np.zeros(3))
        tau_w = self._wheel_command(applied)
        tau_held = (_vec(applied.torque_body, 'torque_body') + self._disturbance_torque(t)
                    - self._A @ tau_w)
        dipole = _vec(applied.dipole_body, 'dipole_body')
        coef = np.zeros((4, 3))
        coef[0] = b_eci
        x = self._kernel_state(state, r_eci, np.zeros(3))
        x_dot = np.empty_like(x)
        kernels.rhs(0.0, x, self._inertia_c, self._mass_inv_c, self._A, self._coupling_c,
                    self._modal_c, self._modal_k, self.mu, self.gravity_gradient,
                    bool(dipole.any()), dipole, coef, tau_held, tau_w,
                    np.empty(9 + self.n_modes), x_dot)
        return self._state_of(x_dot)

    def step(self, state: SpacecraftState, t: float, dt: float, env: FrameEnvironment,
             command: ActuatorCommand, substeps: int = 1) -> tuple[SpacecraftState, dict]:
        """Integrate one frame from ``t`` to ``t + dt`` with the command held constant.

        The command is saturated by the actuators once, at ``t`` (the wheel torque so that no
        wheel passes its momentum limit within ``dt``), then held; the orbit follows (E6), the
        field (E7) (with (E8) when this frame follows the previous call's frame); fixed RK4
        with ``substeps`` equal substeps, quaternion renormalised after each, all in one
        compiled call (``kernels.frame_step``).

        Parameters
        ----------
        state : SpacecraftState
            State at ``t``.
        t : float
            Frame start [s] since the scenario epoch.
        dt : float
            Frame length [s], ``> 0``.
        env : FrameEnvironment
            Environment at ``t`` with its rates.
        command : ActuatorCommand
            Requested actuation.
        substeps : int
            Number of RK4 substeps, ``>= 1``.

        Returns
        -------
        state : SpacecraftState
            State at ``t + dt``.
        applied : dict of numpy.ndarray
            What acted during the frame, body axes: ``dipole_body`` (3,) [A m^2] and
            ``wheel_torque`` (n,) [N m] after the limits, held; ``torque_ideal_body``,
            ``torque_wheels_body`` (``-A tau_w``) held, ``torque_disturbance_body`` (held over
            the first substep), and at ``t``: ``torque_gg_body``, ``torque_magnetic_body``,
            ``torque_external_body`` (all but the wheels) and ``torque_body`` (total) [N m].
            With wheels also the driver status (n,) bool: ``torque_limited`` (the command
            exceeds the torque limit (W4)) and ``momentum_limited`` (the torque is cut at the
            momentum limit: the wheel is at, or would pass within ``dt``, ``max_momentum``);
            ``wheel_torque`` includes the momentum control error (W5) if modelled.
        """
        t, dt = float(t), float(dt)
        if not (math.isfinite(t) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f't must be finite and dt > 0, got t={t}, dt={dt}')
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) \
                or substeps < 1:
            raise ValueError(f'substeps must be an integer >= 1, got {substeps!r}')
        substeps = int(substeps)
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
        return self._state_of(x), applied

    # ------------------------------------------------------------------ diagnostics
    def angular_momentum_eci(self, state: SpacecraftState) -> np.ndarray:
        """Total angular momentum ``R(q) (I omega + F eta_dot + A h_w)`` [N m s], ECI,
        shape (3,)."""
        self.check_state(state)
        h_body = (self.inertia @ state.omega_body_eci_body + self._A @ state.h_wheels
                  + self._coupling_c @ state.eta_dot)
        c = np.array(_body_from_eci(*state.q_eci_body.tolist())).reshape(3, 3)
        return c.T @ h_body

    def kinetic_energy(self, state: SpacecraftState) -> float:
        """Rotational kinetic energy of the body without rotors ``1/2 w . I w`` [J]."""
        self.check_state(state)
        w = state.omega_body_eci_body
        return 0.5 * float(w @ self.inertia @ w)

    def mechanical_energy(self, state: SpacecraftState) -> float:
        """Kinetic + modal strain energy [J] (rotor spin excluded), conserved by (E2f), (E9)
        without damping and torques: ``1/2 v^T M v + 1/2 eta^T Lambda^2 eta``,
        ``v = [omega; eta_dot]``."""
        self.check_state(state)
        v = np.concatenate((state.omega_body_eci_body, state.eta_dot))
        strain = state.eta @ (self._modal_k * state.eta)
        return 0.5 * float(v @ self.mass @ v) + 0.5 * float(strain)


def steps_per_second(n: int = 2000, substeps: int = 1) -> float:
    """Wall-clock RK4 substeps per second of :meth:`Spacecraft.step` (free body + gravity
    gradient, 0.1 s frames), a plain Python loop; a benchmark, not a test."""
    sc = Spacecraft(np.diag([118.0, 100.0, 19.6]))
    state = SpacecraftState(np.array([0.36, 0.48, -0.48, 0.64]), np.radians([-3.0, 3.0, 3.0]))
    env = FrameEnvironment(r_eci=np.array([7068.137e3, 0.0, 0.0]),
                           v_eci=np.array([0.0, 1035.0, 7436.0]))
    command = sc.zero_command()
    t, dt = 0.0, 0.1
    sc.step(state, t, dt, env, command, substeps)     # compile (or load the cache) first
    start = time.perf_counter()
    for _ in range(n):
        state, _ = sc.step(state, t, dt, env, command, substeps)
        t += dt
    return n * substeps / (time.perf_counter() - start)


if __name__ == '__main__':
    print(f'{steps_per_second():.0f} RK4 steps/s (one substep per frame, frame overhead incl.)')
    print(f'{steps_per_second(200, 10):.0f} RK4 steps/s (ten substeps per frame)')
