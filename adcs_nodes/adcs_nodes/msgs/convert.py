"""Core sample <-> ROS message, one :class:`Converter` per topic kind, bit-exact both ways.

``to_msg(sample, epoch_ns)`` makes the message the nodes publish and the bags hold (stamp =
epoch + ``sample.t_ns``); ``to_core(msg, epoch_ns)`` reads one back into the core type
(:mod:`adcs_nodes.core.samples`), values as sent (no checks: those are the consumer's). The
input records name the converter of their topic (:mod:`adcs_nodes.inputs`); :data:`TOPICS`
has the others.
"""
from __future__ import annotations

from typing import Any, Callable, NamedTuple, Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState, MagneticField
from std_msgs.msg import Header

from adcs_msgs import msg as m
from adcs_nodes.core import samples as s
from adcs_nodes.msgs.fields import make, quat, stamp_ns, to_quat, to_stamp, to_vec3, vec3


class Converter(NamedTuple):
    """``to_msg(sample, epoch_ns) -> message`` and ``to_core(message, epoch_ns) -> sample``."""

    to_msg: Callable[[Any, int], Any]
    to_core: Callable[[Any, int], Any]


def _header(t_ns: int, epoch_ns: int, frame_id: str) -> Header:
    return make(Header, stamp=to_stamp(epoch_ns + t_ns), frame_id=frame_id)


def _t(msg: Any, epoch_ns: int) -> int:
    return stamp_ns(msg.header.stamp) - epoch_ns


def _f64(seq: Any) -> np.ndarray:
    """A sequence field -> float64 array (copied)."""
    return np.array(seq, dtype=float)


def _list(a: Any) -> list:
    return np.asarray(a, dtype=float).tolist()


# ---------------------------------------------------------------------- the world
CLOCK = Converter(lambda x, e: make(Clock, clock=to_stamp(e + x.t_ns)),
                  lambda msg, e: s.Tick(stamp_ns(msg.clock) - e))


ENVIRONMENT = Converter(
    lambda x, e: make(m.Environment, header=_header(x.t_ns, e, 'eci'), r_eci=to_vec3(x.r_eci_m),
                      v_eci=to_vec3(x.v_eci_m_s), q_eci_orbit=to_quat(x.q_eci_orbit),
                      omega_orbit_eci_eci=to_vec3(x.omega_orbit_eci_eci),
                      orbit_rate=float(x.orbit_rate_rad_s),
                      argument_of_latitude=float(x.arg_latitude_rad),
                      b_eci=to_vec3(x.b_eci_T), b_dot_eci=to_vec3(x.b_dot_eci_T_s),
                      q_eci_ecef=to_quat(x.q_eci_ecef)),
    lambda msg, e: s.EnvironmentSample(
        _t(msg, e), vec3(msg.r_eci), vec3(msg.v_eci), quat(msg.q_eci_orbit),
        vec3(msg.omega_orbit_eci_eci), msg.orbit_rate, msg.argument_of_latitude,
        vec3(msg.b_eci), vec3(msg.b_dot_eci), quat(msg.q_eci_ecef)))

ATTITUDE_STATE = Converter(
    lambda x, e: make(m.AttitudeState, header=_header(x.t_ns, e, 'body'),
                      q_eci_body=to_quat(x.q_eci_body), q_orbit_body=to_quat(x.q_orbit_body),
                      omega_body_eci_body=to_vec3(x.omega_body_eci_body),
                      omega_body_orbit_body=to_vec3(x.omega_body_orbit_body),
                      covariance=x.covariance),
    lambda msg, e: s.AttitudeState(
        _t(msg, e), quat(msg.q_eci_body), quat(msg.q_orbit_body),
        vec3(msg.omega_body_eci_body), vec3(msg.omega_body_orbit_body),
        _f64(msg.covariance)))


def _faults_msg(x: s.FaultEvents, e: int) -> DiagnosticArray:
    return DiagnosticArray(header=_header(x.t_ns, e, ''), status=[DiagnosticStatus(
        level=DiagnosticStatus.WARN if ev.active else DiagnosticStatus.OK,
        name=f'fault/{ev.index}', hardware_id=ev.target,
        message=('active: ' if ev.active else 'cleared: ') + ev.description,
        values=[KeyValue(key='kind', value=ev.kind), KeyValue(key='target', value=ev.target),
                *(KeyValue(key=k, value=v) for k, v in ev.params)]) for ev in x.events])


