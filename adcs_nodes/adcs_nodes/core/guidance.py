"""Guidance: the attitude target as a time-tagged profile of segments (pure numpy).

A profile is a list of segments sorted by start time ``t_s``; the one with the latest start
at or before ``t`` is active. Every segment gives the target attitude ``q_ref_body`` (scalar
last, rotating target-body vectors into the profile's frame: ``orbit`` or ``eci``), the
target rate ``omega_body_ref_body`` and acceleration ``omega_dot_body_ref_body`` (body axes,
w.r.t. that frame) and the time left in a maneuver ``time_to_go_s``.

Segments
--------
``hold``: constant attitude ``q``; zero rate and acceleration.

``slew``: rest-to-rest eigenaxis rotation from the previous segment's final attitude ``q0``
to ``q`` in ``duration_s`` seconds, with the smooth (versine) angle profile, ``s = (t -
t_s) / T`` in [0, 1]::

    theta(s)   = Theta (s - sin(2 pi s) / (2 pi))                                   (G1)
    theta'(t)  = Theta / T (1 - cos(2 pi s))                                          (G2)
    theta''(t) = Theta / T^2 2 pi sin(2 pi s)                                         (G3)
    q_ref      = q0 (x) [e sin(theta/2), cos(theta/2)],  omega = theta' e,  omega' = theta'' e

with ``(e, Theta)`` the eigenaxis and angle of ``q0^* q`` (shortest way). Rate and
acceleration are zero at both ends; the peak rate is ``2 Theta / T``.

``track``: sinusoidal tracking about a body axis ``e`` from the attitude ``q`` (paper 001's
tracking phases)::

    theta(t) = A sin(2 pi (t - t_s) / P),  q_ref = q (x) [e sin(theta/2), cos(theta/2)]     (G4)

with ``omega = theta' e`` and ``omega' = theta'' e``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Sequence

import numpy as np

from adcs_nodes.core import attitude as att

SEGMENT_TYPES = ('hold', 'slew', 'track')
FRAMES = ('orbit', 'eci')


@dataclass(frozen=True)
class Segment:
    """One profile segment from ``t_s`` [s]: ``type`` ``hold``, ``slew`` or ``track``; ``q`` (4,)
    the hold, slew end or tracking centre attitude; ``duration_s`` of a slew; ``axis_body``
    (3,), ``amplitude_rad`` and ``period_s`` of a track."""

    t_s: float
    type: str
    q: np.ndarray
    duration_s: float = 0.0
    axis_body: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    amplitude_rad: float = 0.0
    period_s: float = 0.0


@dataclass(frozen=True)
class TargetSample:
    """Target at one time (fields as ``adcs_msgs/AttitudeTarget``)."""

    q_ref_body: np.ndarray
    omega_body_ref_body: np.ndarray
    omega_dot_body_ref_body: np.ndarray
    frame: str
    time_to_go_s: float
    profile: str


def _rotation(q0: np.ndarray, axis: np.ndarray, theta: float) -> np.ndarray:
    return att.multiply(q0, att.from_axis_angle(axis, theta))


class Guidance:
    """A time-tagged attitude profile of ``segments`` (sorted here; identity held before the
    first) in one ``frame`` (``'orbit'`` or ``'eci'``). ``ValueError`` on an unknown frame or
    type, a non-unit quaternion, or a slew or track without a positive duration or period."""

    def __init__(self, segments: Sequence[Segment], frame: str = 'orbit') -> None:
        if frame not in FRAMES:
            raise ValueError(f'frame must be one of {FRAMES}, got {frame!r}')
        segs = sorted(segments, key=lambda s: s.t_s)
        if not segs or segs[0].t_s > 0.0:
            segs.insert(0, Segment(0.0, 'hold', att.identity()))
        for s in segs:
            if s.type not in SEGMENT_TYPES:
                raise ValueError(f'segment at {s.t_s} s: type must be one of {SEGMENT_TYPES}')
            q = np.asarray(s.q, dtype=float)
            if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1) > 1e-3:
                raise ValueError(f'segment at {s.t_s} s: q must be a unit quaternion, got {q}')
            if s.type == 'slew' and not s.duration_s > 0:
                raise ValueError(f'slew at {s.t_s} s: duration_s must be > 0')
            if s.type == 'track' and not s.period_s > 0:
                raise ValueError(f'track at {s.t_s} s: period_s must be > 0')
        self.frame = frame
        self.segments: List[Segment] = segs
        # start attitude of each segment: the end attitude of the one before
        self._q_start: List[np.ndarray] = []
        q_prev = att.normalize(segs[0].q)
        for s in segs:
            self._q_start.append(q_prev)
            q_prev = att.normalize(s.q)

    def active(self, t: float) -> int:
        """Index of the segment active at ``t`` [s]."""
        idx = 0
        for i, s in enumerate(self.segments):
            if s.t_s <= t:
                idx = i
        return idx

    def at(self, t: float) -> TargetSample:
        """The target at time ``t`` [s]."""
        i = self.active(t)
        s, q0 = self.segments[i], self._q_start[i]
        zero = np.zeros(3)
        q = att.normalize(s.q)
        if s.type == 'hold':
            return TargetSample(q, zero, zero, self.frame, 0.0, 'hold')
        tau = t - s.t_s
        if s.type == 'slew':
            if tau >= s.duration_s:
                return TargetSample(q, zero, zero, self.frame, 0.0, 'hold')
            rotvec = att.to_rotation_vector(att.multiply(att.conjugate(q0), q))
            big_theta = float(np.linalg.norm(rotvec))
            if big_theta < 1e-12:
                return TargetSample(q, zero, zero, self.frame, s.duration_s - tau, 'slew')
            e = rotvec / big_theta
            T, x = s.duration_s, tau / s.duration_s
            theta = big_theta * (x - math.sin(2 * math.pi * x) / (2 * math.pi))      # (G1)
            rate = big_theta / T * (1 - math.cos(2 * math.pi * x))                    # (G2)
            acc = big_theta / T ** 2 * 2 * math.pi * math.sin(2 * math.pi * x)        # (G3)
            return TargetSample(_rotation(q0, e, theta), rate * e, acc * e, self.frame,
                                T - tau, 'slew')
        e = np.asarray(s.axis_body, dtype=float)
        e = e / np.linalg.norm(e)
        w = 2 * math.pi / s.period_s
        theta = s.amplitude_rad * math.sin(w * tau)                                   # (G4)
        rate = s.amplitude_rad * w * math.cos(w * tau)
        acc = -s.amplitude_rad * w * w * math.sin(w * tau)
        return TargetSample(_rotation(q, e, theta), rate * e, acc * e, self.frame, 0.0,
                            'track')


def guidance_from_params(t_s: Sequence[float], types: Sequence[str],
                         q_xyzw: Sequence[float], duration_s: Sequence[float],
                         axis_body: Sequence[float], amplitude_deg: Sequence[float],
                         period_s: Sequence[float], frame: str) -> Guidance:
    """Flat per-segment arrays (ROS parameters) -> :class:`Guidance`.

    ``q_xyzw`` and ``axis_body`` hold 4 and 3 values per segment.
    """
    n = len(t_s)
    lens = {'types': len(types), 'duration_s': len(duration_s),
            'amplitude_deg': len(amplitude_deg), 'period_s': len(period_s),
            'q_xyzw/4': len(q_xyzw) / 4, 'axis_body/3': len(axis_body) / 3}
    bad = {k: v for k, v in lens.items() if v != n}
    if bad:
        raise ValueError(f'guidance profile arrays differ in length from t_s ({n}): {bad}')
    segs = [Segment(float(t_s[i]), str(types[i]), np.asarray(q_xyzw[4 * i:4 * i + 4], float),
                    float(duration_s[i]), np.asarray(axis_body[3 * i:3 * i + 3], float),
                    math.radians(float(amplitude_deg[i])), float(period_s[i]))
            for i in range(n)]
    return Guidance(segs, frame)
