"""Controller-manager logic: switching rules, schedule and status (no ROS).

The ``controller_manager`` node wraps :class:`ControllerManagerCore`: every frame it passes the
frame time and the latest command of every controller (all run in shadow mode, DESIGN section
7) and publishes what :meth:`ControllerManagerCore.step` returns. Every decision is a function
of the frame times and the inputs only. The concerns live in three modules: the switching
rules here, the automatic mode sequence in :mod:`adcs_nodes.core.mode_sequence`, the command
health check and fallback chain in :mod:`adcs_nodes.core.command_health`.

* **Switch at a frame boundary, one zero frame** (ros2_control; Basilisk). A request made at
  ``t_req`` takes effect at the first frame with ``t > t_req`` (``None``: the next frame); that
  frame outputs one all-zero command, the new controller's command goes out from the next. A
  switch to the active controller changes nothing (no zero frame, not counted).
* **One pending request, the last one wins** (``replaced_requests`` counts the replaced ones;
  the answer says what will happen). A request for the active controller cancels a pending one.
* **Schedule**: ``(t_s, name)`` applies at the frame whose time equals ``t_s`` (to 1 ns), or
  the first frame after; the last entry due in a frame wins; a pending operator request beats
  a scheduled entry due in the same frame.
* **Automatic sequence**: a mode change that changes the controller switches in the frame of
  the decision (zero frame). An operator or scheduled switch to a controller suspends the
  sequence (mode ``''``); the pseudo-name ``'auto'`` restarts it in ``detumble``.
* **Fallback**: an unusable active command is replaced in the same frame by the first usable
  fallback (``missed_frames``, ``last_fault``). With ``latch_fallback`` the controller used
  becomes the active one (a counted switch, no zero frame) and the sequence is suspended.
  ``active`` is the selected controller, ``source`` the one forwarded; a usable command's
  ``info['note']`` (a failed wheel it flies without) goes to ``last_fault``.
* **Start**: the first frame forwards the initial controller (no zero frame).
"""
from __future__ import annotations

import math
from typing import Iterable, Mapping, Optional, Sequence

from numpy.typing import ArrayLike

from adcs_nodes.core.command_health import (TIME_TOL_S, CommandHealth, clip_finite,
                                            limit_violation, warm_up)
from adcs_nodes.core.control import Command, Estimate, Target, finite, positive
from adcs_nodes.core.mode_sequence import AUTO_SEQUENCE, AutoSequence, ModeSequencer

__all__ = ['AUTO', 'AUTO_SEQUENCE', 'AutoSequence', 'ControllerManagerCore', 'TIME_TOL_S',
           'clip_finite', 'limit_violation', 'warm_up']

AUTO = 'auto'
"""Pseudo-controller name that (re)starts the automatic mode sequence."""


