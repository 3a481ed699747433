"""The controller manager's automatic mode sequence detumble -> acquire [-> point] (no ROS).

``detumble`` (B-dot) until the rate ``|omega|`` is below ``rate_enter`` for ``confirm_frames``
consecutive frames, then ``acquire`` (the magnetic law), then optionally ``point`` once the
attitude error to the target is below ``angle_enter`` for ``confirm_frames`` frames.
Back-transitions with hysteresis: a rate above ``rate_exit`` (> ``rate_enter``) for
``exit_confirm_frames`` frames returns to ``detumble``; an error above ``angle_exit``
(> ``angle_enter``) returns from ``point`` to ``acquire``. An invalid or missing estimate holds
the mode and clears the counters. The rate is ``|omega_body_eci_body|`` or, with
``rate_frame: orbit``, the rate relative to the orbital frame ``|omega - omega0 e_N|``
(paper 000 eq. (7)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Optional

import numpy as np

from adcs_nodes.core import attitude
from adcs_nodes.core.control import Estimate, Target, positive
from adcs_nodes.core.spec import Param, Section

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


def _opt_positive(value, name: str, unit: str) -> Optional[float]:
    return None if value is None else positive(value, name, unit)


def _count(value, name: str) -> int:
    if isinstance(value, bool) or int(value) != value or value < 1:
        raise ValueError(f'{name} must be an integer >= 1, got {value!r}')
    return int(value)


@dataclass(frozen=True)
class AutoSequence:
    """Thresholds of the automatic mode sequence (rad, rad/s; see the module docstring).

    ``point`` (optional, may equal ``acquire``) needs ``angle_enter_rad``;
    ``rate_exit_rad_s = None``: no way back to ``detumble``; ``rate_frame`` is ``'eci'`` or
    ``'orbit'``. ``ValueError`` on a missing threshold or an exit threshold not above its
    enter threshold.
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


class ModeSequencer:
    """The state of an :class:`AutoSequence`: the mode and its confirmation counters."""

    def __init__(self, auto: AutoSequence) -> None:
        self.auto = auto
        self.restart()

    def restart(self, mode: str = 'detumble') -> str:
        """Enter ``mode`` with cleared counters; returns its controller."""
        self.mode = mode
        self._counts = {'enter': 0, 'exit': 0, 'angle_exit': 0}
        return self.auto.controller_of(mode)

    def update(self, estimate: Optional[Estimate], target: Optional[Target]) -> Optional[str]:
        """One frame: the controller of the new mode on a transition, else ``None``."""
        a, mode = self.auto, self.mode
        if estimate is None or not estimate.is_usable():
            self._counts = {'enter': 0, 'exit': 0, 'angle_exit': 0}
            return None
        omega = np.asarray(estimate.omega_body_eci_body, dtype=float)
        q = attitude.normalize(estimate.q_orbit_body)
        if a.rate_frame == 'orbit':                       # paper 000 eq. (7)
            e_n = attitude.rotate(attitude.conjugate(q), [0.0, 1.0, 0.0])
            omega = omega - float(estimate.omega0) * e_n
        rate = float(np.linalg.norm(omega))
        if mode == 'detumble':
            entered = self._held('enter', rate < a.rate_enter_rad_s, a.confirm_frames)
            return self.restart('acquire') if entered else None
        if a.rate_exit_rad_s is not None and self._held(
                'exit', rate > a.rate_exit_rad_s, a.exit_confirm_frames):
            return self.restart('detumble')
        if a.point is None:
            return None
        q_ref = Target().q_orbit_body_ref if target is None else target.q_orbit_body_ref
        try:
            angle = attitude.angle_between(q, q_ref)
        except ValueError:
            return None
        if mode == 'acquire':
            entered = self._held('enter', angle < a.angle_enter_rad, a.confirm_frames)
            return self.restart('point') if entered else None
        if a.angle_exit_rad is not None and self._held(
                'angle_exit', angle > a.angle_exit_rad, a.exit_confirm_frames):
            return self.restart('acquire')
        return None

    def _held(self, counter: str, condition: bool, frames: int) -> bool:
        """``condition`` counted in a row on ``counter`` (reset when false): held ``frames``."""
        self._counts[counter] = self._counts[counter] + 1 if condition else 0
        return self._counts[counter] >= frames
