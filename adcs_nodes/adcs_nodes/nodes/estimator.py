"""``estimator`` node: attitude and rate estimate from the sensors (flight software).

The algorithm is a registered estimator (parameter ``algorithm``; ``adcs list`` shows them):
the node converts messages to numpy, checks them, and calls the core's
``step(EstimatorInputs, t, dt)`` (:mod:`adcs_nodes.core.estimation.algorithms`). What it
subscribes to comes from the entry's ``inputs``:

* ``magnetometer``: ``sensors/magnetometer`` (``sensor_msgs/MagneticField``, sensor frame;
  rotated into body axes with the mount from ``/tf_static``);
* ``horizon``: ``sensors/horizon`` (``adcs_msgs/HorizonSensor``);
* ``star_tracker``, ``gyro``: ``sensors/star_tracker``, ``sensors/gyro`` (``sensor_msgs/Imu``);
* ``actuator_command``: ``adcs/actuator_command`` (the applied dipole, for the prediction).

Never ``sim/*``: the reference field and orbit are the flight software's own models
(``onboard_orbit.*``, ``onboard_field.*``).

Publishes ``adcs/attitude_estimate`` (``adcs_msgs/AttitudeState``: q to the orbit frame and to
ECI, rates, 6x6 covariance), ``adcs/estimator/diagnostics`` (``adcs_msgs/FilterDiagnostics``)
and ``/tf`` (``eci -> body_estimate``). Bad input (NaN, zero or implausible field, stale or
invalid sensor) is rejected with a warning and counted; a non-finite estimate is never
published.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional

import numpy as np
from sensor_msgs.msg import Imu, MagneticField
from std_msgs.msg import Header

from adcs_msgs.msg import ActuatorCommand, AttitudeState, FilterDiagnostics, HorizonSensor
from adcs_nodes import registry
from adcs_nodes.core import attitude as att
from adcs_nodes.core.estimation.algorithms import EstimatorInputs, omega_orbit_from_eci
from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.controller import DEFAULT_FIELD, DEFAULT_ORBIT, inertia_matrix
from adcs_nodes.nodes.convert import all_finite, quat, to_quat, to_vec3, vec3
from adcs_nodes.nodes.managed import ManagedLockstepNode
from adcs_nodes.nodes.messages import make
from adcs_nodes.nodes.tf import (MountTable, TfPublisher, covariance_to_body,
                                 estimate_transforms)
from adcs_nodes.registry import Param

#: What every estimator node knows besides its algorithm's own parameters.
CONTEXT_PARAMS = (
    Param('expected_mounts', 'str[]', [], '-', 'sensor frames whose /tf_static mount must '
          'have arrived before the node is ready (the launcher sets them)', read_only=True),
    Param('algorithm', 'str', 'magnetic_filter', '-', 'registered estimator algorithm',
          read_only=True),
    Param('period_s', 'float', 2.0, 's', 'estimator period', positive=True, read_only=True),
    Param('magnetometer_period_s', 'float', 10.0, 's', 'period of sensors/magnetometer',
          positive=True, read_only=True),
    Param('horizon_period_s', 'float', 1.0, 's', 'period of sensors/horizon', positive=True,
          read_only=True),
    Param('star_tracker_period_s', 'float', 1.0, 's', 'period of sensors/star_tracker',
          positive=True, read_only=True),
    Param('gyro_period_s', 'float', 1.0, 's', 'period of sensors/gyro', positive=True,
          read_only=True),
    Param('command_period_s', 'float', 0.0, 's', 'period of adcs/actuator_command (0: the '
          'latest command)', min=0.0, read_only=True),
    Param('inertia_kgm2', 'float[]', [118.0, 118.0, 19.6], 'kg m^2',
          'onboard inertia: 3 diagonal values or 9 (row-major)', read_only=True),
    Param('initial_q_orbit_body', 'float[]', [0.0, 0.0, 0.0, 1.0], '-',
          'initial attitude estimate, body -> orbit, scalar last', length=4, read_only=True),
    Param('initial_omega_body_orbit_body', 'float[]', [0.0, 0.0, 0.0], 'rad/s',
          'initial rate estimate w.r.t. the orbit frame, body axes', length=3,
          read_only=True),
    Param('min_field_T', 'float', 1e-6, 'T', 'smallest plausible |B| (smaller: rejected)',
          positive=True),
    Param('max_field_T', 'float', 1e-3, 'T', 'largest plausible |B| (larger: rejected)',
          positive=True),
)


class EstimatorNode(ManagedLockstepNode):
    """Attitude estimator (see module docstring); a managed node (:mod:`.managed`)."""

    def __init__(self, name: str = 'estimator', **kwargs: Any) -> None:
        super().__init__(name, **kwargs)

    def configure(self) -> None:
        """Parameters, onboard models, filter core and endpoints (lifecycle configure)."""
        registry.load_plugins(self.param('plugins', []))
        p = node_params.declare_all(self, CONTEXT_PARAMS)
        self.entry = registry.get('estimator', p['algorithm'])
        self.algorithm = self.entry.name
        own = node_params.declare_all(self, self.entry.params)
        self.mounts = MountTable(self)    # sensor mounts from /tf_static, by header.frame_id
        self.add_ready_check(lambda: self.mounts.missing(p['expected_mounts']))
        self.tf_pub = TfPublisher(self)   # /tf: eci -> body_estimate
        self.reference = make_onboard_reference(
            self.section('onboard_orbit', DEFAULT_ORBIT, merge=False),
            self.section('onboard_field', DEFAULT_FIELD, merge=False), self.epoch)
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.field_range = (p['min_field_T'], p['max_field_T'])
        ctx = {'inertia_kgm2': inertia_matrix(p['inertia_kgm2']), 'period_s': p['period_s'],
               'epoch': self.epoch, 'seed': self.seed, 'reference': self.reference}
        self.core = self.entry.build(own, ctx)
        self.core.initialise(att.normalize(p['initial_q_orbit_body']),
                             np.asarray(p['initial_omega_body_orbit_body'], dtype=float))
        topics = {
            'magnetometer': ('mag', MagneticField, 'sensors/magnetometer',
                             p['magnetometer_period_s']),
            'horizon': ('horizon', HorizonSensor, 'sensors/horizon', p['horizon_period_s']),
            'star_tracker': ('star', Imu, 'sensors/star_tracker', p['star_tracker_period_s']),
            'gyro': ('gyro', Imu, 'sensors/gyro', p['gyro_period_s']),
            'actuator_command': ('cmd', ActuatorCommand, 'adcs/actuator_command',
                                 p['command_period_s']),
        }
        # the command applied over [t_k-1, t_k] is the one stamped t_k-1: awaited (determinism)
        inputs = {key: (mtype, topic, period, 'previous' if key == 'cmd' else 'frame')
                  for need, (key, mtype, topic, period) in topics.items()
                  if need in self.entry.inputs}
        self.est_pub = self.publisher(AttitudeState, 'adcs/attitude_estimate')
        self.diag_pub = self.publisher(FilterDiagnostics, 'adcs/estimator/diagnostics')
        self.update_count = 0
        self.rejected_count = 0
        self.last_rejection = ''
        self._last_t: Optional[int] = None
        self.lockstep_inputs(inputs, p['period_s'], self.on_frame)
        self.start_handshake()

    # ------------------------------------------------------------------ inputs
    def _reject(self, why: str) -> None:
        self.rejected_count += 1
        self.last_rejection = why
        self.get_logger().warning(f'measurement rejected: {why}')

    def _mount(self, frame_id: str) -> Optional[np.ndarray]:
        q_body_sensor = self.mounts.lookup(frame_id)
        if q_body_sensor is None:
            self._reject(f'no /tf_static mount body -> {frame_id!r}')
        return q_body_sensor

    def _field_body(self, msg: MagneticField) -> Optional[np.ndarray]:
        """Magnetometer sample rotated into body axes, or None (rejected) if implausible."""
        b_sensor = vec3(msg.magnetic_field)
        if not all_finite(b_sensor):
            self._reject('magnetometer sample is not finite')
            return None
        norm = float(np.linalg.norm(b_sensor))
        lo, hi = self.field_range
        if not lo <= norm <= hi:
            self._reject(f'magnetometer |B| = {norm:.3g} T outside [{lo:g}, {hi:g}] T')
            return None
        q_body_sensor = self._mount(msg.header.frame_id)
        return None if q_body_sensor is None else att.rotate(q_body_sensor, b_sensor)

    def _field_var(self, msg: MagneticField) -> Optional[np.ndarray]:
        """Per-body-axis variances [T^2] of a sample's ``magnetic_field_covariance``, or None
        when the message gives none (all zeros, ``[0] = -1``) or its mount is unknown."""
        q_body_sensor = self.mounts.lookup(msg.header.frame_id)
        cov = None if q_body_sensor is None else covariance_to_body(
            msg.magnetic_field_covariance, q_body_sensor)
        return None if cov is None else np.diag(cov).copy()

    def _horizon(self, msg: HorizonSensor) -> Optional[tuple]:
        if not msg.valid or not math.isfinite(msg.roll) or not math.isfinite(msg.pitch):
            self._reject('horizon sensor sample invalid (out of view or not finite)')
            return None
        return (float(msg.roll), float(msg.pitch))

    def _gyro(self, msg: Imu) -> Optional[np.ndarray]:
        w = vec3(msg.angular_velocity)
        if not all_finite(w):
            self._reject('gyro sample is not finite')
            return None
        q_body_sensor = self._mount(msg.header.frame_id)
        return None if q_body_sensor is None else att.rotate(q_body_sensor, w)

    def _star(self, msg: Imu) -> Optional[np.ndarray]:
        q = quat(msg.orientation)
        if not all_finite(q) or abs(float(np.linalg.norm(q)) - 1.0) > 1e-3:
            self._reject('star tracker attitude not finite or not a unit quaternion')
            return None
        return att.normalize(q)

    def inputs_for(self, t_ns: int, msgs: Dict[str, Any]) -> EstimatorInputs:
        """Fresh, checked samples of frame ``t_ns`` -> the core's :class:`EstimatorInputs`."""
        def fresh(key, convert):
            msg = msgs.get(key)
            return convert(msg) if self.fresh(key, msg, t_ns) else None
        cmd = msgs.get('cmd')
        dipole = vec3(cmd.dipole_body) if cmd is not None else np.zeros(3)
        return EstimatorInputs(
            self.reference.at(t_ns / NS_PER_S), b_body=fresh('mag', self._field_body),
            horizon_roll_pitch=fresh('horizon', self._horizon),
            dipole_body=dipole if all_finite(dipole) else np.zeros(3),
            gyro_rate_body=fresh('gyro', self._gyro), q_eci_body_meas=fresh('star', self._star),
            b_body_var=fresh('mag', self._field_var))

    # ------------------------------------------------------------------ frame
    def on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """One estimator step at elapsed sim time ``t_ns``."""
        t = t_ns / NS_PER_S
        for topic in missing:
            self._reject(f'stale input {topic} at t={t:g} s (timeout)')
        inputs = self.inputs_for(t_ns, msgs)
        dt = 0.0 if self._last_t is None else (t_ns - self._last_t) / NS_PER_S
        self._last_t = t_ns
        step = self.core.step(inputs, t, dt)
        self.update_count += step.updates
        for why in step.rejections:
            self._reject(why)
        if step.estimate is not None:
            self._publish(t_ns, inputs.ref, step)

    # ------------------------------------------------------------------ output
    def _publish(self, t_ns: int, ref, step) -> None:
        est = step.estimate
        q_orbit_body = est.q_orbit_body
        q_eci_body = att.multiply(ref.q_eci_orbit, q_orbit_body)
        msg = make(AttitudeState, header=make(Header, stamp=self.stamp(t_ns), frame_id='body'),
                   q_eci_body=to_quat(q_eci_body), q_orbit_body=to_quat(q_orbit_body),
                   omega_body_eci_body=to_vec3(est.omega_body_eci_body),
                   omega_body_orbit_body=to_vec3(omega_orbit_from_eci(
                       q_orbit_body, est.omega_body_eci_body, ref.omega0)),
                   covariance=np.asarray(est.covariance, dtype=float).reshape(-1))
        self.est_pub.publish(msg)
        if self.tf_pub.wanted():          # /tf and the filter diagnostics: only when read
            self.tf_pub.send(estimate_transforms(msg.header.stamp, ref.r_eci, q_eci_body))
        if self.diag_pub.get_subscription_count() == 0:
            return
        d = FilterDiagnostics()
        d.header = msg.header
        d.algorithm = self.algorithm
        d.innovation = list(step.innovation)
        d.covariance_trace = float(step.covariance_trace)
        d.update_count = self.update_count
        d.rejected_count = self.rejected_count
        d.last_rejection = self.last_rejection
        self.diag_pub.publish(d)


def main(args=None) -> int:
    """``ros2 run adcs_nodes estimator``."""
    return runtime.run(EstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
