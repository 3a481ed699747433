"""Controller cores: the common interface (DESIGN section 7) and shared helpers (pure numpy).

Interface
---------
Every controller core has ``reset()`` and::

    update(inputs: ControlInputs, t, dt) -> Command

* ``inputs.estimate``: :class:`Estimate`, the flight software's attitude and rate estimate
  (orbit and inertial attitude).
* ``inputs.target``: :class:`Target`, the guidance target in its own frame (``orbit`` or
  ``eci``; ``None``: the orbital frame, zero rate).
* ``inputs.b_body``: fresh magnetometer sample, body axes, shape (3,) [T]; ``None`` when no
  new sample arrived this frame. ``inputs.b_body_model``: the onboard model field rotated
  with the estimate (``None`` without a valid estimate).
* ``inputs.wheel_speed_rad_s``: measured wheel speeds, scenario order (``None``: no
  tachometer); ``inputs.wheel_momentum_Nms``: the same times the wheel inertias.
* ``t``, ``dt``: frame time and frame period [s] (float seconds, DESIGN section 2).

A controller never raises on bad *data* (it returns a zero :class:`Command` with
``reason`` set); it raises ``ValueError`` only on bad *configuration*, at construction.
Each controller is registered once in :mod:`adcs_nodes.registry` (name, parameters with
units and ranges, inputs, actuators); nothing else in the project names it.

Direction-preserving scaling onto the actuator box (paper 000, eq. (31))::

    phi   = max_i |v_i| / l_i
    sigma = 1 if phi <= 1 else 1 / phi                                                  (31)
    v_out = sigma v

so ``|v_out,i| <= l_i`` and ``v_out`` is parallel to ``v`` (the paper's ``u_i = sigma L*_i /
l_i`` in the unit cube (6)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Optional, Protocol

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import kernels
from adcs_nodes.core.kernels import finite_vector

__all__ = ['Estimate', 'Target', 'Command', 'ControlInputs', 'Controller', 'scale_to_limits',
           'limits_vector', 'inertia_matrix', 'finite_vector', 'cross3']


def cross3(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Cross product ``a x b`` of two (3,) vectors (:func:`adcs_nodes.core.kernels.cross`)."""
    return kernels.cross(np.asarray(a, dtype=float), np.asarray(b, dtype=float))


def finite(value, name: str) -> float:
    """``value`` as a finite float; ``ValueError`` naming ``name`` if not."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be a number, got {value!r}') from None
    if not math.isfinite(x):
        raise ValueError(f'{name} must be finite, got {x}')
    return x


def positive(value, name: str, unit: str = '', zero: bool = False,
             upper: float = math.inf) -> float:
    """``value`` as a finite float > 0 (``zero``: >= 0) and <= ``upper``; ``ValueError``
    naming ``name`` and ``unit`` (if any) if not."""
    u = f' [{unit}]' if unit else ''
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be a number{u}, got {value!r}') from None
    if not (math.isfinite(x) and (x > 0.0 or (zero and x == 0.0)) and x <= upper):
        low = f'{">=" if zero else ">"} 0'
        what = f'finite, {low} and <= {upper:g}' if upper < math.inf else f'finite and {low}'
        raise ValueError(f'{name} must be {what}{u}, got {value!r}')
    return x


def integer(value, name: str, low: int = 1) -> int:
    """``value`` as an int >= ``low`` (a bool or a float is refused); ``ValueError`` naming
    ``name`` if not."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        what = 'a non-negative integer' if low == 0 else f'an integer >= {low}'
        raise ValueError(f'{name} must be {what}, got {value!r}')
    return int(value)


def inertia_matrix(value: ArrayLike, name: str = 'inertia_kgm2') -> np.ndarray:
    """An inertia tensor [kg m^2] as a (3, 3) float array (a (3,) value is the diagonal);
    ``ValueError`` unless finite with a positive definite symmetric part."""
    J = np.asarray(value, dtype=float)
    if J.shape == (3,):
        J = np.diag(J)
    J = finite_vector(J, name, (3, 3))
    if not np.all(np.linalg.eigvalsh(0.5 * (J + J.T)) > 0.0):
        raise ValueError(f'{name} must be symmetric positive definite')
    return J