def _faults_core(msg: DiagnosticArray, e: int) -> s.FaultEvents:
    events = []
    for st in msg.status:
        active = st.level == DiagnosticStatus.WARN
        events.append(s.FaultEvent(
            int(st.name.rpartition('/')[2]), active, st.values[0].value, st.values[1].value,
            st.message.partition(': ')[2],
            tuple((kv.key, kv.value) for kv in st.values[2:])))
    return s.FaultEvents(_t(msg, e), tuple(events))


FAULTS = Converter(_faults_msg, _faults_core)

WHEEL_STATE = Converter(
    lambda x, e: make(m.WheelState, header=_header(x.t_ns, e, 'body'), names=list(x.names),
                      momentum=_list(x.momentum_Nms), speed=_list(x.speed_rad_s),
                      torque=_list(x.torque_Nm), h_wheels_body=to_vec3(x.h_wheels_body_Nms)),
    lambda msg, e: s.WheelState(_t(msg, e), tuple(msg.names), _f64(msg.momentum),
                                _f64(msg.speed), _f64(msg.torque), vec3(msg.h_wheels_body)))

APPENDAGES = Converter(
    lambda x, e: make(m.AppendageState, header=_header(x.t_ns, e, 'body'), eta=_list(x.eta),
                      eta_dot=_list(x.eta_dot), frequency_hz=_list(x.frequency_hz)),
    lambda msg, e: s.AppendageState(_t(msg, e), _f64(msg.eta), _f64(msg.eta_dot),
                                    _f64(msg.frequency_hz)))


# ---------------------------------------------------------------------- sensors
#: ``covariance[0] = -1``: not provided (REP 145).
_NOT_PROVIDED = (-1.0,) + (0.0,) * 8
_ZERO3, _UNIT_Q = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)


def _imu(x: Any, e: int, q: Any, q_cov: Any, w: Any, w_cov: Any) -> Imu:
    return make(Imu, header=_header(x.t_ns, e, x.frame_id), orientation=to_quat(q),
                orientation_covariance=q_cov, angular_velocity=to_vec3(w),
                angular_velocity_covariance=w_cov, linear_acceleration=to_vec3(_ZERO3),
                linear_acceleration_covariance=_NOT_PROVIDED)


MAGNETOMETER = Converter(
    lambda x, e: make(MagneticField, header=_header(x.t_ns, e, x.frame_id),
                      magnetic_field=to_vec3(x.b_sensor_T),
                      magnetic_field_covariance=x.covariance_T2),
    lambda msg, e: s.MagnetometerSample(_t(msg, e), msg.header.frame_id,
                                        vec3(msg.magnetic_field),
                                        _f64(msg.magnetic_field_covariance)))
GYRO = Converter(
    lambda x, e: _imu(x, e, _UNIT_Q, _NOT_PROVIDED, x.omega_sensor_rad_s, x.covariance),
    lambda msg, e: s.GyroSample(_t(msg, e), msg.header.frame_id, vec3(msg.angular_velocity),
                                _f64(msg.angular_velocity_covariance)))
STAR_TRACKER = Converter(
    lambda x, e: _imu(x, e, x.q_eci_body, x.covariance, _ZERO3, _NOT_PROVIDED),
    lambda msg, e: s.StarTrackerSample(_t(msg, e), msg.header.frame_id, quat(msg.orientation),
                                       _f64(msg.orientation_covariance)))
HORIZON = Converter(
    lambda x, e: make(m.HorizonSensor, header=_header(x.t_ns, e, x.frame_id),
                      roll=float(x.roll_rad), pitch=float(x.pitch_rad),
                      roll_variance=float(x.roll_variance_rad2),
                      pitch_variance=float(x.pitch_variance_rad2), valid=bool(x.valid)),
    lambda msg, e: s.HorizonSample(_t(msg, e), msg.header.frame_id, msg.roll, msg.pitch,
                                   msg.roll_variance, msg.pitch_variance, msg.valid))
WHEEL_SPEEDS = Converter(
    lambda x, e: make(JointState, header=_header(x.t_ns, e, x.frame_id), name=list(x.names),
                      position=[], velocity=_list(x.speed_rad_s), effort=[]),
    lambda msg, e: s.WheelSpeeds(_t(msg, e), msg.header.frame_id, tuple(msg.name),
                                 _f64(msg.velocity)))


