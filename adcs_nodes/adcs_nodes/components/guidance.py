"""Guidance's frame step: the scenario's profile (or a slew goal's hold) at the frame time ->
``adcs/attitude_target``.

The profile is either quaternion segments (:mod:`adcs_nodes.core.guidance`: hold, slew, track)
or, with ``euler312_profile`` (JSON text), paper 001's maneuvers, holds and sine tracking in
its LVLH 3-1-2 Euler angles (:mod:`adcs_nodes.core.guidance_profiles`).
"""
from __future__ import annotations

import json
from dataclasses import replace
from typing import Any, Dict, Optional

import numpy as np

from adcs_nodes.core.guidance import FRAMES, TargetSample, guidance_from_params
from adcs_nodes.core.guidance_profiles import profile_from_dicts
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.core.samples import AttitudeTarget
from adcs_nodes.registry import Param
from adcs_nodes.spec import HOLD, PROFILE

PARAMS = (
    Param('period_s', 'float', 2.0, 's', 'publication period', positive=True, read_only=True),
    Param('frame', 'str', 'orbit', '-', 'frame of the profile attitudes', choices=FRAMES,
          read_only=True),
    *replace(PROFILE, read_only=True).columns('profile_', HOLD),
    Param('controllers', 'str[]', [''], '-', 'controllers a slew goal may name (the run\'s)',
          read_only=True),
    Param('euler312_profile', 'str', '', '-', "paper 001 profile as JSON: a list of "
          "{type: maneuver|hold|sine, start_s, end_s, ...} in LVLH 3-1-2 Euler degrees "
          "(replaces the segments; '': none)", read_only=True),
)


class _Euler312:
    """Adapter: a paper 001 :class:`Profile` with the quaternion guidance's ``at(t)``."""

    def __init__(self, text: str) -> None:
        try:
            items = json.loads(text)
        except ValueError as exc:
            raise ValueError(f'euler312_profile is not JSON: {exc}') from None
        self.profile = profile_from_dicts(items)

    def at(self, t: float) -> TargetSample:
        q, w, a, ttg, frame = self.profile.profile_at(t)
        kind = 'maneuver' if ttg > 0 else 'hold'
        return TargetSample(q, w, a, frame, ttg, kind)


class GuidanceComponent:
    """The target of each frame: the profile's, or a slew goal's hold (:meth:`hold`)."""

    def __init__(self, p: Dict[str, Any]) -> None:
        if p['euler312_profile']:
            self.guidance = _Euler312(p['euler312_profile'])
        else:
            self.guidance = guidance_from_params(
                p['profile_t_s'], p['profile_type'], p['profile_q_xyzw'],
                p['profile_duration_s'], p['profile_axis_body'], p['profile_amplitude_deg'],
                p['profile_period_s'], p['frame'])
        self.override: Optional[TargetSample] = None     # a slew goal's hold target

    def hold(self, q_xyzw: np.ndarray, frame: str) -> None:
        """Hold ``q_xyzw`` in ``frame`` from the next frame on (a slew goal)."""
        zero = np.zeros(3)
        self.override = TargetSample(np.asarray(q_xyzw, dtype=float), zero, zero, frame, 0.0,
                                     'slew_goal')

    def step(self, t_ns: int) -> AttitudeTarget:
        """The target of frame ``t_ns``."""
        s = self.override or self.guidance.at(t_ns / NS_PER_S)
        return AttitudeTarget(t_ns, s.frame, np.array(s.q_ref_body, dtype=float),
                              np.array(s.omega_body_ref_body, dtype=float),
                              np.array(s.omega_dot_body_ref_body, dtype=float),
                              float(s.time_to_go_s), s.profile)
