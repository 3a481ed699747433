"""Message -> core conversion of each sensor input, with its plausibility checks (pure).

Each function returns ``(value, None)`` or ``(None, why)``: the estimator counts a rejection
with its reason, a controller simply reads nothing. Sensor frames are rotated into body axes
with the mount of the sample's ``header.frame_id`` (``mounts.lookup``: ``/tf_static`` in a
graph, the sensors' parameters in the FrameLoop).
"""
from __future__ import annotations

import math
from typing import Any, Optional, Tuple

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.nodes.convert import all_finite, quat, vec3

Checked = Tuple[Optional[Any], Optional[str]]


def field_body(msg: Any, mounts: Any,
               field_range: Optional[Tuple[float, float]] = None) -> Checked:
    """Magnetometer sample in body axes [T]: finite, ``|B|`` inside ``field_range`` (when
    given), a known mount."""
    b_sensor = vec3(msg.magnetic_field)
    if not all_finite(b_sensor):
        return None, 'magnetometer sample is not finite'
    if field_range is not None:
        norm = float(np.linalg.norm(b_sensor))
        lo, hi = field_range
        if not lo <= norm <= hi:
            return None, f'magnetometer |B| = {norm:.3g} T outside [{lo:g}, {hi:g}] T'
    q_body_sensor = mounts.lookup(msg.header.frame_id)
    if q_body_sensor is None:
        return None, f'no /tf_static mount body -> {msg.header.frame_id!r}'
    return att.rotate(q_body_sensor, b_sensor), None


def horizon_roll_pitch(msg: Any) -> Checked:
    """(roll, pitch) [rad] of a valid horizon-sensor sample."""
    if not msg.valid or not math.isfinite(msg.roll) or not math.isfinite(msg.pitch):
        return None, 'horizon sensor sample invalid (out of view or not finite)'
    return (float(msg.roll), float(msg.pitch)), None


def gyro_rate_body(msg: Any, mounts: Any) -> Checked:
    """Gyro rate in body axes [rad/s]: finite, a known mount."""
    w = vec3(msg.angular_velocity)
    if not all_finite(w):
        return None, 'gyro sample is not finite'
    q_body_sensor = mounts.lookup(msg.header.frame_id)
    if q_body_sensor is None:
        return None, f'no /tf_static mount body -> {msg.header.frame_id!r}'
    return att.rotate(q_body_sensor, w), None


def star_q_eci_body(msg: Any) -> Checked:
    """Star-tracker ``q_eci_body`` (scalar last): finite and a unit quaternion (to 1e-3)."""
    q = quat(msg.orientation)
    if not all_finite(q) or abs(float(np.linalg.norm(q)) - 1.0) > 1e-3:
        return None, 'star tracker attitude not finite or not a unit quaternion'
    return att.normalize(q), None


def wheel_speeds(msg: Any, n_wheels: int) -> Checked:
    """Measured wheel speeds [rad/s]: the configured count, finite."""
    if len(msg.velocity) != n_wheels:
        return None, f'{len(msg.velocity)} wheel speeds for {n_wheels} wheels'
    w = np.asarray(msg.velocity, dtype=float)
    return (w, None) if all_finite(w) else (None, 'wheel speeds not finite')


def applied_dipole(msg: Any) -> np.ndarray:
    """The dipole of an applied command [A m^2, body]; zero when absent or not finite."""
    dipole = vec3(msg.dipole_body) if msg is not None else np.zeros(3)
    return dipole if all_finite(dipole) else np.zeros(3)
