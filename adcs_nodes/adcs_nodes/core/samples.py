"""The data that flows between components, one immutable type per topic (DESIGN section 6):
named tuples, the lightest immutable record in Python (a frame makes a dozen).

Every sample carries ``t_ns``: elapsed sim time [ns] of its stamp (a message's stamp is the
run's epoch plus ``t_ns``). Arrays are float64, quaternions ``[x, y, z, w]`` (scalar last),
names say frame and unit. Sensor samples are as the sensor measured them (sensor axes, its
``frame_id``, its covariance); conditioning (mount rotation, plausibility) is the consumer's.
The converters to and from ROS messages are :mod:`adcs_nodes.msgs.convert` (bit-exact both
ways). Pure Python: no message type here.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Tuple

import numpy as np

Array = np.ndarray


def all_finite(*arrays) -> bool:
    """True when every value of every array is finite (small ones value by value: several
    times faster than ``np.isfinite(a).all()`` for the 3- and 4-vectors here)."""
    isfinite = math.isfinite
    for a in arrays:
        a = np.asarray(a)
        if a.size > 16:
            if not np.isfinite(a).all():
                return False
        else:
            v = a.ravel().tolist()               # a finite sum: all finite
            if not isfinite(sum(v)) and not all(map(isfinite, v)):
                return False
    return True


class Tick(NamedTuple):
    """``/clock``: the frame's sim time."""
    t_ns: int


class EnvironmentSample(NamedTuple):
    """``sim/environment``: orbit state and geomagnetic field (truth models), ECI axes."""
    t_ns: int
    r_eci_m: Array                      #: (3,) position [m]
    v_eci_m_s: Array                    #: (3,) velocity [m/s]
    q_eci_orbit: Array                  #: (4,) orbit frame -> ECI
    omega_orbit_eci_eci: Array          #: (3,) orbit-frame rate w.r.t. ECI [rad/s]
    orbit_rate_rad_s: float
    arg_latitude_rad: float
    b_eci_T: Array                      #: (3,) field [T]
    b_dot_eci_T_s: Array                #: (3,) its rate along the orbit [T/s]
    q_eci_ecef: Array                   #: (4,) Earth rotation


class AttitudeState(NamedTuple):
    """``sim/state`` (truth) and ``adcs/attitude_estimate``: attitude and rate of the body."""
    t_ns: int
    q_eci_body: Array                   #: (4,)
    q_orbit_body: Array                 #: (4,)
    omega_body_eci_body: Array          #: (3,) [rad/s]
    omega_body_orbit_body: Array        #: (3,) [rad/s]
    covariance: Array                   #: (36,) row-major 6x6 of (attitude, rate); 0: truth


class FaultEvent(NamedTuple):
    """One fault starting (``active``) or ending in a frame."""
    index: int
    active: bool
    kind: str
    target: str
    description: str                            #: ``Fault.describe()``
    params: Tuple[Tuple[str, str], ...] = ()    #: sorted ``(name, str(value))``


class FaultEvents(NamedTuple):
    """``sim/faults``: the faults that start or end in frame ``t_ns``."""
    t_ns: int
    events: Tuple[FaultEvent, ...]


class WheelState(NamedTuple):
    """``sim/wheels``: the reaction wheels (truth)."""
    t_ns: int
    names: Tuple[str, ...]
    momentum_Nms: Array                 #: (n,) about each wheel axis
    speed_rad_s: Array                  #: (n,) relative to the body; (0,) without wheels
    torque_Nm: Array                    #: (n,) applied motor torque; (0,) without wheels
    h_wheels_body_Nms: Array            #: (3,) total wheel momentum, body axes


class AppendageState(NamedTuple):
    """``sim/appendages``: modal coordinates of the flexible appendages."""
    t_ns: int
    eta: Array
    eta_dot: Array
    frequency_hz: Array


class MagnetometerSample(NamedTuple):
    """``sensors/magnetometer``: the field in sensor axes (NaN: a lost sample)."""
    t_ns: int
    frame_id: str
    b_sensor_T: Array                   #: (3,)
    covariance_T2: Array                #: (9,) row-major, sensor axes; zeros: unknown


class GyroSample(NamedTuple):
    """``sensors/gyro``: measured body rate w.r.t. ECI in sensor axes."""
    t_ns: int
    frame_id: str
    omega_sensor_rad_s: Array           #: (3,)
    covariance: Array                   #: (9,) row-major [rad^2/s^2]


class StarTrackerSample(NamedTuple):
    """``sensors/star_tracker``: measured inertial attitude."""
    t_ns: int
    frame_id: str
    q_eci_body: Array                   #: (4,)
    covariance: Array                   #: (9,) row-major [rad^2]


class HorizonSample(NamedTuple):
    """``sensors/horizon``: roll and pitch of the body w.r.t. the orbit frame."""
    t_ns: int
    frame_id: str
    roll_rad: float
    pitch_rad: float
    roll_variance_rad2: float
    pitch_variance_rad2: float
    valid: bool                         #: False: the Earth out of view


class WheelSpeeds(NamedTuple):
    """``sensors/wheels``: measured wheel speeds (a tachometer)."""
    t_ns: int
    frame_id: str
    names: Tuple[str, ...]
    speed_rad_s: Array


class FilterDiagnostics(NamedTuple):
    """``adcs/estimator/diagnostics`` of the estimate stamped ``t_ns``."""
    t_ns: int
    algorithm: str
    innovation: Tuple[float, ...]
    covariance_trace: float
    update_count: int
    rejected_count: int
    last_rejection: str


class AttitudeTarget(NamedTuple):
    """``adcs/attitude_target`` as guidance published it (a consumer checks it)."""
    t_ns: int
    frame: str                          #: ``orbit`` or ``eci``
    q_ref_body: Array                   #: (4,)
    omega_body_ref_body: Array          #: (3,) [rad/s]
    omega_dot_body_ref_body: Array      #: (3,) [rad/s^2]
    time_to_go_s: float
    profile: str


class ActuatorCommand(NamedTuple):
    """``adcs/actuator_command`` and ``adcs/controllers/<name>/command``: a command as sent
    (``source``: the controller, ``'<name>: <why>'`` for an invalid one)."""
    t_ns: int
    dipole_body_Am2: Array              #: (3,)
    wheel_torque_Nm: Array              #: (n,) scenario order; (0,): none
    torque_body_Nm: Array               #: (3,) ideal body torque
    source: str


class MagnetorquerCommand(NamedTuple):
    """``actuators/magnetorquer/command``: the commanded dipole, body axes."""
    t_ns: int
    dipole_body_Am2: Array


class WheelCommand(NamedTuple):
    """``actuators/wheels/command``: the commanded motor torques by wheel name."""
    t_ns: int
    names: Tuple[str, ...]
    torque_Nm: Tuple[float, ...]


class ControllerStatus(NamedTuple):
    """``adcs/controller_status``: what the manager forwards."""
    t_ns: int
    active: str
    available: Tuple[str, ...]
    mode: str
    switch_count: int
    missed_frames: int
    last_fault: str