class ControllerManagerCore:
    """Selects, checks and forwards one controller's command per frame.

    ``controllers``: the names (unique, non-empty); ``safe`` one of them (B-dot); ``initial``
    active at start (default the ``auto`` sequence's ``detumble``, else ``safe``); actuator
    limits ``max_dipole_Am2`` (3,) [A m^2], ``max_wheel_torque`` (n_wheels,) [N m] (default
    none), ``max_torque`` (3,) [N m] (default 0: no ideal actuator; ``inf``: none);
    ``stale_after_s`` [s] the oldest usable command (0: exact stamp); ``schedule`` of
    ``(t_s [s], name)`` (``'auto'`` with ``auto``); ``auto`` an :class:`AutoSequence`;
    ``latch_fallback``: the fallback becomes the active one; ``estimate_period_s`` [s]: the
    estimate's staleness is checked; ``estimate_users`` (default all but ``safe``);
    ``fallback`` tried in order before ``safe``; ``startup_s`` [s]: until the active command
    is first forwarded, a frame this close to the first is a start-up frame, not a missed one
    (default 0: lockstep). ``ValueError`` on unknown or duplicate names, bad limits, a bad
    schedule or an inconsistent ``auto``.
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
        self.auto = auto
        self._initial = self._check_initial(initial)
        users = [n for n in names if n != safe] if estimate_users is None else \
            list(estimate_users)
        unknown = [n for n in users if n not in names]
        if unknown:
            raise ValueError(f'estimate_users: unknown controllers {unknown}; known: {names}')
        self.health = CommandHealth(max_dipole_Am2, max_wheel_torque, max_torque,
                                    stale_after_s, estimate_period_s, users)
        self.n_wheels = self.health.n_wheels
        self.schedule = self._check_schedule(schedule)
        self.latch_fallback = bool(latch_fallback)
        self.fallback = [str(n) for n in fallback]
        bad = [n for n in self.fallback if n not in names]
        if bad or safe in self.fallback or len(set(self.fallback)) != len(self.fallback):
            raise ValueError(f'fallback must list configured controllers other than the safe '
                             f'one ({safe!r}), each once; got {self.fallback}; known: {names}')
        self.startup_s = positive(startup_s, 'startup_s', 's', zero=True)
        self.reset()

    def _check_initial(self, initial: Optional[str]) -> str:
        auto, names = self.auto, self.names
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
        initial = self.safe if initial is None else initial
        if initial not in names:
            raise ValueError(f'initial controller {initial!r} is not among the controllers '
                             f'{names}')
        return initial

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
        self._sequencer = ModeSequencer(self.auto) if self._auto_on else None
        self._status: dict = self._make_status(None, '', '', False)

    @property
    def mode(self) -> str:
        """Mode of the automatic sequence, '' when it is off or suspended."""
        return self._sequencer.mode if self._auto_on else ''

    @property
    def estimate_users(self) -> set:
        """Controllers whose command depends on the estimate."""
        return self.health.estimate_users

    def list_controllers(self) -> tuple[list[str], str, str]:
        """``(names, active, safe)`` for the ``~/list_controllers`` service."""
        return list(self.names), self.active, self.safe

    def status(self) -> dict:
        """The status of the last :meth:`step` (see there)."""
        return dict(self._status)

    # --------------------------------------------------------------- requests
    def request_switch(self, name: str, t: Optional[float] = None) -> tuple[bool, str]:
        """Ask for a switch to ``name`` (or ``'auto'``) at the first frame with time > ``t``
        [s] (``None``: the next frame).

        Returns ``(success, message)``: False for an unknown name (nothing changes); the
        message says what will happen, or that it replaces (or equals) the pending request.
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
        """``(command, status)`` of frame ``t`` [s] from the latest ``(stamp [s], Command or
        None)`` of each controller (missing: none received), the ``estimate`` stamped
        ``estimate_t`` [s] (the sequence, the estimate check) and the ``target`` of the point
        mode (default the orbital frame). The command is finite and inside the limits
        (``reason``: why zero or from the fallback); the status has ``t``, ``mode``,
        ``active``, ``available``, ``safe``, ``source`` (forwarded, '' for zero), ``pending``,
        ``switch_count``, ``missed_frames``, ``startup_frames``, ``last_fault``, ``fault`` and
        ``estimate_fault`` (this frame), ``fallback``, ``zero_frame``,
        ``estimate_stale_frames``, ``replaced_requests``, ``note`` (the forwarded command's,
        e.g. a failed wheel it flies without).
        """
        t = finite(t, 'frame time')
        if self._t_first is None:
            self._t_first = t
        est_fault = self.health.estimate_fault(t, estimate, estimate_t)
        if est_fault:
            self.estimate_stale_frames += 1
        old = self.active
        request = self._due_request(t)
        if request == AUTO:
            self._auto_on = True
            self.active = self._sequencer.restart()
        elif request is not None:
            self._auto_on = False
            self.active = request
        elif self._auto_on:
            self.active = self._sequencer.update(None if est_fault else estimate,
                                                 target) or self.active
        if self.active != old:
            self.switch_count += 1
            cmd = Command.zero(self.n_wheels,
                               f'switch {old} -> {self.active}: zero command for one frame')
            self._status = self._make_status(t, '', '', False, zero_frame=True)
            return cmd, self.status()
        return self._forward(t, commands, est_fault)

    def _forward(self, t: float, commands: Mapping, est_fault: str) -> tuple[Command, dict]:
        """The active command if usable, else the fallback chain's (or zero)."""
        fault, source, note = '', self.active, ''
        cmd, why = self.health.usable(commands, self.active, t, est_fault)
        if cmd is not None:
            self._forwarded = True
            note = cmd.info.get('note', '')       # usable, degraded (e.g. a failed wheel)
            if note:
                self.last_fault = f'{self.active}: {note}'
        elif (self.startup_s > 0.0 and not self._forwarded
              and t - self._t_first <= self.startup_s + TIME_TOL_S):
            self.startup_frames += 1                 # the chain's first command on its way
        else:
            self.missed_frames += 1
        if cmd is None:
            chain = self.fallback + [self.safe] if self.active != self.safe else []
            cmd, source, fault = self.health.fall_back(commands, t, self.active, why, chain,
                                                       est_fault)
            self.last_fault = fault
            if self.latch_fallback and self.active != self.safe:
                self.active = source or self.safe
                self.switch_count += 1
                self._auto_on = False
        out = (Command.zero(self.n_wheels, fault) if cmd is None else
               self.health.sanitize(cmd, fault))
        self._status = self._make_status(t, source, fault, bool(fault) and bool(source),
                                         estimate_fault=est_fault)
        self._status['note'] = note
        return out, self.status()

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
