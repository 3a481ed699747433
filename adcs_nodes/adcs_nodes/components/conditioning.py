"""Core sample -> checked value of each sensor input, in body axes (pure).

Each function returns ``(value, None)`` or ``(None, why)``: the estimator counts a rejection
with its reason, a controller simply reads nothing. Sensor frames are rotated into body axes
with the mount of the sample's ``frame_id`` (``mounts.lookup``: ``/tf_static`` in a graph,
the sensors' parameters in the FrameLoop).
"""
from __future__ import annotations

import math
from typing import Any, Optional, Tuple

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.core.samples import (ActuatorCommand, GyroSample, HorizonSample,
                                     MagnetometerSample, StarTrackerSample, WheelSpeeds,
                                     all_finite)

Checked = Tuple[Optional[Any], Optional[str]]


def field_body(x: MagnetometerSample, mounts: Any,
               field_range: Optional[Tuple[float, float]] = None) -> Checked:
    """Magnetometer sample in body axes [T]: finite, ``|B|`` inside ``field_range`` (when
    given), a known mount."""
    b_sensor = x.b_sensor_T
    if not all_finite(b_sensor):
        return None, 'magnetometer sample is not finite'
    if field_range is not None:
        norm = float(np.linalg.norm(b_sensor))
        lo, hi = field_range
        if not lo <= norm <= hi:
            return None, f'magnetometer |B| = {norm:.3g} T outside [{lo:g}, {hi:g}] T'
    q_body_sensor = mounts.lookup(x.frame_id)
    if q_body_sensor is None:
        return None, f'no /tf_static mount body -> {x.frame_id!r}'
    return att.rotate(q_body_sensor, b_sensor), None


def horizon_roll_pitch(x: HorizonSample) -> Checked:
    """(roll, pitch) [rad] of a valid horizon-sensor sample."""
    if not x.valid or not math.isfinite(x.roll_rad) or not math.isfinite(x.pitch_rad):
        return None, 'horizon sensor sample invalid (out of view or not finite)'
    return (float(x.roll_rad), float(x.pitch_rad)), None


def gyro_rate_body(x: GyroSample, mounts: Any) -> Checked:
    """Gyro rate in body axes [rad/s]: finite, a known mount."""
    if not all_finite(x.omega_sensor_rad_s):
        return None, 'gyro sample is not finite'
    q_body_sensor = mounts.lookup(x.frame_id)
    if q_body_sensor is None:
        return None, f'no /tf_static mount body -> {x.frame_id!r}'
    return att.rotate(q_body_sensor, x.omega_sensor_rad_s), None


def star_q_eci_body(x: StarTrackerSample) -> Checked:
    """Star-tracker ``q_eci_body`` (scalar last): finite and a unit quaternion (to 1e-3)."""
    q = x.q_eci_body
    if not all_finite(q) or abs(float(np.linalg.norm(q)) - 1.0) > 1e-3:
        return None, 'star tracker attitude not finite or not a unit quaternion'
    return att.normalize(q), None


def wheel_speeds(x: WheelSpeeds, n_wheels: int) -> Checked:
    """Measured wheel speeds [rad/s]: the configured count, finite."""
    if len(x.speed_rad_s) != n_wheels:
        return None, f'{len(x.speed_rad_s)} wheel speeds for {n_wheels} wheels'
    w = np.array(x.speed_rad_s, dtype=float)
    return (w, None) if all_finite(w) else (None, 'wheel speeds not finite')


def applied_dipole(x: Optional[ActuatorCommand]) -> np.ndarray:
    """The dipole of an applied command [A m^2, body]; zero when absent or not finite."""
    if x is None or not all_finite(x.dipole_body_Am2):
        return np.zeros(3)
    return np.array(x.dipole_body_Am2, dtype=float)
