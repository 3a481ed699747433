"""Rigid-body attitude dynamics of the simulated spacecraft, with reaction wheels.

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

Frame step (DESIGN section 6): from ``t_k`` to ``t_k + dt`` the command is held (zero-order
hold) and the environment is extrapolated from its value and rate at ``t_k``::

    r_eci(t_k + s) = r_eci + v_eci s,     b_eci(t_k + s) = b_eci + b_dot_eci s            (E5)

Integration: classical fixed-step RK4 with ``substeps`` equal substeps; the quaternion is
renormalised after each substep; disturbance torques are sampled at each substep's midpoint
and held over it. Inputs are validated once per frame, never inside the substep loop.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from sim_node.models.actuators import Magnetorquer, WheelCluster
from sim_node.models.disturbances import MU_EARTH, Disturbance, check_inertia


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
    """

    q_eci_body: np.ndarray
    omega_body_eci_body: np.ndarray
    h_wheels: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        self.q_eci_body = np.asarray(self.q_eci_body, dtype=float)
        self.omega_body_eci_body = np.asarray(self.omega_body_eci_body, dtype=float)
        self.h_wheels = np.asarray(self.h_wheels, dtype=float).reshape(-1)


@dataclass
class FrameEnvironment:
    """Environment at the start ``t_k`` of a frame, with its rates for (E5).

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
    """

    r_eci: np.ndarray
    v_eci: np.ndarray = field(default_factory=_zeros3)
    b_eci: np.ndarray = field(default_factory=_zeros3)
    b_dot_eci: np.ndarray = field(default_factory=_zeros3)


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


def rk4_step(f: Callable[[float, np.ndarray], np.ndarray], t: float, x: np.ndarray,
             h: float) -> np.ndarray:
    """One classical Runge-Kutta step of ``dx/dt = f(t, x)``.

    Parameters
    ----------
    f : callable
        ``f(t, x) -> dx/dt``, flat arrays of the shape of ``x``.
    t : float
        Time at the start of the step [s].
    x : numpy.ndarray, shape (m,)
        State at ``t``.
    h : float
        Step [s].

    Returns
    -------
    numpy.ndarray, shape (m,)
        State at ``t + h``.
    """
    half = 0.5 * h
    k1 = f(t, x)
    k2 = f(t + half, x + half * k1)
    k3 = f(t + half, x + half * k2)
    k4 = f(t + h, x + h * k3)
    return x + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


def pack_state(state: SpacecraftState) -> np.ndarray:
    """Flat state ``[q (4), omega (3), h_wheels (n)]``, shape (7 + n,)."""
    return np.concatenate((state.q_eci_body, state.omega_body_eci_body, state.h_wheels))


def unpack_state(x: np.ndarray) -> SpacecraftState:
    """Inverse of :func:`pack_state` (copies)."""
    return SpacecraftState(x[0:4].copy(), x[4:7].copy(), x[7:].copy())


# The right-hand side works on 3-vectors as Python float tuples and (3, 3) matrices as
# row-major 9-tuples: on 3 elements a numpy call costs ~1 us of overhead, a float operation
# ~30 ns, which makes RK4 about twice as fast. Validation happens before, at the edges.
Vec3 = tuple[float, float, float]


def _matvec(m: tuple, v: Vec3) -> Vec3:
    """``M v`` for a row-major 9-tuple ``M``."""
    x, y, z = v
    return (m[0] * x + m[1] * y + m[2] * z,
            m[3] * x + m[4] * y + m[5] * z,
            m[6] * x + m[7] * y + m[8] * z)


