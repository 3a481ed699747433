"""The simulated sensors' frame step: truth messages of frame t -> the sensor's sample message.

Each sensor component wraps the model its registry entry builds (:mod:`sim_node.entries`,
:mod:`sim_node.models.sensors`) with the node's random seed ``derive_seed(seed, name)``, and
stamps its samples with the frame and its ``frame_id`` (the child frame of its ``/tf_static``
mount). A missing or non-finite truth gives no sample (a warning); a magnetometer dropout a
NaN field (the ROS convention for "no data"); a horizon sensor without the Earth in view
``valid = false``.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Type

import numpy as np
from sensor_msgs.msg import Imu, JointState, MagneticField

from adcs_msgs.msg import HorizonSensor as HorizonMsg
from adcs_nodes.components.base import FrameClock, Log, silent
from adcs_nodes.core import attitude as att
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.nodes.convert import all_finite, quat, to_quat, to_vec3, vec3
from sim_node.faults import SensorFaults, parse


class SensorComponent:
    """Base: a sensor model sampled on the truth of a frame.

    Parameters
    ----------
    model
        The sensor model (``entry.build(params, {'seed': ...})``).
    frame_id : str
        ``header.frame_id`` of the samples.
    clock : FrameClock
    log : Log
    """

    #: The truth topics it reads: ``('state', 'env')`` or ``('wheels',)``.
    truth = ('state', 'env')

    def __init__(self, model: Any, frame_id: str, clock: FrameClock, log: Log = silent,
                 faults: Optional[SensorFaults] = None) -> None:
        self.model = model
        self.faults = faults
        self.frame_id = frame_id
        self.clock = clock
        self.log = log
        self.covariance = (model.covariance.reshape(-1).tolist()
                           if hasattr(model, 'covariance') else None)

    def header(self, msg: Any, t_ns: int) -> Any:
        """Stamp ``msg`` with frame ``t_ns`` and this sensor's frame id; returns it."""
        msg.header.stamp = self.clock.stamp(t_ns)
        msg.header.frame_id = self.frame_id
        return msg

    def truth_ok(self, t_ns: int, what: str, *arrays: np.ndarray) -> bool:
        """True when every truth array is finite and non-zero; else warn (no sample)."""
        if all_finite(*arrays) and all(np.any(a) for a in arrays):
            return True
        self.log('warning', f't={t_ns / NS_PER_S:.3f} s: non-finite truth ({what}), no sample')
        return False

    def step(self, t_ns: int, truth: Dict[str, Any]) -> Optional[Any]:
        """The sample message of frame ``t_ns`` from the truth messages, or None."""
        if any(truth.get(k) is None for k in self.truth):
            self.log('warning', f't={t_ns / NS_PER_S:.3f} s: no truth yet, no sample')
            return None
        msg = self.sample(t_ns, *(truth[k] for k in self.truth))
        if msg is None or self.faults is None:
            return msg
        values = self.faults.apply(t_ns, self.values(msg))      # the scenario's faults
        return None if values is None else self.with_values(msg, values)

    def sample(self, t_ns: int, *truth: Any) -> Optional[Any]:
        raise NotImplementedError     # pragma: no cover (every sensor defines it)

    def values(self, msg: Any) -> np.ndarray:
        """The sample's measured values (what a fault changes)."""
        raise NotImplementedError     # pragma: no cover (every sensor defines it)

    def with_values(self, msg: Any, values: np.ndarray) -> Any:
        """``msg`` with its measured values replaced."""
        raise NotImplementedError     # pragma: no cover (every sensor defines it)


class MagnetometerComponent(SensorComponent):
    """``sensors/magnetometer``: the truth field in the sensor frame [T]."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.dropouts = 0

    def sample(self, t_ns: int, state: Any, env: Any) -> Optional[MagneticField]:
        q_eci_body, b_eci = quat(state.q_eci_body), vec3(env.b_eci)
        if not self.truth_ok(t_ns, 'q_eci_body or b_eci', q_eci_body, b_eci):
            return None
        b_sensor = self.model.measure(att.to_matrix(q_eci_body).T @ b_eci)
        if b_sensor is None:
            # a lost sample is published as NaN (the ROS convention for "no data"), so the
            # lockstep goes on and the estimator counts it as rejected instead of waiting
            self.dropouts += 1
            self.log('debug', f't={t_ns / NS_PER_S:.3f} s: dropout ({self.dropouts})')
            b_sensor = np.full(3, np.nan)
        msg = self.header(MagneticField(), t_ns)
        msg.magnetic_field = to_vec3(b_sensor)
        msg.magnetic_field_covariance = self.covariance
        return msg

    def values(self, msg: MagneticField) -> np.ndarray:
        return vec3(msg.magnetic_field)

    def with_values(self, msg: MagneticField, values: np.ndarray) -> MagneticField:
        msg.magnetic_field = to_vec3(values)
        return msg


class GyroComponent(SensorComponent):
    """``sensors/gyro``: the measured body rate [rad/s, body axes]; the bias random walk spans
    the sim time since the previous sample."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._last_t_ns: Optional[int] = None

    def sample(self, t_ns: int, state: Any, env: Any) -> Optional[Imu]:
        omega = vec3(state.omega_body_eci_body)
        if not all_finite(omega):
            self.truth_ok(t_ns, 'omega_body_eci_body', omega)   # logs the warning
            return None
        dt = 0.0 if self._last_t_ns is None else (t_ns - self._last_t_ns) / NS_PER_S
        self._last_t_ns = t_ns
        msg = self.header(Imu(), t_ns)
        msg.angular_velocity = to_vec3(self.model.measure(omega, dt))
        msg.angular_velocity_covariance = self.covariance
        msg.orientation_covariance[0] = -1.0
        msg.linear_acceleration_covariance[0] = -1.0
        return msg

    def values(self, msg: Imu) -> np.ndarray:
        return vec3(msg.angular_velocity)

    def with_values(self, msg: Imu, values: np.ndarray) -> Imu:
        msg.angular_velocity = to_vec3(values)
        return msg


