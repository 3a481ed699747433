"""B-dot detumbling: the safe-mode controller (pure numpy).

Law (Stickler and Alfriend, "Elementary magnetic attitude control system", J. Spacecraft and
Rockets 13(5), 1976; the "B-dot" law)::

    m = -k_b dB_body/dt                                                               (B1)

with ``dB_body/dt`` the derivative of the field *as seen in body axes*. For a fast tumble
``dB_body/dt ~ -omega x B``, so the torque ``m x B = -k_b B x (omega x B)`` gives::

    d/dt (1/2 omega^T I omega) = omega . (m x B) = -k_b (|omega|^2 |B|^2 - (omega . B)^2) <= 0
                                                                                       (B2)

kinetic energy only decreases, up to the slow rotation of ``B`` along the orbit (about twice
the orbit rate), which B-dot cannot remove: the body settles at a rate of that order. It needs
only the magnetometer, no attitude and no rate estimate: this is why it is the safe mode the
controller manager falls back to.

Derivative (first-order backward difference of successive valid measurements ``b_k`` at
``t_k``; the first call has none and commands zero)::

    bdot_k = (b_k - b_{k-1}) / (t_k - t_{k-1})                                            (B3)

optionally low-pass filtered (first order, time constant ``tau``, exact for a held input)::

    f_k = f_{k-1} + (1 - exp(-(t_k - t_{k-1}) / tau)) (bdot_k - f_{k-1}),  f_1 = bdot_1    (B4)

An externally provided ``b_dot_body`` (e.g. from a sensor model or an estimator) replaces (B3)
and passes through the same filter. The dipole is then scaled onto the coil limits keeping
its direction (paper 000, eq. (31); :func:`adcs_nodes.core.control.scale_to_limits`).

Units: ``k_b`` [A m^2 s / T], ``B`` [T], ``dB/dt`` [T/s], ``m`` [A m^2].
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core.control import (Command, ControlInputs, Estimate, Target, limits_vector,
                                     positive, scale_to_limits)


def _valid_vec3(v) -> Optional[np.ndarray]:
    if v is None:
        return None
    try:
        arr = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        return None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        return None
    return arr


class BdotController:
    """B-dot detumbling controller (B1)-(B4), the safe mode.

    Parameters
    ----------
    gain : float
        ``k_b`` [A m^2 s / T], > 0.
    max_dipole_Am2 : float or array_like, shape (3,)
        Coil limits [A m^2], body axes, > 0.
    filter_time_constant_s : float
        ``tau`` of the low-pass (B4) [s]; 0 (default) disables the filter.
    n_wheels : int
        Length of the (zero) wheel-torque vector in the command.

    Raises
    ------
    ValueError
        On a non-positive gain, bad limits or a negative time constant.
    """

    def __init__(self, gain: float, max_dipole_Am2: ArrayLike = 40.0,
                 filter_time_constant_s: float = 0.0, n_wheels: int = 0) -> None:
        self.gain = positive(gain, 'gain', 'A m^2 s/T')
        self.tau = positive(filter_time_constant_s, 'filter_time_constant_s', 's', zero=True)
        self.max_dipole = limits_vector(max_dipole_Am2, 'max_dipole_Am2', 3,
                                        allow_zero=False, allow_inf=False)
        if int(n_wheels) != n_wheels or n_wheels < 0:
            raise ValueError(f'n_wheels must be an integer >= 0, got {n_wheels!r}')
        self.n_wheels = int(n_wheels)
        self._b_prev: Optional[np.ndarray] = None
        self._t_prev = 0.0
        self._f: Optional[np.ndarray] = None
        self._t_f = 0.0
        self._last: Optional[Command] = None

    def reset(self) -> None:
        """Forget the previous measurement, the filter state and the held command."""
        self._b_prev = None
        self._f = None
        self._last: Optional[Command] = None

    def _zero(self, reason: str) -> Command:
        return Command.zero(self.n_wheels, reason)

    def update(self, inputs: ControlInputs, t: float, dt: float) -> Command:
        """Registry interface: needs only the magnetometer (the safe-mode rule).

        A frame without a fresh sample holds the last command (the derivative needs a new
        sample); the estimate and target are never read.
        """
        if inputs.b_body is None:
            if self._last is not None:
                return self._last
            return self._zero('no magnetic field sample yet')
        self._last = self.law(None, None, inputs.b_body, t, dt)
        return self._last

    def law(self, estimate: Optional[Estimate], target: Optional[Target],
            b_body: Optional[ArrayLike], t: float, dt: float,
            b_dot_body: Optional[ArrayLike] = None) -> Command:
        """Dipole command for frame ``t``.

        Parameters
        ----------
        estimate, target : ignored
            Accepted for the common interface; B-dot needs neither.
        b_body : array_like, shape (3,), or None
            Measured field, body axes [T]. Missing or non-finite samples are skipped (the next
            valid one is differenced against the last valid one over the real time gap).
        t : float
            Frame time [s]; must increase between calls (else the derivative restarts).
        dt : float
            Frame period [s]; used only as the filter step for the first external ``b_dot``.
        b_dot_body : array_like, shape (3,), optional
            Externally provided ``dB_body/dt`` [T/s]; replaces the finite difference (B3).

        Returns
        -------
        Command
            ``dipole_body`` [A m^2]; ``info`` holds ``b_dot`` (filtered, [T/s]),
            ``dipole_demand`` and ``sigma``.
        """
        t = float(t)
        b = _valid_vec3(b_body)
        raw = _valid_vec3(b_dot_body)
        if raw is None:
            if b is None:
                return self._zero('no valid magnetic field measurement')
            if self._b_prev is None:
                self._b_prev, self._t_prev = b, t
                return self._zero('first field sample: dB/dt not yet available')
            h = t - self._t_prev
            if not h > 0.0:
                reason = f'time did not advance ({self._t_prev} -> {t} s): derivative restarted'
                self._b_prev, self._t_prev, self._f = b, t, None
                return self._zero(reason)
            raw = (b - self._b_prev) / h                                              # (B3)
        if b is not None:
            self._b_prev, self._t_prev = b, t
        if self._f is None or self.tau == 0.0:
            self._f = raw
        else:
            h = t - self._t_f
            if not h > 0.0:
                h = float(dt) if float(dt) > 0.0 else 0.0
            self._f = self._f + (1.0 - math.exp(-h / self.tau)) * (raw - self._f)     # (B4)
        self._t_f = t
        demand = -self.gain * self._f                                                 # (B1)
        dipole, sigma = scale_to_limits(demand, self.max_dipole)                      # (31)
        cmd = Command(dipole, np.zeros(self.n_wheels), np.zeros(3))
        cmd.info = {'b_dot': self._f.copy(), 'dipole_demand': demand, 'sigma': sigma}
        return cmd