def _cross(a: Vec3, b: Vec3) -> Vec3:
    """``a x b``."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _body_from_eci(qx: float, qy: float, qz: float, qw: float) -> tuple:
    """``R(q / |q|)^T`` as a row-major 9-tuple: ECI components to body components."""
    k = 2.0 / (qx * qx + qy * qy + qz * qz + qw * qw)
    return (1.0 - k * (qy * qy + qz * qz), k * (qx * qy + qz * qw), k * (qx * qz - qy * qw),
            k * (qx * qy - qz * qw), 1.0 - k * (qx * qx + qz * qz), k * (qy * qz + qx * qw),
            k * (qx * qz + qy * qw), k * (qy * qz - qx * qw), 1.0 - k * (qx * qx + qy * qy))


def _vec(value, name: str, n: int = 3) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n,):
        raise ValueError(f'{name} must have shape ({n},), got {arr.shape}')
    if not np.isfinite(arr).all():
        raise ValueError(f'{name} is not finite: {arr}')
    return arr


class Spacecraft:
    """Rigid spacecraft with optional magnetorquers, reaction wheels and disturbances.

    Parameters
    ----------
    inertia : array_like, shape (3, 3)
        Inertia about the centre of mass, body axes [kg m^2], without the rotors' axial
        inertia; symmetric positive definite.
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
        Gravitational parameter [m^3/s^2] for (D1).

    Raises
    ------
    ValueError
        On an invalid inertia, actuator or disturbance object, or ``mu``.
    """

    def __init__(self, inertia, magnetorquer: Magnetorquer | None = None,
                 wheels: WheelCluster | None = None, disturbances: Sequence = (),
                 gravity_gradient: bool = True, mu: float = MU_EARTH) -> None:
        self.inertia = check_inertia(inertia)
        self.inertia_inv = np.linalg.inv(self.inertia)
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
        self.n_wheels = wheels.n if wheels is not None else 0
        self._A = wheels.A if wheels is not None else np.zeros((3, 0))

    # ----------------------------------------------------------------- validation (edges)
    def check_state(self, state: SpacecraftState) -> None:
        """Raise ``ValueError`` unless ``state`` is finite, shaped for this spacecraft and
        has a non-zero quaternion."""
        q = _vec(state.q_eci_body, 'q_eci_body', 4)
        if q @ q < 1e-12:
            raise ValueError('q_eci_body has zero norm')
        _vec(state.omega_body_eci_body, 'omega_body_eci_body')
        _vec(state.h_wheels, 'h_wheels', self.n_wheels)

    def zero_command(self) -> ActuatorCommand:
        """An all-zero :class:`ActuatorCommand` sized for this spacecraft."""
        return ActuatorCommand(wheel_torque=np.zeros(self.n_wheels))

    def _saturate(self, command: ActuatorCommand, h_wheels: np.ndarray,
                  dt: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Applied (dipole_body, wheel_torque, torque_ideal_body) of a command."""
        dipole = _vec(command.dipole_body, 'dipole_body')
        if self.magnetorquer is not None:
            dipole = self.magnetorquer.apply(dipole)
        else:
            dipole = np.zeros(3)
        cmd_w = np.asarray(command.wheel_torque, dtype=float).reshape(-1)
        if cmd_w.size == 0:
            cmd_w = np.zeros(self.n_wheels)
        cmd_w = _vec(cmd_w, 'wheel_torque', self.n_wheels)
        tau_w = self.wheels.apply(cmd_w, h_wheels, dt) if self.wheels is not None else cmd_w
        return dipole, tau_w, _vec(command.torque_body, 'torque_body').copy()

    # ---------------------------------------------------------------------- the model
    def _make_rhs(self, t_k: float, r_eci: np.ndarray, v_eci: np.ndarray, b_eci: np.ndarray,
                  b_dot_eci: np.ndarray, dipole_body: np.ndarray, tau_held_body: np.ndarray,
                  tau_w: np.ndarray) -> tuple[Callable, Callable]:
        """``f(t, x)`` of (E1)-(E5) with everything but the state held fixed.

        ``tau_held_body`` [N m] is the sum of the torques that do not depend on the state:
        ideal, disturbances and the wheels' reaction ``-A tau_w``; it is read at every call, so
        the caller may update it in place between substeps. Also returns
        ``torques(q, s) -> (tau_gg, tau_magnetic)`` (tuples, body axes [N m]) at ``t_k + s``.
        """
        inertia = tuple(self.inertia.ravel().tolist())
        inertia_inv = tuple(self.inertia_inv.ravel().tolist())
        a_mat = self._A
        use_gg = self.gravity_gradient
        use_mtq = bool(np.any(dipole_body))
        use_wheels = self.n_wheels > 0
        three_mu = 3.0 * self.mu
        r0, v0 = tuple(r_eci.tolist()), tuple(v_eci.tolist())
        b0, b_dot = tuple(b_eci.tolist()), tuple(b_dot_eci.tolist())
        dipole = tuple(dipole_body.tolist())
        n_x = 7 + self.n_wheels
        zero = (0.0, 0.0, 0.0)

        def torques(q: tuple, s: float) -> tuple[Vec3, Vec3]:
            c = _body_from_eci(*q)
            tau_gg = tau_mag = zero
            if use_gg:
                r = _matvec(c, (r0[0] + s * v0[0], r0[1] + s * v0[1], r0[2] + s * v0[2]))
                r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
                k = three_mu / (r2 * r2 * math.sqrt(r2))   # (D1) with r unnormalised
                gx, gy, gz = _cross(r, _matvec(inertia, r))
                tau_gg = (k * gx, k * gy, k * gz)
            if use_mtq:
                b = _matvec(c, (b0[0] + s * b_dot[0], b0[1] + s * b_dot[1],
                                b0[2] + s * b_dot[2]))
                tau_mag = _cross(dipole, b)                  # (A1)
            return tau_gg, tau_mag

        def rhs(t: float, x: np.ndarray) -> np.ndarray:
            qx, qy, qz, qw, wx, wy, wz = x[:7].tolist()
            tx, ty, tz = tau_held_body.tolist()
            if use_gg or use_mtq:
                (gx, gy, gz), (mx, my, mz) = torques((qx, qy, qz, qw), t - t_k)
                tx += gx + mx
                ty += gy + my
                tz += gz + mz
            hx, hy, hz = _matvec(inertia, (wx, wy, wz))
            if use_wheels:
                hwx, hwy, hwz = (a_mat @ x[7:]).tolist()
                hx, hy, hz = hx + hwx, hy + hwy, hz + hwz
            gyro = _cross((wx, wy, wz), (hx, hy, hz))
            w_dot = _matvec(inertia_inv, (tx - gyro[0], ty - gyro[1], tz - gyro[2]))  # (E2)
            x_dot = np.empty(n_x)
            x_dot[:7] = (0.5 * (qw * wx + qy * wz - qz * wy),                          # (E1)
                         0.5 * (qw * wy + qz * wx - qx * wz),
                         0.5 * (qw * wz + qx * wy - qy * wx),
                         -0.5 * (qx * wx + qy * wy + qz * wz),
                         w_dot[0], w_dot[1], w_dot[2])
            x_dot[7:] = tau_w                                                           # (E3)
            return x_dot

        return rhs, torques

    def _disturbance_torque(self, t: float) -> np.ndarray:
        tau = np.zeros(3)
        for d in self.disturbances:
            tau += d.torque(t)
        return tau

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
            holds ``domega/dt`` [rad/s^2], ``h_wheels`` holds ``dh_w/dt`` [N m].
        """
        self.check_state(state)
        r_eci, b_eci = env_at_t
        r_eci, b_eci = self._check_env(r_eci, np.zeros(3), b_eci, np.zeros(3))[::2]
        wheel_torque = np.asarray(applied.wheel_torque, dtype=float).reshape(-1)
        tau_w = np.zeros(self.n_wheels) if wheel_torque.size == 0 else \
            _vec(wheel_torque, 'wheel_torque', self.n_wheels)
        tau_held = (_vec(applied.torque_body, 'torque_body') + self._disturbance_torque(t)
                    - self._A @ tau_w)
        dipole = _vec(applied.dipole_body, 'dipole_body')
        rhs, _ = self._make_rhs(t, r_eci, np.zeros(3), b_eci, np.zeros(3), dipole, tau_held,
                                tau_w)
        return unpack_state(rhs(t, pack_state(state)))

    def _check_env(self, r_eci, v_eci, b_eci, b_dot_eci) -> tuple:
        env = (_vec(r_eci, 'r_eci'), _vec(v_eci, 'v_eci'), _vec(b_eci, 'b_eci'),
               _vec(b_dot_eci, 'b_dot_eci'))
        if self.gravity_gradient and not env[0].any():
            raise ValueError('r_eci must not be zero with gravity gradient on')
        return env

    def step(self, state: SpacecraftState, t: float, dt: float, env: FrameEnvironment,
             command: ActuatorCommand, substeps: int = 1) -> tuple[SpacecraftState, dict]:
        """Integrate one frame from ``t`` to ``t + dt`` with the command held constant.

        The command is saturated by the actuators once, at ``t`` (the wheel torque so that no
        wheel passes its momentum limit within ``dt``), then held; the environment follows
        (E5); fixed RK4 with ``substeps`` equal substeps, quaternion renormalised after each.

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
        """
        t, dt = float(t), float(dt)
        if not (math.isfinite(t) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f't must be finite and dt > 0, got t={t}, dt={dt}')
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) \
                or substeps < 1:
            raise ValueError(f'substeps must be an integer >= 1, got {substeps!r}')
        self.check_state(state)
        r_eci, v_eci, b_eci, b_dot_eci = self._check_env(env.r_eci, env.v_eci, env.b_eci,
                                                         env.b_dot_eci)
        dipole, tau_w, tau_ideal = self._saturate(command, state.h_wheels, dt)
        tau_wheels = -(self._A @ tau_w)
        tau_fixed = tau_ideal + tau_wheels
        tau_held = tau_fixed.copy()
        rhs, torques = self._make_rhs(t, r_eci, v_eci, b_eci, b_dot_eci, dipole, tau_held,
                                      tau_w)

        x = pack_state(state)
        x[0:4] /= math.sqrt(x[0:4] @ x[0:4])
        tau_gg, tau_mag = torques(tuple(x[0:4].tolist()), 0.0)
        h = dt / substeps
        tau_dist_first = np.zeros(3)
        for i in range(substeps):
            t_i = t + i * h
            if self.disturbances:
                tau_dist = self._disturbance_torque(t_i + 0.5 * h)
                tau_held[:] = tau_fixed + tau_dist
                if i == 0:
                    tau_dist_first = tau_dist
            x = rk4_step(rhs, t_i, x, h)
            x[0:4] /= math.sqrt(x[0:4] @ x[0:4])

        tau_external = tau_ideal + tau_dist_first + tau_gg + tau_mag
        applied = {
            'dipole_body': dipole,
            'wheel_torque': tau_w,
            'torque_ideal_body': tau_ideal,
            'torque_wheels_body': tau_wheels,
            'torque_disturbance_body': tau_dist_first,
            'torque_gg_body': np.array(tau_gg),
            'torque_magnetic_body': np.array(tau_mag),
            'torque_external_body': tau_external,
            'torque_body': tau_external + tau_wheels,
        }
        return unpack_state(x), applied

    # ------------------------------------------------------------------ diagnostics
    def angular_momentum_eci(self, state: SpacecraftState) -> np.ndarray:
        """Total angular momentum ``R(q) (I omega + A h_w)`` [N m s], ECI, shape (3,)."""
        self.check_state(state)
        h_body = self.inertia @ state.omega_body_eci_body + self._A @ state.h_wheels
        c = np.array(_body_from_eci(*state.q_eci_body.tolist())).reshape(3, 3)
        return c.T @ h_body

    def kinetic_energy(self, state: SpacecraftState) -> float:
        """Rotational kinetic energy of the body without rotors ``1/2 w . I w`` [J]."""
        self.check_state(state)
        w = state.omega_body_eci_body
        return 0.5 * float(w @ self.inertia @ w)


def steps_per_second(n: int = 2000, substeps: int = 1) -> float:
    """Wall-clock RK4 substeps per second of :meth:`Spacecraft.step` (free body + gravity
    gradient, 0.1 s frames), a plain Python loop; a benchmark, not a test."""
    sc = Spacecraft(np.diag([118.0, 100.0, 19.6]))
    state = SpacecraftState(np.array([0.36, 0.48, -0.48, 0.64]), np.radians([-3.0, 3.0, 3.0]))
    env = FrameEnvironment(r_eci=np.array([7068.137e3, 0.0, 0.0]),
                           v_eci=np.array([0.0, 1035.0, 7436.0]))
    command = sc.zero_command()
    t, dt = 0.0, 0.1
    start = time.perf_counter()
    for _ in range(n):
        state, _ = sc.step(state, t, dt, env, command, substeps)
        t += dt
    return n * substeps / (time.perf_counter() - start)


if __name__ == '__main__':
    print(f'{steps_per_second():.0f} RK4 steps/s (one substep per frame, frame overhead incl.)')
    print(f'{steps_per_second(200, 10):.0f} RK4 steps/s (ten substeps per frame)')
