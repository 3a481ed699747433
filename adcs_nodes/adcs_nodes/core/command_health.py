"""The controller manager's command health check and fallback chain (no ROS).

A controller's command is usable only if the controller did not refuse it (``Command.refused``,
with its reason), is fresh (stamp equal to the frame time, or older by at most
``stale_after_s``; never from the future), has the right shapes, is finite and is inside the
actuator limits (``|v_i| <= l_i (1 + 1e-9) + 1e-12``) and, when the controller uses
the estimate (``estimate_users``) and the estimate is monitored (``estimate_period_s``), the
estimate is fresh (stamped at the estimator's last frame at or before ``t``, or older by at
most ``stale_after_s``) and usable. An unusable active command hands over to the ``fallback``
controllers in order, then to the safe one (B-dot), with the same checks; if none is usable the
output is zero. The last line of defence zeroes non-finite entries and clips to the limits.
A controller that does not use wheels may send an empty ``wheel_torque`` (zero torque).
The per-component kernels are numba-compiled; they compare and copy, so the forwarded command
has the bits of the controller's.
"""
from __future__ import annotations

import functools
import math
from typing import Iterable, Mapping, Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core.control import Command, Estimate, limits_vector, positive
from adcs_nodes.core.kernels import jit

TIME_TOL_S = 1e-9
"""Tolerance on time comparisons [s] (sim time comes from integer nanoseconds)."""
_LIMIT_RTOL = 1e-9


@jit
def limit_violation(v, limit, rtol):
    """First bad component of ``v`` against ``limit`` (both float64, shape (n,)): ``-1`` when
    every ``v_i`` is finite and ``|v_i| <= limit_i (1 + rtol) + 1e-12``; ``-2 - i`` for the
    first non-finite ``v_i`` (checked first); else the first ``i`` over its limit."""
    for i in range(v.shape[0]):
        if not math.isfinite(v[i]):
            return -2 - i
    for i in range(v.shape[0]):
        if abs(v[i]) > limit[i] * (1.0 + rtol) + 1e-12:
            return i
    return -1


@jit
def clip_finite(v, limit):
    """``clip(v, -limit, limit)`` after zeroing the non-finite entries, shape (n,)."""
    out = np.zeros(v.shape[0])
    for i in range(v.shape[0]):
        if math.isfinite(v[i]):
            out[i] = min(max(v[i], -limit[i]), limit[i])
    return out


@functools.cache
def warm_up() -> None:
    """Compile (or load from the numba cache) the check kernels, once per process."""
    for n in (0, 3):
        v = np.zeros(n)
        limit_violation(v, v, _LIMIT_RTOL)
        clip_finite(v, v)


def command_fields(cmd, max_dipole: np.ndarray, max_wheel: np.ndarray,
                   max_torque: np.ndarray) -> tuple[dict, str]:
    """``({field: float array}, '')`` when ``cmd``'s fields have their limits' shapes (an empty
    ``wheel_torque``: zero on every wheel), are finite and inside the limits (module
    docstring), else ``({}, why)`` naming the field (the manager's check and the controller
    component's, at its boundary)."""
    values = {}
    for name, limit, unit in (('dipole_body', max_dipole, 'A m^2'),
                              ('wheel_torque', max_wheel, 'N m'),
                              ('torque_body', max_torque, 'N m')):
        try:
            arr = np.asarray(getattr(cmd, name), dtype=float)
        except AttributeError:
            return {}, f'malformed command {type(cmd).__name__}'
        except (TypeError, ValueError):
            return {}, f'malformed {name}: {getattr(cmd, name)!r}'
        if name == 'wheel_torque' and arr.shape == (0,):
            arr = np.zeros(limit.shape)
        if arr.shape != limit.shape:
            return {}, f'malformed {name}: shape {arr.shape}, expected {limit.shape}'
        i = limit_violation(arr, limit, _LIMIT_RTOL)
        if i <= -2:
            return {}, f'non-finite (NaN or inf) {name}: {arr}'
        if i >= 0:
            return {}, (f'out of range: {name}[{i}] = {arr[i]:.6g} {unit} exceeds the limit '
                        f'{limit[i]:.6g} {unit}')
        values[name] = arr
    return values, ''


