"""Guidance profiles of paper 001: maneuvers with end times, holds, sinusoidal tracking.

Tan Tian-le, "State transition control of satellite attitude" (seed paper 001, Sec. 6; digest
``papers/mpi-state-transition-control.md`` section 4). Pure functions of time.

Segments give the paper's 3-1-2 Euler angles ``e = [phi, theta, psi]`` w.r.t. its LVLH frame
(converted to the project's ``q_orbit_body`` by the MPI module's one boundary,
:func:`adcs_nodes.core.control.mpi.q_orbit_body_of_lvlh_euler312`). Each evaluates to
``(q_ref_body, omega_body_ref_body, omega_dot_body_ref_body, time_to_go_s, frame)``, the
reference ``'orbit'``; the rate is the body rate w.r.t. the orbit frame in target-body axes::

    maneuver [t0, t1):  e = e_f, rates of the final state, time_to_go = t1 - t           (G1)
    hold     [t0, t1):  e = e_h, zero rate, time_to_go = 0                                 (G2)
    sine     [t0, t1):  e = c + a o sin(2 pi (t - t0) / P + p)                             (G3)
                        e_dot, e_ddot its derivatives, time_to_go = 0
    w     = body_rate_from_euler312(e, e_dot)         (inverse of the paper's (3))
    w_dot = body_accel_from_euler312(e, e_dot, e_ddot)

Outside every segment the profile holds the end attitude of the last segment that ended
(zero rate); before the first segment it evaluates the first at its start time.

ASSUMPTION (digest section 4): the tracking sines have zero phase at their start (1000 s),
which gives the rate step the paper reports as maximum wheel torque at 1000 s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, NamedTuple, Sequence

import numpy as np

from adcs_nodes.core.control.mpi import (body_accel_from_euler312, body_rate_from_euler312,
                                         q_orbit_body_of_lvlh_euler312)

__all__ = ['ProfilePoint', 'Maneuver', 'Hold', 'SineTracking', 'Profile', 'profile_from_dicts']


class ProfilePoint(NamedTuple):
    """One evaluation of a profile: ``q_ref_body`` (4,) scalar last into ``frame`` (``'orbit'``),
    ``omega_body_ref_body`` (3,) [rad/s] w.r.t. it, target-body axes, its derivative
    ``omega_dot_body_ref_body`` [rad/s^2], ``time_to_go_s`` (0 when holding or tracking)."""

    q_ref_body: np.ndarray
    omega_body_ref_body: np.ndarray
    omega_dot_body_ref_body: np.ndarray
    time_to_go_s: float
    frame: str


def _vec3(value: Any, name: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be three numbers, got {value!r}') from None
    if arr.ndim == 0:
        arr = np.full(3, float(arr))
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f'{name} must be three finite numbers, got {value!r}')
    return arr


def _times(start_s: float, end_s: float) -> tuple[float, float]:
    t0, t1 = float(start_s), float(end_s)
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 > t0):
        raise ValueError(f'segment needs finite start_s < end_s, got {start_s!r}, {end_s!r}')
    return t0, t1


def _check_roll(euler_rad: np.ndarray, name: str) -> None:
    if abs(euler_rad[0]) >= math.radians(85.0):
        raise ValueError(f'{name}: |roll| must stay below 85 deg (3-1-2 singularity at 90)')


def _point(e: np.ndarray, de: np.ndarray, dde: np.ndarray, ttg: float) -> ProfilePoint:
    return ProfilePoint(q_orbit_body_of_lvlh_euler312(e), body_rate_from_euler312(e, de),
                        body_accel_from_euler312(e, de, dde), float(ttg), 'orbit')


@dataclass(frozen=True)
class Maneuver:
    """Reach ``euler_deg`` (with ``euler_rate_deg_s``) by ``end_s`` (G1)."""

    start_s: float
    end_s: float
    euler_deg: Sequence[float]
    euler_rate_deg_s: Sequence[float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        _times(self.start_s, self.end_s)
        _check_roll(np.radians(_vec3(self.euler_deg, 'maneuver euler_deg')), 'maneuver')
        _vec3(self.euler_rate_deg_s, 'maneuver euler_rate_deg_s')

    def at(self, t: float) -> ProfilePoint:
        e = np.radians(_vec3(self.euler_deg, 'euler_deg'))
        return _point(e, np.radians(_vec3(self.euler_rate_deg_s, 'rate')), np.zeros(3),
                      max(self.end_s - t, 0.0))

    def end_point(self) -> ProfilePoint:
        return _point(np.radians(_vec3(self.euler_deg, 'e')), np.zeros(3), np.zeros(3), 0.0)


@dataclass(frozen=True)
class Hold:
    """Hold ``euler_deg`` at zero rate (G2)."""

    start_s: float
    end_s: float
    euler_deg: Sequence[float]

    def __post_init__(self) -> None:
        _times(self.start_s, self.end_s)
        _check_roll(np.radians(_vec3(self.euler_deg, 'hold euler_deg')), 'hold')

    def at(self, t: float) -> ProfilePoint:
        return _point(np.radians(_vec3(self.euler_deg, 'e')), np.zeros(3), np.zeros(3), 0.0)

    def end_point(self) -> ProfilePoint:
        return self.at(self.end_s)


@dataclass(frozen=True)
class SineTracking:
    """Sinusoids about ``center_deg`` per axis (G3); ``period_s`` per axis (> 0)."""

    start_s: float
    end_s: float
    center_deg: Sequence[float]
    amplitude_deg: Sequence[float]
    period_s: Sequence[float]
    phase_deg: Sequence[float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        _times(self.start_s, self.end_s)
        c = _vec3(self.center_deg, 'sine center_deg')
        a = _vec3(self.amplitude_deg, 'sine amplitude_deg')
        if np.any(_vec3(self.period_s, 'sine period_s') <= 0.0):
            raise ValueError(f'sine period_s must be > 0, got {self.period_s!r}')
        _vec3(self.phase_deg, 'sine phase_deg')
        _check_roll(np.radians([abs(c[0]) + abs(a[0]), 0.0, 0.0]), 'sine')

    def euler(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``e, e_dot, e_ddot`` [rad, rad/s, rad/s^2] at ``t`` (G3)."""
        c = np.radians(_vec3(self.center_deg, 'c'))
        a = np.radians(_vec3(self.amplitude_deg, 'a'))
        w = 2.0 * math.pi / _vec3(self.period_s, 'p')
        arg = w * (t - self.start_s) + np.radians(_vec3(self.phase_deg, 'ph'))
        return c + a * np.sin(arg), a * w * np.cos(arg), -a * w * w * np.sin(arg)

    def at(self, t: float) -> ProfilePoint:
        e, de, dde = self.euler(t)
        return _point(e, de, dde, 0.0)

    def end_point(self) -> ProfilePoint:
        return _point(self.euler(self.end_s)[0], np.zeros(3), np.zeros(3), 0.0)