def limits_vector(value: ArrayLike, name: str, n: int, allow_zero: bool = True,
                  allow_inf: bool = True) -> np.ndarray:
    """Per-axis actuator limits (n,) of a scalar or (n,) ``value``; ``ValueError`` naming
    ``name`` on NaN, negative, a bad shape, or zero (absent) or ``inf`` (no limit) when not
    allowed."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be numeric, got {value!r}') from None
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f'{name} must be a scalar or have shape ({n},), got {arr.shape}')
    if np.any(np.isnan(arr)) or np.any(arr < 0.0):
        raise ValueError(f'{name} must be >= 0 (not NaN), got {arr}')
    if not allow_zero and np.any(arr == 0.0):
        raise ValueError(f'{name} must be > 0, got {arr}')
    if not allow_inf and np.any(np.isinf(arr)):
        raise ValueError(f'{name} must be finite, got {arr}')
    return arr


def scale_to_limits(v: ArrayLike, limits: ArrayLike) -> tuple[np.ndarray, float]:
    """``(sigma v (n,), sigma in [0, 1])``, eq. (31), of the finite demand ``v`` (n,) and the
    per-axis ``limits`` (n,) >= 0 (``inf``: none; a zero limit with a non-zero demand gives
    ``sigma = 0``)."""
    v = np.asarray(v, dtype=float)
    lim = np.asarray(limits, dtype=float)
    mag = np.abs(v)
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = np.where(mag > 0.0, mag / lim, 0.0)
    phi = float(np.max(ratio)) if ratio.size else 0.0
    if phi <= 1.0:
        return v.copy(), 1.0
    sigma = 1.0 / phi                                                                 # (31)
    out = sigma * v
    # Rounding can leave |out_i| one ulp above l_i on the saturated axis: pin it.
    return np.clip(out, -lim, lim), sigma


@dataclass(frozen=True)
class Estimate:
    """Attitude and rate estimate handed to a controller: ``q_orbit_body`` (4,) scalar last
    (paper 000's ``Lambda``), ``omega_body_eci_body`` (3,) [rad/s] body axes, ``omega0`` the
    orbit rate [rad/s], ``valid`` (False: no usable solution, controllers command zero),
    ``q_eci_body`` (4,) or ``None`` if unknown."""

    q_orbit_body: np.ndarray
    omega_body_eci_body: np.ndarray
    omega0: float
    valid: bool = True
    q_eci_body: Optional[np.ndarray] = None

    def q_eci_orbit(self) -> Optional[np.ndarray]:
        """Orbit frame in ECI from the two attitudes, ``q_eci_body q_orbit_body^*``."""
        if self.q_eci_body is None:
            return None
        from adcs_nodes.core import attitude
        return attitude.multiply(attitude.normalize(self.q_eci_body),
                                 attitude.conjugate(attitude.normalize(self.q_orbit_body)))

    def is_usable(self) -> bool:
        """True when ``valid`` and every field is finite with the right shape."""
        try:
            q = np.asarray(self.q_orbit_body, dtype=float)
            w = np.asarray(self.omega_body_eci_body, dtype=float)
            w0 = float(self.omega0)
        except (TypeError, ValueError):
            return False
        return (bool(self.valid) and q.shape == (4,) and w.shape == (3,)
                and all(map(math.isfinite, q.tolist())) and all(map(math.isfinite, w.tolist()))
                and math.isfinite(w0) and math.sqrt(float(q @ q)) > 1e-9)


def _identity_quat() -> np.ndarray:
    return np.array([0.0, 0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Target:
    """Attitude target from guidance in ``frame`` (``'orbit'`` or ``'eci'``): ``q_ref_body``
    (4,) scalar last (default identity, paper 000's ``Lambda* = 1``, (11)), feed-forward
    ``omega_body_ref_body`` (3,) [rad/s] and ``omega_dot_body_ref_body`` (3,) [rad/s^2] w.r.t.
    the frame, body axes, and ``time_to_go_s`` of the maneuver (0: holding or tracking)."""

    q_ref_body: np.ndarray = field(default_factory=_identity_quat)
    omega_body_ref_body: np.ndarray = field(default_factory=lambda: np.zeros(3))
    omega_dot_body_ref_body: np.ndarray = field(default_factory=lambda: np.zeros(3))
    frame: str = 'orbit'
    time_to_go_s: float = 0.0

    @property
    def q_orbit_body_ref(self) -> np.ndarray:
        """The target attitude w.r.t. the orbital frame (only for ``frame == 'orbit'``)."""
        if self.frame != 'orbit':
            raise ValueError(f'target is in frame {self.frame!r}; convert it with '
                             'Target.in_frame("orbit", estimate) first')
        return self.q_ref_body

    def in_frame(self, frame: str, estimate: Optional['Estimate']) -> 'Target':
        """The same target expressed against ``frame`` (``'orbit'`` or ``'eci'``).

        Uses the estimate's orbit frame in ECI (``q_eci_orbit``); the rates are relative rates
        and are kept (the difference is the orbit rate, which the laws add themselves).
        Raises ``ValueError`` when a conversion is needed and the estimate lacks ``q_eci_body``.
        """
        if frame == self.frame:
            return self
        from adcs_nodes.core import attitude
        q_eci_orbit = None if estimate is None else estimate.q_eci_orbit()
        if q_eci_orbit is None:
            raise ValueError(f'cannot convert a {self.frame!r} target to {frame!r}: the '
                             'estimate has no inertial attitude')
        if frame == 'orbit':       # q_orbit_ref = q_eci_orbit^* q_eci_ref
            q = attitude.multiply(attitude.conjugate(q_eci_orbit), self.q_ref_body)
        else:                      # q_eci_ref = q_eci_orbit q_orbit_ref
            q = attitude.multiply(q_eci_orbit, self.q_ref_body)
        return Target(q, self.omega_body_ref_body, self.omega_dot_body_ref_body, frame,
                      self.time_to_go_s)


@dataclass
class Command:
    """Actuator command of a controller: ``dipole_body`` (3,) [A m^2], ``wheel_torque`` (n,)
    [N m] in scenario order ((0,): no wheels, zero torque), ``torque_body`` (3,) [N m] ideal,
    body axes; ``reason`` why it is zero or degraded; ``info`` the law's diagnostics;
    ``refused``: the controller cannot fly this frame (``reason`` says why; the manager falls
    back as for a stale command)."""

    dipole_body: np.ndarray = field(default_factory=lambda: np.zeros(3))
    wheel_torque: np.ndarray = field(default_factory=lambda: np.zeros(0))
    torque_body: np.ndarray = field(default_factory=lambda: np.zeros(3))
    reason: str = ''
    info: dict = field(default_factory=dict)
    refused: bool = False

    @classmethod
    def zero(cls, n_wheels: int = 0, reason: str = '', refused: bool = False) -> 'Command':
        """All-zero command with ``n_wheels`` wheel torques and a ``reason``."""
        return cls(np.zeros(3), np.zeros(n_wheels), np.zeros(3), reason, refused=refused)

    def is_finite(self) -> bool:
        """True when every actuator field is finite."""
        return all(bool(np.all(np.isfinite(np.asarray(a, dtype=float))))
                   for a in (self.dipole_body, self.wheel_torque, self.torque_body))


@dataclass(frozen=True)
class ControlInputs:
    """Everything a controller core may read in one frame (see the module docstring).

    A controller reads only what its registry entry declares under ``inputs``; the node
    fills the rest with ``None``.
    """

    estimate: Optional[Estimate] = None
    target: Optional[Target] = None
    b_body: Optional[np.ndarray] = None
    b_body_model: Optional[np.ndarray] = None
    wheel_speed_rad_s: Optional[np.ndarray] = None
    wheel_momentum_Nms: Optional[np.ndarray] = None
    #: a fresh horizon-sensor sample: (roll, pitch) [rad] of the body w.r.t. the orbit frame
    horizon_roll_pitch: Optional[tuple] = None
    #: a fresh gyro sample [rad/s, body axes]
    gyro_rate_body: Optional[np.ndarray] = None
    #: a fresh star-tracker attitude ``q_eci_body`` (scalar last)
    q_eci_body_meas: Optional[np.ndarray] = None
    #: the dipole applied over the previous command frame [A m^2, body axes]
    applied_dipole_body: Optional[np.ndarray] = None
    #: fresh samples of a plugin's input kinds, by input key (``adcs_nodes.inputs.register``)
    samples: Mapping[str, Any] = field(default_factory=dict)
    #: (n,) bool, False for a wheel that does not follow its torque (None: all healthy)
    wheel_ok: Optional[np.ndarray] = None
    #: magnetorquer limits (3,) [A m^2] for the axis failed wheels leave uncovered (None: none)
    backup_dipole_Am2: Optional[np.ndarray] = None

    def field_body(self) -> Optional[np.ndarray]:
        """The fresh measurement when there is one, else the onboard-model field."""
        return self.b_body if self.b_body is not None else self.b_body_model


class Controller(Protocol):
    """Structural type of a controller core (DESIGN section 7)."""

    def reset(self) -> None:
        """Forget all internal state (filters, stages, previous samples)."""

    def update(self, inputs: ControlInputs, t: float, dt: float) -> Command:
        """Command for frame time ``t`` [s] (frame period ``dt`` [s])."""