class CommandHealth:
    """Limits, staleness and estimate checks of the commands (see the module docstring).

    ``max_dipole_Am2`` (3,) [A m^2], ``max_wheel_torque`` (n,) [N m] (its length is the number
    of wheels), ``max_torque`` (3,) [N m]; ``stale_after_s`` [s]; ``estimate_period_s`` [s] or
    ``None`` (estimate not monitored); ``estimate_users``: controllers that need the estimate.
    """

    def __init__(self, max_dipole_Am2: ArrayLike, max_wheel_torque: ArrayLike,
                 max_torque: ArrayLike, stale_after_s: float,
                 estimate_period_s: Optional[float], estimate_users: Iterable[str]) -> None:
        self.max_dipole = limits_vector(max_dipole_Am2, 'max_dipole_Am2', 3)
        wheel = np.atleast_1d(np.asarray(max_wheel_torque, dtype=float))
        self.max_wheel = limits_vector(wheel, 'max_wheel_torque', wheel.size)
        self.n_wheels = int(wheel.size)
        self.max_torque = limits_vector(max_torque, 'max_torque', 3)
        warm_up()
        self.stale_after = positive(stale_after_s, 'stale_after_s', 's', zero=True)
        self.estimate_period = (None if estimate_period_s is None else
                                positive(estimate_period_s, 'estimate_period_s', 's'))
        self.estimate_users = set(estimate_users)

    def estimate_fault(self, t: float, estimate: Optional[Estimate],
                       estimate_t: Optional[float]) -> str:
        """'' when the estimate is fresh and usable (or not monitored), else why not."""
        if self.estimate_period is None:
            return ''
        if estimate is None or estimate_t is None:
            return 'stale: no estimate received'
        try:
            stamp = float(estimate_t)
        except (TypeError, ValueError):
            return f'stale: bad estimate stamp {estimate_t!r}'
        if not math.isfinite(stamp):
            return f'stale: estimate stamp not finite ({stamp})'
        if stamp > t + TIME_TOL_S:
            return f'stale: estimate stamp {stamp:.9g} s is ahead of the frame {t:.9g} s'
        p = self.estimate_period
        last_frame = p * math.floor((t + TIME_TOL_S) / p)       # estimator's frame <= t
        if last_frame - stamp > self.stale_after + TIME_TOL_S:
            return (f'stale: estimate stamped {stamp:.9g} s, the estimator\'s frame is '
                    f'{last_frame:.9g} s (limit {self.stale_after:g} s)')
        if not estimate.is_usable():
            return 'invalid estimate (flagged invalid or not finite)'
        return ''

    def usable(self, commands: Mapping, name: str, t: float,
               est_fault: str) -> tuple[Optional[Command], str]:
        """``(command, '')`` if controller ``name``'s command is usable, else ``(None, why)``."""
        cmd, why = self.check(commands.get(name), t)
        if cmd is not None and est_fault and name in self.estimate_users:
            return None, f'estimator {est_fault}'
        return cmd, why

    def fall_back(self, commands: Mapping, t: float, active: str, why: str,
                  chain: Sequence[str], est_fault: str
                  ) -> tuple[Optional[Command], str, str]:
        """Try ``chain`` (fallbacks then safe) after ``active`` failed with ``why``.

        Returns ``(command or None, source ('' for none), fault text)``.
        """
        fault = f'{active}: {why}'
        for i, name in enumerate(chain):
            if name == active:
                continue
            cmd, why_other = self.usable(commands, name, t, est_fault)
            if cmd is not None:
                return cmd, name, fault + f'; fallback to {name}'
            fault += (f'; safe controller {name}' if i == len(chain) - 1 else
                      f'; fallback {name}') + f': {why_other}'
        return None, '', fault + '; zero command'

    def check(self, entry, t: float) -> tuple[Optional[Command], str]:
        """``(command, '')`` if the ``(stamp, command)`` entry is usable, else
        ``(None, reason)``."""
        if entry is None:
            return None, 'stale: no command received'
        try:
            stamp, cmd = entry
            stamp = float(stamp)
        except (TypeError, ValueError):
            return None, f'malformed entry {entry!r}'
        if cmd is None:
            return None, f'stale: no command (stamp {stamp:.9g} s)'
        if not math.isfinite(stamp):
            return None, f'stale: stamp not finite ({stamp})'
        if stamp > t + TIME_TOL_S:
            return None, f'stale: stamp {stamp:.9g} s is ahead of the frame {t:.9g} s'
        if t - stamp > self.stale_after + TIME_TOL_S:
            return None, (f'stale: stamp {stamp:.9g} s is {t - stamp:.9g} s older than the '
                          f'frame {t:.9g} s (limit {self.stale_after:g} s)')
        if getattr(cmd, 'refused', False):
            return None, str(getattr(cmd, 'reason', '') or 'refused')
        values, why = command_fields(cmd, self.max_dipole, self.max_wheel, self.max_torque)
        if why:
            return None, why
        info = getattr(cmd, 'info', None)
        return Command(values['dipole_body'], values['wheel_torque'], values['torque_body'],
                       str(getattr(cmd, 'reason', '')), dict(info) if info else {}), ''

    def sanitize(self, cmd: Command, reason: str) -> Command:
        """The last line of defence: non-finite entries zeroed, then clipped to the limits."""
        def clip(v, lim):
            return clip_finite(np.asarray(v, dtype=float), lim)
        return Command(clip(cmd.dipole_body, self.max_dipole),
                       clip(cmd.wheel_torque, self.max_wheel),
                       clip(cmd.torque_body, self.max_torque), reason or cmd.reason, cmd.info)