class Profile:
    """A time-ordered list of non-overlapping segments (``ValueError`` if empty, unknown or
    overlapping)."""

    def __init__(self, segments: Iterable[Any]) -> None:
        segs = sorted(segments, key=lambda s: s.start_s)
        if not segs:
            raise ValueError('a profile needs at least one segment')
        for s in segs:
            if not isinstance(s, (Maneuver, Hold, SineTracking)):
                raise ValueError(f'unknown profile segment {s!r}')
        for a, b in zip(segs, segs[1:]):
            if b.start_s < a.end_s - 1e-9:
                raise ValueError(f'profile segments overlap: [{a.start_s}, {a.end_s}) and '
                                 f'[{b.start_s}, {b.end_s})')
        self.segments = segs
        self._starts = [s.start_s for s in segs]

    @property
    def end_s(self) -> float:
        """End of the last segment [s]."""
        return self.segments[-1].end_s

    def profile_at(self, t: float) -> ProfilePoint:
        """The target at ``t`` [s] (module docstring); a non-finite ``t`` gives the first
        segment's start (never NaN)."""
        t = float(t)
        if not math.isfinite(t) or t < self.segments[0].start_s:
            return self.segments[0].at(self.segments[0].start_s)
        i = int(np.searchsorted(self._starts, t, side='right')) - 1
        seg = self.segments[i]
        if t < seg.end_s:
            return seg.at(t)
        return seg.end_point()


def profile_from_dicts(items: Iterable[dict]) -> Profile:
    """Profile from plain dicts (``type``: ``maneuver``, ``hold`` or ``sine`` plus the
    segment's fields); ``ValueError`` on unknown keys/types."""
    kinds = {'maneuver': Maneuver, 'hold': Hold, 'sine': SineTracking}
    segs = []
    for item in items:
        item = dict(item)
        kind = item.pop('type', None)
        if kind not in kinds:
            raise ValueError(f'profile segment type must be one of {sorted(kinds)}, got {kind!r}')
        try:
            segs.append(kinds[kind](**item))
        except TypeError as exc:
            raise ValueError(f'{kind} segment: {exc}') from None
    return Profile(segs)