class StarTrackerComponent(SensorComponent):
    """``sensors/star_tracker``: the measured ``q_eci_body`` (``Imu.orientation``)."""

    def sample(self, t_ns: int, state: Any, env: Any) -> Optional[Imu]:
        q_eci_body = quat(state.q_eci_body)
        if not self.truth_ok(t_ns, 'q_eci_body', q_eci_body):
            return None
        msg = self.header(Imu(), t_ns)
        msg.orientation = to_quat(self.model.measure(q_eci_body))
        msg.orientation_covariance = self.covariance
        msg.angular_velocity_covariance[0] = -1.0
        msg.linear_acceleration_covariance[0] = -1.0
        return msg

    def values(self, msg: Imu) -> np.ndarray:
        return quat(msg.orientation)

    def with_values(self, msg: Imu, values: np.ndarray) -> Imu:
        msg.orientation = to_quat(values)
        return msg


class HorizonSensorComponent(SensorComponent):
    """``sensors/horizon``: roll and pitch of the body w.r.t. the orbit frame from the zenith
    ``R(q_eci_body)^T r_eci / |r_eci|``; ``valid = false`` out of view."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.invalid = 0

    def sample(self, t_ns: int, state: Any, env: Any) -> Optional[HorizonMsg]:
        q_eci_body, r_eci = quat(state.q_eci_body), vec3(env.r_eci)
        if not self.truth_ok(t_ns, 'q_eci_body or r_eci', q_eci_body, r_eci):
            return None
        zenith_body = att.to_matrix(q_eci_body).T @ (r_eci / np.linalg.norm(r_eci))
        m = self.model.measure_zenith(zenith_body)
        if not m.valid:
            self.invalid += 1
        var = self.model.variance
        msg = self.header(HorizonMsg(), t_ns)
        msg.roll = float(m.roll)
        msg.pitch = float(m.pitch)
        msg.roll_variance = float(var[0])
        msg.pitch_variance = float(var[1])
        msg.valid = bool(m.valid)
        return msg

    def values(self, msg: HorizonMsg) -> np.ndarray:
        return np.array([msg.roll, msg.pitch])

    def with_values(self, msg: HorizonMsg, values: np.ndarray) -> HorizonMsg:
        msg.roll, msg.pitch = float(values[0]), float(values[1])
        msg.valid = bool(msg.valid and np.all(np.isfinite(values)))
        return msg


class WheelTachometerComponent(SensorComponent):
    """``sensors/wheels``: measured wheel speeds relative to the body [rad/s]."""

    truth = ('wheels',)

    def sample(self, t_ns: int, wheels: Any) -> Optional[JointState]:
        speed = np.asarray(wheels.speed, dtype=float)
        if not np.all(np.isfinite(speed)):
            self.log('warning', f't={t_ns / NS_PER_S:.3f} s: non-finite wheel speed, no sample')
            return None
        msg = self.header(JointState(), t_ns)
        msg.name = list(wheels.names)
        msg.velocity = [float(v) for v in self.model.measure(speed)]
        return msg

    def values(self, msg: JointState) -> np.ndarray:
        return np.asarray(msg.velocity, dtype=float)

    def with_values(self, msg: JointState, values: np.ndarray) -> JointState:
        msg.velocity = [float(v) for v in values]
        return msg


#: The component of each registered sensor model, by registry name.
SENSOR_COMPONENTS: Dict[str, Type[SensorComponent]] = {
    'magnetometer': MagnetometerComponent,
    'gyro': GyroComponent,
    'star_tracker': StarTrackerComponent,
    'horizon_sensor': HorizonSensorComponent,
    'wheel_tachometer': WheelTachometerComponent,
}


def sensor_faults(sensor: str, text: str, seed: int) -> Optional[SensorFaults]:
    """The faults of a sensor from its node parameter ``faults`` (JSON; '' none), seeded from
    the scenario ``seed``; a star tracker's bias is a rotation."""
    faults = parse(text)
    return SensorFaults(faults, seed, rotation=sensor == 'star_tracker') if faults else None
