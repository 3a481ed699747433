"""Wheel health: does each reaction wheel's measured speed follow the torque it was given?
(pure numpy, no ROS)

A wheel controller that reads the tachometer (``sensors/wheels``) and the command the manager
applied in the previous frame (``adcs/actuator_command``) checks each wheel over one sample
interval ``dt``. The motor torque ``tau`` held over ``dt`` changes the wheel's momentum by
``tau dt``; its speed relative to the body, ``h / J_w - a . omega``, by::

    expected = tau dt / J_w          (the body-rate term ``a . d omega`` is J_w / J_body smaller)
    measured = w(t) - w(t - dt)      (tachometer)

A frame is *informative* for a wheel when ``|expected| >= min_change_rad_s`` (well above the
tachometer's noise and resolution) and the wheel stays clear of its momentum limit (the
motor's torque is cut there on purpose). An informative frame is *bad* when
``|measured - expected| > tolerance |expected|``. Each wheel's health is a state:

* ``ok`` -> ``stuck`` (``|measured / expected| < STUCK_RATIO``) or ``lost torque`` after
  ``confirm_frames`` bad informative frames in a row (a good one clears the count);
* ``stuck`` / ``lost torque`` -> ``ok`` after ``recover_frames`` good informative frames in a
  row. A failed wheel is left out of the allocation, so it is given a probe torque
  (:meth:`WheelHealth.probe`: ``PROBE_FACTOR`` times the smallest judged change, its sign
  alternating each frame, net momentum zero) to see whether it follows again.

ASSUMPTION (not from a paper): the thresholds (defaults ``confirm_frames`` 5,
``recover_frames`` 5, ``min_change_rad_s`` 0.2 rad/s, ``tolerance`` 0.5, ``STUCK_RATIO`` 0.1,
``PROBE_FACTOR`` 2) are chosen against the default tachometer
(0.01 rad/s noise, 0.015 rad/s resolution) and paper 001's wheel momentum error (0.0033 N m s
on a 0.1 kg m^2 rotor: 0.03 rad/s), not from a wheel's data sheet.

The check runs only when the applied command was held over exactly the sample interval (the
command stamped at the previous tachometer sample, one control period before the current
one): with a tachometer slower than the control period the torque changes inside the interval
and nothing is judged.
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike

#: Defaults (ASSUMPTION, see module docstring).
CONFIRM_FRAMES = 5
RECOVER_FRAMES = 5
STUCK_RATIO = 0.1
PROBE_FACTOR = 2.0
OK, STUCK, LOST = 'ok', 'stuck', 'lost torque'
MIN_CHANGE_RAD_S = 0.2
TOLERANCE = 0.5
#: A wheel whose momentum after the interval would pass this share of its limit is not judged.
MOMENTUM_MARGIN = 0.95


class WheelHealth:
    """Per-wheel state (ok, stuck, lost torque) from measured speed against applied torque
    (module docstring): rotor inertias ``inertia_kgm2`` (n,) [kg m^2] > 0, momentum limits
    ``max_momentum_Nms`` (n,) [N m s] > 0, the control period ``period_s`` [s] (the hold of an
    applied command), the thresholds (>= 1 frames, > 0 otherwise), wheel ``names`` (default
    ``wheel0``, ...), motor limits ``max_torque_Nm`` (n,) [N m] bounding the probe.
    ``ValueError`` on inconsistent shapes or non-positive values."""

    def __init__(self, inertia_kgm2: ArrayLike, max_momentum_Nms: ArrayLike, period_s: float,
                 confirm_frames: int = CONFIRM_FRAMES,
                 min_change_rad_s: float = MIN_CHANGE_RAD_S, tolerance: float = TOLERANCE,
                 names: Optional[Sequence[str]] = None, recover_frames: int = RECOVER_FRAMES,
                 max_torque_Nm: Optional[ArrayLike] = None) -> None:
        self.inertia = np.asarray(inertia_kgm2, dtype=float).reshape(-1)
        self.max_momentum = np.asarray(max_momentum_Nms, dtype=float).reshape(-1)
        n = self.inertia.size
        if n == 0 or self.max_momentum.shape != (n,):
            raise ValueError(f'wheel health: {n} inertias and {self.max_momentum.size} '
                             'momentum limits (one each per wheel, at least one wheel)')
        if not np.all(np.isfinite(self.inertia)) or np.any(self.inertia <= 0.0) \
                or np.any(~(self.max_momentum > 0.0)):
            raise ValueError('wheel health: inertias must be finite and > 0, momentum '
                             'limits > 0')
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ValueError(f'wheel health: period_s must be > 0, got {period_s!r}')
        for key, v in (('confirm_frames', confirm_frames), ('recover_frames', recover_frames)):
            if isinstance(v, bool) or int(v) != v or v < 1:
                raise ValueError(f'wheel health: {key} must be an integer >= 1, got {v!r}')
        if not min_change_rad_s > 0.0 or not tolerance > 0.0:
            raise ValueError('wheel health: min_change_rad_s and tolerance must be > 0')
        self.period = float(period_s)
        self.confirm, self.recover = int(confirm_frames), int(recover_frames)
        self.min_change = float(min_change_rad_s)
        self.tolerance = float(tolerance)
        limit = np.inf if max_torque_Nm is None else np.asarray(max_torque_Nm, dtype=float)
        self.probe_Nm = np.minimum(PROBE_FACTOR * self.min_change * self.inertia / self.period,
                                   limit)
        self.names = list(names) if names else [f'wheel{i}' for i in range(n)]
        if len(self.names) != n:
            raise ValueError(f'wheel health: {len(self.names)} names for {n} wheels')
        self.reset()

    @property
    def n(self) -> int:
        """Number of wheels."""
        return self.inertia.size

    def reset(self) -> None:
        """Forget the history: every wheel ``ok``."""
        self._t: Optional[float] = None
        self._w: Optional[np.ndarray] = None
        self.bad = np.zeros(self.n, dtype=int)
        self.good = np.zeros(self.n, dtype=int)
        self.state: List[str] = [OK] * self.n
        self.reasons: List[str] = [''] * self.n
        self.judged_frames = 0
        self.recoveries = 0
        self._probes = 0

    @property
    def ok(self) -> np.ndarray:
        """(n,) bool: True for a wheel in state ``ok``."""
        return np.array([s == OK for s in self.state])

    def reason(self) -> str:
        """Each failed wheel, named first, with its reason ('' when every wheel is ok)."""
        return '; '.join(r for r in self.reasons if r)

    def probe(self) -> np.ndarray:
        """(n,) [N m]: the probe torque of each failed wheel (0 for the others), its sign
        alternating with each call."""
        sign = 1.0 if self._probes % 2 == 0 else -1.0
        self._probes += 1
        return np.where(self.ok, 0.0, sign * self.probe_Nm)

    def update(self, t: float, speeds: Optional[ArrayLike], t_cmd: Optional[float],
               torque: Optional[ArrayLike]) -> str:
        """Judge the interval ending at the tachometer sample stamped ``t`` [s], ``speeds``
        (n,) [rad/s] relative to the body (None: nothing judged), with the applied motor
        ``torque`` (n,) or (0,): zero [N m] stamped ``t_cmd`` [s] (judged only when that is
        the previous sample's stamp, one period before ``t``). Returns :meth:`reason`."""
        if speeds is None:
            return self.reason()
        w = np.asarray(speeds, dtype=float).reshape(-1)
        if w.shape != (self.n,) or not np.all(np.isfinite(w)):
            return self.reason()
        prev_t, prev_w = self._t, self._w
        self._t, self._w = float(t), w.copy()
        if prev_t is None or t_cmd is None or torque is None:
            return self.reason()
        dt = float(t) - prev_t
        if abs(float(t_cmd) - prev_t) > 1e-9 or abs(dt - self.period) > 1e-9:
            return self.reason()
        tau = np.asarray(torque, dtype=float).reshape(-1)
        if tau.size == 0:
            tau = np.zeros(self.n)
        if tau.shape != (self.n,) or not np.all(np.isfinite(tau)):
            return self.reason()
        expected = tau * dt / self.inertia
        measured = w - prev_w
        h_after = np.abs(w * self.inertia)
        self.judged_frames += 1
        for i in range(self.n):
            if abs(expected[i]) < self.min_change or max(
                    h_after[i], abs(prev_w[i] * self.inertia[i])) \
                    > MOMENTUM_MARGIN * self.max_momentum[i]:
                continue
            good = abs(measured[i] - expected[i]) <= self.tolerance * abs(expected[i])
            self.bad[i], self.good[i] = (0, self.good[i] + 1) if good else \
                (self.bad[i] + 1, 0)
            if self.state[i] == OK and self.bad[i] >= self.confirm:
                ratio = measured[i] / expected[i]
                self.state[i] = STUCK if abs(ratio) < STUCK_RATIO else LOST
                self.reasons[i] = (
                    f'wheel {self.names[i]} {self.state[i]} since t = {float(t):g} s: speed '
                    f'change {measured[i]:+.3g} rad/s for {expected[i]:+.3g} rad/s expected '
                    f'({tau[i]:+.3g} N m over {dt:g} s), {self.bad[i]} frames in a row')
            elif self.state[i] != OK and self.good[i] >= self.recover:
                self.state[i], self.reasons[i] = OK, ''
                self.recoveries += 1
        return self.reason()