# ---------------------------------------------------------------------- flight software
DIAGNOSTICS = Converter(
    lambda x, e: make(m.FilterDiagnostics, header=_header(x.t_ns, e, 'body'),
                      algorithm=x.algorithm, innovation=list(x.innovation),
                      covariance_trace=float(x.covariance_trace),
                      update_count=int(x.update_count), rejected_count=int(x.rejected_count),
                      last_rejection=x.last_rejection),
    lambda msg, e: s.FilterDiagnostics(_t(msg, e), msg.algorithm, tuple(msg.innovation),
                                       msg.covariance_trace, msg.update_count,
                                       msg.rejected_count, msg.last_rejection))

TARGET = Converter(
    lambda x, e: make(m.AttitudeTarget, header=_header(x.t_ns, e, x.frame),
                      q_ref_body=to_quat(x.q_ref_body),
                      omega_body_ref_body=to_vec3(x.omega_body_ref_body),
                      omega_dot_body_ref_body=to_vec3(x.omega_dot_body_ref_body),
                      time_to_go_s=float(x.time_to_go_s), profile=x.profile),
    lambda msg, e: s.AttitudeTarget(_t(msg, e), msg.header.frame_id, quat(msg.q_ref_body),
                                    vec3(msg.omega_body_ref_body),
                                    vec3(msg.omega_dot_body_ref_body), msg.time_to_go_s,
                                    msg.profile))

COMMAND = Converter(
    lambda x, e: make(m.ActuatorCommand, header=_header(x.t_ns, e, 'body'),
                      dipole_body=to_vec3(x.dipole_body_Am2),
                      wheel_torque=_list(x.wheel_torque_Nm),
                      torque_body=to_vec3(x.torque_body_Nm), source=x.source),
    lambda msg, e: s.ActuatorCommand(_t(msg, e), vec3(msg.dipole_body),
                                     _f64(msg.wheel_torque), vec3(msg.torque_body),
                                     msg.source))

MAGNETORQUER_COMMAND = Converter(
    lambda x, e: make(Vector3Stamped, header=_header(x.t_ns, e, 'body'),
                      vector=to_vec3(x.dipole_body_Am2)),
    lambda msg, e: s.MagnetorquerCommand(_t(msg, e), vec3(msg.vector)))


WHEEL_COMMAND = Converter(
    lambda x, e: make(JointState, header=_header(x.t_ns, e, ''), name=list(x.names),
                      position=[], velocity=[], effort=[float(v) for v in x.torque_Nm]),
    lambda msg, e: s.WheelCommand(_t(msg, e), tuple(msg.name), tuple(msg.effort)))
CONTROLLER_STATUS = Converter(
    lambda x, e: make(m.ControllerStatus, header=_header(x.t_ns, e, ''), active=x.active,
                      available=list(x.available), mode=x.mode,
                      switch_count=int(x.switch_count), missed_frames=int(x.missed_frames),
                      last_fault=x.last_fault),
    lambda msg, e: s.ControllerStatus(_t(msg, e), msg.active, tuple(msg.available), msg.mode,
                                      msg.switch_count, msg.missed_frames, msg.last_fault))

#: The converters of the topics that are not an input record's (:mod:`adcs_nodes.inputs`).
TOPICS = {
    '/clock': CLOCK, 'sim/environment': ENVIRONMENT, 'sim/state': ATTITUDE_STATE,
    'sim/faults': FAULTS, 'sim/wheels': WHEEL_STATE, 'sim/appendages': APPENDAGES,
    'adcs/estimator/diagnostics': DIAGNOSTICS, 'adcs/controller_status': CONTROLLER_STATUS,
    'actuators/magnetorquer/command': MAGNETORQUER_COMMAND,
    'actuators/wheels/command': WHEEL_COMMAND,
}


def for_topic(topic: str) -> Optional[Converter]:
    """The converter of ``topic`` in :data:`TOPICS` (a controller's command topic too)."""
    topic = topic.lstrip('/') if topic != '/clock' else topic
    if topic.startswith('adcs/controllers/') and topic.endswith('/command'):
        return COMMAND
    return TOPICS.get(topic)
