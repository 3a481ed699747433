"""Controller-manager logic: switching, schedule, automatic mode sequence, fallback (no ROS).

The ``controller_manager`` node wraps :class:`ControllerManagerCore`: every frame it passes the
frame time and the latest command of every controller (all controllers run in shadow mode,
DESIGN section 7) and publishes what :meth:`ControllerManagerCore.step` returns. Every decision
is a function of the frame times and the inputs only (no wall clock, no randomness).

Rules
-----
* **Switch at a frame boundary, one zero frame** (ros2_control: switch between updates;
  Basilisk: commands zeroed on a mode change). A request made with time ``t_req`` becomes
  effective at the first frame with ``t > t_req`` (``t_req = None``: the next frame). The frame
  in which a switch takes effect outputs exactly one all-zero command; the new controller's
  command is forwarded from the following frame. A switch to the controller already active
  changes nothing (no zero frame, not counted).
* **One pending request, the last one wins**: requests are not queued. A request made while
  another is pending (before its frame boundary) replaces it; the answer says so (``replaces
  the pending request for X, which will not be applied``) and ``replaced_requests`` counts it.
  A request for the controller already active cancels a pending one. So 100 rapid requests
  between two frames apply exactly one switch, the last one, and every answer says what will
  happen when it is given.
* **Schedule**: ``(t_s, name)`` entries apply at the frame whose time equals ``t_s`` (to 1 ns),
  or the first frame after ``t_s`` if none falls on it; that frame is the zero frame. When
  several entries are due in one frame the last one wins. A pending operator request made
  before the frame takes precedence over a scheduled entry due in the same frame.
* **Automatic mode sequence** (:class:`AutoSequence`): ``detumble`` (B-dot) until the rate
  ``|omega|`` is below ``rate_enter`` for ``confirm_frames`` consecutive frames, then
  ``acquire`` (the magnetic law), then optionally ``point`` once the attitude error is below
  ``angle_enter`` for ``confirm_frames`` frames. Back-transitions with hysteresis: a rate above
  ``rate_exit`` (> ``rate_enter``) for ``exit_confirm_frames`` frames returns to ``detumble``;
  an error above ``angle_exit`` (> ``angle_enter``) returns from ``point`` to ``acquire``. A mode
  change that changes the controller switches in the frame of the decision (zero frame). An
  invalid or missing estimate holds the mode and clears the counters. An operator or scheduled
  switch to a controller suspends the sequence (mode ``''``); the pseudo-name ``'auto'``
  (request or schedule) restarts it in ``detumble``.
* **Fallback**: the active controller's command is forwarded only if it is fresh (stamp equal
  to the frame time, or older by at most ``stale_after_s``; never from the future), has the
  right shapes, is finite and is inside the actuator limits, and, when the active controller
  uses the estimate (``estimate_users``) and the estimate is monitored (``estimate_period_s``),
  only if the estimate is fresh too (stamped at the estimator's last frame at or before ``t``,
  or older by at most ``stale_after_s``) and usable. Otherwise the safe controller's
  command (same checks) is forwarded in the same frame, ``missed_frames`` counts the frame and
  ``last_fault`` says why (stale / non-finite / out of range, naming the component). With a
  ``fallback`` list, its controllers are tried first, in order, with the same checks (e.g.
  ``['magnetic']``: a wheel controller whose wheel check failed hands over to the magnetic law
  on the magnetorquers, which does not need the wheels, and B-dot is the last resort); the
  first usable one is forwarded and named in ``last_fault`` (``; fallback to magnetic``). With
  ``latch_fallback`` the safe controller also becomes the active one (a counted switch, no
  zero frame: the safe command is needed now) and the automatic sequence is suspended; by
  default the fallback is per frame and the active controller resumes as soon as its command
  is valid again. If the safe command is bad too, the output is zero. The status key
  ``active`` is the selected controller, ``source`` the one whose command was forwarded.
* **Start**: the first frame forwards the initial controller (no zero frame).
* **Last line of defence**: the output is always finite and inside the limits (non-finite
  entries are zeroed, then every component is clipped).

A controller that does not use wheels may send an empty ``wheel_torque``: it is read as zero
torque on every wheel.

Compiled checks (issue 13)
--------------------------
The per-component tests of a command (finite, ``|v_i| <= l_i (1 + 1e-9) + 1e-12``) and the last
line of defence (non-finite -> 0, then ``clip(v, -l, l)``) are the numba kernels
:func:`limit_violation` and :func:`clip_finite` (``cache=True``, no fastmath); uncompiled
(``NUMBA_DISABLE_JIT=1``) they are the same Python. They compare and copy values, so the
forwarded command has the bits of the controller's.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Iterable, Mapping, Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude
from adcs_nodes.core.control import Command, Estimate, Target, limits_vector, positive
from adcs_nodes.core.kernels import jit
from adcs_nodes.core.spec import Param, Section

AUTO = 'auto'
"""Pseudo-controller name that (re)starts the automatic mode sequence."""
TIME_TOL_S = 1e-9
"""Tolerance on time comparisons [s] (sim time comes from integer nanoseconds)."""
_LIMIT_RTOL = 1e-9


@jit
def limit_violation(v, limit, rtol):
    """First bad component of ``v`` against the limits ``limit`` (both float64, shape (n,)).

    Returns
    -------
    int
        ``-1`` when every ``v_i`` is finite and ``|v_i| <= limit_i (1 + rtol) + 1e-12``;
        ``-2 - i`` when ``v_i`` is the first non-finite component (checked first); else the
        first ``i`` over its limit.
    """
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
    """Compile (or load from the numba cache) the check kernels, once per process (from the
    constructor: never inside a frame)."""
    for n in (0, 3):
        v = np.zeros(n)
        limit_violation(v, v, _LIMIT_RTOL)
        clip_finite(v, v)


def _opt_positive(value, name: str, unit: str) -> Optional[float]:
    return None if value is None else positive(value, name, unit)


def _count(value, name: str) -> int:
    if isinstance(value, bool) or int(value) != value or value < 1:
        raise ValueError(f'{name} must be an integer >= 1, got {value!r}')
    return int(value)


#: The ``manager.auto`` section (a node's ``auto.*``): the automatic mode sequence.
AUTO_SEQUENCE = Section('auto', (
    Param('detumble', 'str', 'bdot', '-', 'controller of the detumble mode'),
    Param('acquire', 'str', 'magnetic', '-', 'controller of the acquire mode'),
    Param('rate_enter_deg_s', 'float', 0.5, 'deg/s', 'detumble -> acquire below this rate',
          positive=True),
    Param('rate_exit_deg_s', 'float', 1.0, 'deg/s', 'acquire -> detumble above this rate',
          positive=True),
    Param('confirm_frames', 'int', 10, '-', 'frames the forward condition must hold', min=1,
          max=1000000),
    Param('exit_confirm_frames', 'int', 1, '-', 'frames the back condition must hold', min=1,
          max=1000000),
    Param('rate_frame', 'str', 'eci', '-', 'rate compared: w.r.t. ECI or the orbit frame',
          choices=('eci', 'orbit')),
    Param('point', 'str', None, '-', 'controller of the optional point mode (after acquire, '
          'once the attitude error is below angle_enter_deg)'),
    Param('angle_enter_deg', 'float', None, 'deg', 'acquire -> point below this attitude '
          'error to the orbital frame', positive=True, max=180.0),
    Param('angle_exit_deg', 'float', None, 'deg', 'point -> acquire above this error '
          '(> angle_enter_deg)', positive=True, max=180.0),
), 'automatic mode sequence detumble -> acquire [-> point]', optional=True)


@dataclass(frozen=True)
class AutoSequence:
    """Thresholds of the automatic mode sequence detumble -> acquire [-> point].

    Attributes
    ----------
    detumble, acquire : str
        Controllers of the ``detumble`` and ``acquire`` modes (default ``bdot``, ``magnetic``).
    point : str, optional
        Controller of the optional ``point`` mode (may equal ``acquire``; needs
        ``angle_enter_rad``).
    rate_enter_rad_s : float
        ``detumble -> acquire`` when the rate is below this [rad/s] (default 0.5 deg/s).
    rate_exit_rad_s : float, optional
        ``acquire/point -> detumble`` when the rate is above this [rad/s]; must exceed
        ``rate_enter_rad_s`` (hysteresis). ``None``: no way back.
    confirm_frames : int
        Consecutive frames a forward condition must hold (>= 1).
    exit_confirm_frames : int
        Consecutive frames a back-transition condition must hold (>= 1).
    angle_enter_rad, angle_exit_rad : float, optional
        ``acquire -> point`` below ``angle_enter``, ``point -> acquire`` above ``angle_exit``
        (> ``angle_enter``) [rad]; attitude error to the target.
    rate_frame : {'eci', 'orbit'}
        Rate compared with the thresholds: ``|omega_body_eci_body|`` (default) or the rate
        relative to the orbital frame ``|omega - omega0 e_N|`` (paper 000 eq. (7)).
    """

    detumble: str = 'bdot'
    acquire: str = 'magnetic'
    point: Optional[str] = None
    rate_enter_rad_s: float = math.radians(0.5)
    rate_exit_rad_s: Optional[float] = math.radians(1.0)
    confirm_frames: int = 10
    exit_confirm_frames: int = 1
    angle_enter_rad: Optional[float] = None
    angle_exit_rad: Optional[float] = None
    rate_frame: str = 'eci'

    def __post_init__(self) -> None:
        for name in ('detumble', 'acquire'):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ValueError(f'auto sequence: {name} must be a controller name')
        enter = _opt_positive(self.rate_enter_rad_s, 'auto sequence: rate_enter_rad_s',
                              'rad/s')
        if enter is None:
            raise ValueError('auto sequence: rate_enter_rad_s is required')
        leave = _opt_positive(self.rate_exit_rad_s, 'auto sequence: rate_exit_rad_s', 'rad/s')
        if leave is not None and not leave > enter:
            raise ValueError(f'auto sequence: rate_exit_rad_s ({leave:g}) must be > '
                             f'rate_enter_rad_s ({enter:g}) for hysteresis')
        _count(self.confirm_frames, 'auto sequence: confirm_frames')
        _count(self.exit_confirm_frames, 'auto sequence: exit_confirm_frames')
        a_in = _opt_positive(self.angle_enter_rad, 'auto sequence: angle_enter_rad', 'rad')
        a_out = _opt_positive(self.angle_exit_rad, 'auto sequence: angle_exit_rad', 'rad')
        if self.point is not None and a_in is None:
            raise ValueError('auto sequence: a point mode needs angle_enter_rad')
        if self.point is None and (a_in is not None or a_out is not None):
            raise ValueError('auto sequence: angle thresholds given without a point controller')
        if a_out is not None and not a_out > a_in:
            raise ValueError(f'auto sequence: angle_exit_rad ({a_out:g}) must be > '
                             f'angle_enter_rad ({a_in:g}) for hysteresis')
        if self.rate_frame not in ('eci', 'orbit'):
            raise ValueError(f"auto sequence: rate_frame must be 'eci' or 'orbit', got "
                             f'{self.rate_frame!r}')

    @classmethod
    def from_dict(cls, config: Mapping) -> 'AutoSequence':
        """Build from a scenario mapping with degree units (:data:`AUTO_SEQUENCE`; ValueError
        naming an unknown key or a value out of range)."""
        config = AUTO_SEQUENCE.validate(config)
        kw = {k: config[k] for k in ('detumble', 'acquire', 'point', 'confirm_frames',
                                     'exit_confirm_frames', 'rate_frame') if k in config}
        for key, field_name in (('rate_enter_deg_s', 'rate_enter_rad_s'),
                                ('rate_exit_deg_s', 'rate_exit_rad_s'),
                                ('angle_enter_deg', 'angle_enter_rad'),
                                ('angle_exit_deg', 'angle_exit_rad')):
            if key in config:
                value = config[key]
                kw[field_name] = None if value is None else math.radians(float(value))
        return cls(**kw)

    def controller_of(self, mode: str) -> str:
        """Controller name of a mode ``'detumble'``, ``'acquire'`` or ``'point'``."""
        return {'detumble': self.detumble, 'acquire': self.acquire,
                'point': self.point or self.acquire}[mode]


class ControllerManagerCore:
    """Selects, checks and forwards one controller's command per frame.

    Parameters
    ----------
    controllers : sequence of str
        Names of all controllers (unique, non-empty).
    safe : str
        Safe-mode controller (B-dot), one of ``controllers``.
    initial : str, optional
        Controller active at start; default the auto sequence's ``detumble`` controller, else
        ``safe``. With ``auto`` it must be the ``detumble`` controller.
    max_dipole_Am2 : float or array_like, shape (3,)
        Magnetorquer limits, body axes [A m^2] (``>= 0``; ``inf``: none).
    max_wheel_torque : float or array_like, shape (n,)
        Wheel motor torque limits [N m]; its length is the number of wheels (default none).
    max_torque : float or array_like, shape (3,)
        Ideal body-torque limits, body axes [N m] (default 0: no ideal actuator).
    stale_after_s : float
        A command older than this (frame time minus stamp) [s] is stale; 0 = exact stamp only.
    schedule : iterable of (float, str)
        Scripted switches ``(t_s [s], name)``; ``name`` may be ``'auto'`` when ``auto`` is set.
    auto : AutoSequence, optional
        Automatic mode sequence (active from the start when given).
    latch_fallback : bool
        Make the safe controller the active one after a fault (default: per-frame fallback).
    estimate_period_s : float, optional
        Period of the attitude estimator [s]; given, the estimate passed to :meth:`step` is
        checked for staleness (``None``: not monitored, e.g. no estimator).
    estimate_users : iterable of str, optional
        Controllers whose command depends on the estimate (default: all but ``safe``; the safe
        controller, B-dot, needs the magnetometer only).
    fallback : sequence of str
        Controllers tried in order, before ``safe``, when the active controller's command is
        not usable (default none: straight to ``safe``).
    startup_s : float
        Start-up [s]: until the first frame that forwards the active controller's command,
        a frame at most this long after the manager's first frame that forwards nothing is a
        start-up frame (zero or fallback command, counted in ``startup_frames``), not a
        missed one (default 0: every frame counts, lockstep). In sample timing a command
        needs one period of each stage of the estimator-controller-manager chain before its
        first arrival (``components.manager.manager_core``).

    Raises
    ------
    ValueError
        On unknown or duplicate names, bad limits, a bad schedule or inconsistent ``auto``.
    """

    def __init__(self, controllers: Sequence[str], safe: str, initial: Optional[str] = None,
                 max_dipole_Am2: ArrayLike = math.inf, max_wheel_torque: ArrayLike = (),
                 max_torque: ArrayLike = 0.0, stale_after_s: float = 0.0,
                 schedule: Iterable[tuple[float, str]] = (),
                 auto: Optional[AutoSequence] = None, latch_fallback: bool = False,
                 estimate_period_s: Optional[float] = None,
                 estimate_users: Optional[Iterable[str]] = None,
                 fallback: Sequence[str] = (), startup_s: float = 0.0) -> None:
        names = list(controllers)
        if not names or any(not isinstance(n, str) or not n for n in names):
            raise ValueError(f'controllers must be a non-empty list of names, got {names!r}')
        if len(set(names)) != len(names):
            raise ValueError(f'controller names must be unique, got {names}')
        self.names = names
        if safe not in names:
            raise ValueError(f'safe controller {safe!r} is not among the controllers {names}')
        self.safe = safe
        if auto is not None:
            if not isinstance(auto, AutoSequence):
                raise ValueError(f'auto must be an AutoSequence, got {type(auto).__name__}')
            if AUTO in names:
                raise ValueError(f"controller name '{AUTO}' is reserved for the auto sequence")
            for mode in ('detumble', 'acquire', 'point'):
                name = getattr(auto, mode)
                if name is not None and name not in names:
                    raise ValueError(f'auto sequence: {mode} controller {name!r} is not among '
                                     f'the controllers {names}')
            if initial is not None and initial != auto.detumble:
                raise ValueError(f'initial controller {initial!r} conflicts with the auto '
                                 f'sequence, which starts with {auto.detumble!r}')
            initial = auto.detumble
        initial = safe if initial is None else initial
        if initial not in names:
            raise ValueError(f'initial controller {initial!r} is not among the controllers '
                             f'{names}')
        self.auto = auto
        self.max_dipole = limits_vector(max_dipole_Am2, 'max_dipole_Am2', 3)
        wheel = np.atleast_1d(np.asarray(max_wheel_torque, dtype=float))
        self.max_wheel = limits_vector(wheel, 'max_wheel_torque', wheel.size)
        self.n_wheels = int(wheel.size)
        self.max_torque = limits_vector(max_torque, 'max_torque', 3)
        warm_up()
        try:
            self.stale_after = float(stale_after_s)
        except (TypeError, ValueError):
            raise ValueError(f'stale_after_s must be a number [s], got {stale_after_s!r}') \
                from None
        if not (math.isfinite(self.stale_after) and self.stale_after >= 0.0):
            raise ValueError(f'stale_after_s must be finite and >= 0 [s], got {stale_after_s!r}')
        self.schedule = self._check_schedule(schedule)
        self.latch_fallback = bool(latch_fallback)
        self.estimate_period = _opt_positive(estimate_period_s, 'estimate_period_s', 's')
        users = [n for n in names if n != safe] if estimate_users is None else \
            list(estimate_users)
        unknown = [n for n in users if n not in names]
        if unknown:
            raise ValueError(f'estimate_users: unknown controllers {unknown}; known: {names}')
        self.estimate_users = set(users)
        self.fallback = [str(n) for n in fallback]
        bad = [n for n in self.fallback if n not in names]
        if bad or safe in self.fallback or len(set(self.fallback)) != len(self.fallback):
            raise ValueError(f'fallback must list configured controllers other than the safe '
                             f'one ({safe!r}), each once; got {self.fallback}; known: {names}')
        self.startup_s = float(startup_s)
        if not (math.isfinite(self.startup_s) and self.startup_s >= 0.0):
            raise ValueError(f'startup_s must be finite and >= 0 [s], got {startup_s!r}')
        self._initial = initial
        self.reset()

    def _check_schedule(self, schedule) -> list[tuple[float, str]]:
        entries = []
        for i, entry in enumerate(schedule):
            try:
                t_s, name = entry
                t_s = float(t_s)
            except (TypeError, ValueError):
                raise ValueError(f'schedule[{i}] must be (t_s, name), got {entry!r}') from None
            if not math.isfinite(t_s):
                raise ValueError(f'schedule[{i}]: time must be finite, got {t_s}')
            if name not in self.names and not (name == AUTO and self.auto is not None):
                raise ValueError(f'schedule[{i}]: unknown controller {name!r}; known: '
                                 f'{", ".join(self._known())}')
            entries.append((t_s, name))
        return sorted(entries, key=lambda e: e[0])        # stable: equal times keep the order

    def _known(self) -> list[str]:
        return self.names + ([AUTO] if self.auto is not None else [])

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to the initial state (initial controller, schedule from the start)."""
        self.active = self._initial
        self.switch_count = 0
        self.missed_frames = 0
        self.startup_frames = 0
        self._t_first: Optional[float] = None       # the first frame's time [s]
        self._forwarded = False                     # the active command went out once
        self.estimate_stale_frames = 0
        self.replaced_requests = 0
        self.last_fault = ''
        self._pending: Optional[tuple[str, Optional[float]]] = None
        self._sched_idx = 0
        self._auto_on = self.auto is not None
        self._auto_mode = 'detumble' if self._auto_on else ''
        self._counts = {'enter': 0, 'exit': 0, 'angle_exit': 0}
        self._status: dict = self._make_status(None, '', '', False)

    @property
    def mode(self) -> str:
        """Mode of the automatic sequence, '' when it is off or suspended."""
        return self._auto_mode if self._auto_on else ''

    def list_controllers(self) -> tuple[list[str], str, str]:
        """``(names, active, safe)`` for the ``~/list_controllers`` service."""
        return list(self.names), self.active, self.safe

    def status(self) -> dict:
        """The status of the last :meth:`step` (see there)."""
        return dict(self._status)

    # --------------------------------------------------------------- requests
    def request_switch(self, name: str, t: Optional[float] = None) -> tuple[bool, str]:
        """Ask for a switch; it takes effect at the first frame with time > ``t``.

        Parameters
        ----------
        name : str
            Controller name, or ``'auto'`` to restart the automatic sequence.
        t : float, optional
            Sim time of the request [s] (normally the last frame processed); ``None``: the
            next frame whatever its time.

        Returns
        -------
        success : bool
            False for an unknown name (nothing changes).
        message : str
            What will happen: the switch and its frame, or that it replaces (or equals) the
            pending request (one pending request; the last one before a frame wins).
        """
        if not isinstance(name, str) or name not in self._known():
            shown = repr(name) if len(repr(name)) <= 60 else repr(name)[:57] + '...'
            return False, f'unknown controller {shown}; known: {", ".join(self._known())}'
        if t is not None:
            t = float(t)
            if not math.isfinite(t):
                return False, f'request time must be finite, got {t}'
        prev = self._pending[0] if self._pending is not None else None
        self._pending = (name, t)
        when = 'the next frame' if t is None else f'the next frame after t = {t:.9g} s'
        if prev is not None and prev != name:
            self.replaced_requests += 1
            note = (f'; replaces the pending request for {prev}, which will not be applied '
                    f'(replaced requests: {self.replaced_requests})')
        elif prev == name:
            note = '; the same request was already pending (applied once)'
        else:
            note = ''
        note += '; a later request before then replaces this one'
        if name == AUTO:
            return True, f'queued: automatic sequence restarts in detumble at {when}{note}'
        if name == self.active:
            return True, (f'{name} is already active: stays active at {when}, no zero frame'
                          f'{note}')
        return True, (f'queued: switch {self.active} -> {name} at {when}, one frame of zero '
                      f'command{note}')

    # ------------------------------------------------------------------- step
    def step(self, t: float, commands: Mapping[str, tuple[float, Optional[Command]]],
             estimate: Optional[Estimate] = None,
             target: Optional[Target] = None,
             estimate_t: Optional[float] = None) -> tuple[Command, dict]:
        """Decide and produce the actuator command of frame ``t``.

        Parameters
        ----------
        t : float
            Frame time [s].
        commands : mapping str -> (float, Command or None)
            Latest command of each controller with its stamp [s]; missing = none received.
        estimate : Estimate, optional
            Attitude estimate at ``t``, used only by the automatic sequence.
        target : Target, optional
            Target for the attitude-error threshold of the ``point`` mode (default the orbital
            frame).
        estimate_t : float, optional
            Stamp of ``estimate`` [s] (checked when ``estimate_period_s`` is set; a stale
            estimate is not used by the automatic sequence either).

        Returns
        -------
        command : Command
            Finite and inside the limits; ``reason`` says why it is zero or from the fallback.
        status : dict
            ``t``, ``mode``, ``active``, ``available``, ``safe``, ``source`` (controller whose
            command was forwarded, '' for zero), ``pending``, ``switch_count``,
            ``missed_frames``, ``last_fault``, ``fault`` (this frame, '' if none),
            ``fallback`` (bool), ``zero_frame`` (bool), ``estimate_fault`` (this frame),
            ``estimate_stale_frames``, ``replaced_requests``.
        """
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f'frame time must be finite, got {t}')
        if self._t_first is None:
            self._t_first = t
        est_fault = self._estimate_fault(t, estimate, estimate_t)
        if est_fault:
            self.estimate_stale_frames += 1
        request = self._due_request(t)
        old = self.active
        if request is not None:
            self._apply_request(request)
        elif self._auto_on:
            self._auto_step(None if est_fault else estimate, target)
        if self.active != old:
            self.switch_count += 1
            cmd = self._zero(f'switch {old} -> {self.active}: zero command for one frame')
            self._status = self._make_status(t, '', '', False, zero_frame=True)
            return cmd, self.status()

        fault = ''
        cmd, why = self._check(commands.get(self.active), t)
        if cmd is not None and est_fault and self.active in self.estimate_users:
            cmd, why = None, f'estimator {est_fault}'
        source = self.active
        if cmd is not None:
            self._forwarded = True
        elif (self.startup_s > 0.0 and not self._forwarded
              and t - self._t_first <= self.startup_s + TIME_TOL_S):
            self.startup_frames += 1                 # the chain's first command on its way
        else:
            self.missed_frames += 1
        if cmd is None:
            fault = f'{self.active}: {why}'
            source = ''
            for name in (self.fallback + [self.safe]) if self.active != self.safe else ():
                if name == self.active:
                    continue
                cmd, why_other = self._check(commands.get(name), t)
                if cmd is not None and est_fault and name in self.estimate_users:
                    cmd, why_other = None, f'estimator {est_fault}'
                if cmd is not None:
                    fault += f'; fallback to {name}'
                    source = name
                    break
                fault += (f'; safe controller {name}' if name == self.safe else
                          f'; fallback {name}') + f': {why_other}'
            if cmd is None:
                fault += '; zero command'
            self.last_fault = fault
            if self.latch_fallback and self.active != self.safe:
                self.active = source or self.safe
                self.switch_count += 1
                self._auto_on = False
        out = self._zero(fault) if cmd is None else self._sanitize(cmd, fault)
        self._status = self._make_status(t, source, fault, bool(fault) and bool(source),
                                         estimate_fault=est_fault)
        return out, self.status()

    # -------------------------------------------------------------- internals
    def _estimate_fault(self, t: float, estimate: Optional[Estimate],
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

    def _due_request(self, t: float) -> Optional[str]:
        scheduled = None
        while (self._sched_idx < len(self.schedule)
               and self.schedule[self._sched_idx][0] <= t + TIME_TOL_S):
            scheduled = self.schedule[self._sched_idx][1]
            self._sched_idx += 1
        if self._pending is not None:
            name, t_req = self._pending
            if t_req is None or t > t_req + TIME_TOL_S:
                self._pending = None
                return name                    # the operator's request beats the schedule
        return scheduled

    def _apply_request(self, name: str) -> None:
        if name == AUTO:
            self._auto_on = True
            self._set_auto_mode('detumble')
        else:
            self._auto_on = False
            self.active = name

    def _set_auto_mode(self, mode: str) -> None:
        self._auto_mode = mode
        self._counts = {'enter': 0, 'exit': 0, 'angle_exit': 0}
        self.active = self.auto.controller_of(mode)

    def _auto_step(self, estimate: Optional[Estimate], target: Optional[Target]) -> None:
        a = self.auto
        if estimate is None or not estimate.is_usable():
            self._counts = {'enter': 0, 'exit': 0, 'angle_exit': 0}
            return
        omega = np.asarray(estimate.omega_body_eci_body, dtype=float)
        q = attitude.normalize(estimate.q_orbit_body)
        if a.rate_frame == 'orbit':
            e_n = attitude.rotate(attitude.conjugate(q), [0.0, 1.0, 0.0])
            omega = omega - float(estimate.omega0) * e_n
        rate = float(np.linalg.norm(omega))
        c = self._counts
        mode = self._auto_mode
        if mode == 'detumble':
            c['enter'] = c['enter'] + 1 if rate < a.rate_enter_rad_s else 0
            if c['enter'] >= a.confirm_frames:
                self._set_auto_mode('acquire')
            return
        if a.rate_exit_rad_s is not None:
            c['exit'] = c['exit'] + 1 if rate > a.rate_exit_rad_s else 0
            if c['exit'] >= a.exit_confirm_frames:
                self._set_auto_mode('detumble')
                return
        if a.point is None:
            return
        q_ref = Target().q_orbit_body_ref if target is None else target.q_orbit_body_ref
        try:
            angle = attitude.angle_between(q, q_ref)
        except ValueError:
            return
        if mode == 'acquire':
            c['enter'] = c['enter'] + 1 if angle < a.angle_enter_rad else 0
            if c['enter'] >= a.confirm_frames:
                self._set_auto_mode('point')
        elif a.angle_exit_rad is not None:
            c['angle_exit'] = c['angle_exit'] + 1 if angle > a.angle_exit_rad else 0
            if c['angle_exit'] >= a.exit_confirm_frames:
                self._set_auto_mode('acquire')

    def _check(self, entry, t: float) -> tuple[Optional[Command], str]:
        """``(command, '')`` if usable, else ``(None, reason)``."""
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
        try:
            fields = (('dipole_body', cmd.dipole_body, self.max_dipole, 'A m^2'),
                      ('wheel_torque', cmd.wheel_torque, self.max_wheel, 'N m'),
                      ('torque_body', cmd.torque_body, self.max_torque, 'N m'))
        except AttributeError:
            return None, f'malformed command {type(cmd).__name__}'
        values = {}
        for name, value, limit, unit in fields:
            try:
                arr = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                return None, f'malformed {name}: {value!r}'
            if name == 'wheel_torque' and arr.shape == (0,):
                arr = np.zeros(self.n_wheels)
            if arr.shape != limit.shape:
                return None, f'malformed {name}: shape {arr.shape}, expected {limit.shape}'
            i = limit_violation(arr, limit, _LIMIT_RTOL)
            if i <= -2:
                why = str(getattr(cmd, 'reason', '') or '')      # the controller's own word
                return None, f'non-finite (NaN or inf) {name}: {arr}' + (f' ({why})' if why
                                                                         else '')
            if i >= 0:
                return None, (f'out of range: {name}[{i}] = {arr[i]:.6g} {unit} exceeds the '
                              f'limit {limit[i]:.6g} {unit}')
            values[name] = arr
        info = getattr(cmd, 'info', None)
        return Command(values['dipole_body'], values['wheel_torque'], values['torque_body'],
                       str(getattr(cmd, 'reason', '')), dict(info) if info else {}), ''

    def _sanitize(self, cmd: Command, reason: str) -> Command:
        def clip(v, lim):
            return clip_finite(np.asarray(v, dtype=float), lim)
        return Command(clip(cmd.dipole_body, self.max_dipole),
                       clip(cmd.wheel_torque, self.max_wheel),
                       clip(cmd.torque_body, self.max_torque), reason or cmd.reason, cmd.info)

    def _zero(self, reason: str) -> Command:
        return Command.zero(self.n_wheels, reason)

    def _make_status(self, t: Optional[float], source: str, fault: str, fallback: bool,
                     zero_frame: bool = False, estimate_fault: str = '') -> dict:
        return {'t': t, 'mode': self.mode, 'active': self.active,
                'available': list(self.names), 'safe': self.safe, 'source': source,
                'pending': '' if self._pending is None else self._pending[0],
                'switch_count': self.switch_count, 'missed_frames': self.missed_frames,
                'startup_frames': self.startup_frames,
                'last_fault': self.last_fault, 'fault': fault, 'fallback': fallback,
                'zero_frame': zero_frame, 'estimate_fault': estimate_fault,
                'estimate_stale_frames': self.estimate_stale_frames,
                'replaced_requests': self.replaced_requests}
