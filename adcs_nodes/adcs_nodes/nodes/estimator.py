"""``estimator`` node: attitude and rate estimate from the sensors (flight software).

Algorithm by parameter ``algorithm``:

* ``magnetic_filter`` (paper 000): predicts every ``period_s`` with the nonlinear model (33)
  and the last commanded dipole, updates with each fresh magnetometer sample (38)-(39).
* ``triad``: TRIAD of the nadir direction (horizon sensor) and the field (paper 004's
  comparison); the rate is the finite difference of successive attitudes.
* ``horizon_mag_yaw``: roll and pitch from the horizon sensor, yaw from formula (3) of
  paper 004; rate as for TRIAD.

Subscribes ``sensors/magnetometer`` (``sensor_msgs/MagneticField``, sensor frame),
``sensors/horizon`` (for triad/horizon_mag_yaw) and ``adcs/actuator_command`` (the applied
dipole, for the prediction). Never ``sim/*``: the reference field and orbit are the flight
software's own models (``onboard_orbit.*``, ``onboard_field.*``).

Publishes ``adcs/attitude_estimate`` (``adcs_msgs/AttitudeState``: q to the orbit frame and to
ECI, rates, 6x6 covariance) and ``adcs/estimator/diagnostics`` (``adcs_msgs/FilterDiagnostics``).
Bad input (NaN, zero or implausible field, stale or invalid sensor) is rejected with a
warning and counted; a non-finite estimate is never published.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional

import numpy as np
from sensor_msgs.msg import MagneticField

from adcs_msgs.msg import ActuatorCommand, AttitudeState, FilterDiagnostics, HorizonSensor
from adcs_nodes.core import attitude as att
from adcs_nodes.core.estimation.horizon_yaw import (attitude_from_horizon_and_yaw,
                                                    triad_from_horizon_and_field,
                                                    yaw_from_horizon_and_field)
from adcs_nodes.core.estimation.magnetic_filter import MAX_DISTURBANCE_DEFAULT, MagneticFilter
from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.convert import all_finite, stamp_ns, to_quat, to_vec3, vec3
from adcs_nodes.nodes.lockstep_node import LockstepNode
from adcs_nodes.nodes.tf import MountTable, TfPublisher, estimate_transforms

ALGORITHMS = ('magnetic_filter', 'triad', 'horizon_mag_yaw')
DEFAULT_ORBIT = {'type': 'circular', 'altitude_km': 690.0, 'inclination_deg': 98.0,
                 'raan_deg': 0.0, 'arg_latitude0_deg': 0.0}
DEFAULT_FIELD = {'model': 'dipole'}


class EstimatorNode(LockstepNode):
    """Attitude estimator (see module docstring)."""

    def __init__(self, name: str = 'estimator', **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.algorithm = str(self.param('algorithm', 'magnetic_filter'))
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f'unknown algorithm {self.algorithm!r}; known: {ALGORITHMS}')
        period_s = float(self.param('period_s', 2.0))
        mag_period_s = float(self.param('magnetometer_period_s', 10.0))
        horizon_period_s = float(self.param('horizon_period_s', 1.0))
        self.mounts = MountTable(self)    # sensor mounts from /tf_static, by header.frame_id
        self.tf_pub = TfPublisher(self)   # /tf: eci -> body_estimate
        self.reference = make_onboard_reference(
            self.section('onboard_orbit', DEFAULT_ORBIT, merge=False),
            self.section('onboard_field', DEFAULT_FIELD, merge=False), self.epoch)
        self.q0 = att.normalize(self.param('initial_q_orbit_body', [0.0, 0.0, 0.0, 1.0]))
        self.omega_rel0 = np.asarray(self.param('initial_omega_body_orbit_body',
                                                [0.0, 0.0, 0.0]), dtype=float)
        inputs = {'mag': (MagneticField, 'sensors/magnetometer', mag_period_s),
                  'cmd': (ActuatorCommand, 'adcs/actuator_command', 0.0)}
        self.max_rate = float(self.param('max_rate_rad_s', 1.0))
        self.resets = 0
        if self.algorithm == 'magnetic_filter':
            inertia = np.asarray(self.param('inertia_kgm2', [118.0, 118.0, 19.6]), float)
            inertia = np.diag(inertia) if inertia.size == 3 else inertia.reshape(3, 3)
            self.filter = MagneticFilter(
                inertia, theta=float(self.param('theta_T2', 9e-14)),
                tau=float(self.param('tau', 0.01)),
                p0_diag=list(self.param('p0_diag', [10.0] * 3 + [0.0036] * 3 + [1e-14] * 3)),
                measurement_form=str(self.param('measurement_form', 'phi')),
                literal_update=bool(self.param('literal_update', False)),
                substeps=int(self.param('substeps', 1)),
                # sanity bounds on a correction (not in the paper): divergence guards only
                max_rate_rad_s=self.max_rate,
                max_disturbance_rad_s2=float(self.param('max_disturbance_rad_s2',
                                                        MAX_DISTURBANCE_DEFAULT)))
        else:
            inputs['horizon'] = (HorizonSensor, 'sensors/horizon', horizon_period_s)
        self.est_pub = self.publisher(AttitudeState, 'adcs/attitude_estimate')
        self.diag_pub = self.publisher(FilterDiagnostics, 'adcs/estimator/diagnostics')
        self.update_count = 0
        self.rejected_count = 0
        self.last_rejection = ''
        self.innovation: List[float] = []
        self._last_t: Optional[int] = None
        self._q_prev: Optional[np.ndarray] = None
        self._omega_rel = self.omega_rel0.copy()
        self._cov = np.full(36, -1.0)          # "unknown" until the first estimate
        self.lockstep_inputs(inputs, period_s, self.on_frame)
        self.start_handshake()

    # ------------------------------------------------------------------ inputs
    def _reject(self, why: str) -> None:
        self.rejected_count += 1
        self.last_rejection = why
        self.get_logger().warning(f'measurement rejected: {why}')

    def _fresh(self, msg, t_ns: int) -> bool:
        """True when ``msg`` is stamped exactly t (a new sample this frame)."""
        return msg is not None and self.elapsed_ns(stamp_ns(msg.header.stamp)) == t_ns

    def _field_body(self, msg: MagneticField) -> Optional[np.ndarray]:
        """Magnetometer sample rotated into body axes, or None (rejected) if implausible."""
        b_sensor = vec3(msg.magnetic_field)
        if not all_finite(b_sensor):
            self._reject('magnetometer sample is not finite')
            return None
        norm = float(np.linalg.norm(b_sensor))
        if not 1e-6 <= norm <= 1e-3:
            self._reject(f'magnetometer |B| = {norm:.3g} T outside [1e-6, 1e-3] T')
            return None
        q_body_sensor = self.mounts.lookup(msg.header.frame_id)
        if q_body_sensor is None:
            self._reject(f'no /tf_static mount body -> {msg.header.frame_id!r}')
            return None
        return att.rotate(q_body_sensor, b_sensor)

    # ------------------------------------------------------------------ frame
    def on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """One estimator step at elapsed sim time ``t_ns``."""
        t = t_ns / NS_PER_S
        ref = self.reference.at(t)
        for topic in missing:
            self._reject(f'stale input {topic} at t={t:g} s (timeout)')
        if self.algorithm == 'magnetic_filter':
            ok = self._filter_step(t_ns, ref, msgs)
        else:
            ok = self._geometric_step(t_ns, ref, msgs)
        self._last_t = t_ns
        if ok:
            self._publish(t_ns, ref)

    def _filter_step(self, t_ns: int, ref, msgs: Dict[str, Any]) -> bool:
        f = self.filter
        omega_abs0 = self.omega_rel0 + att.to_matrix(self.q0).T @ np.array(
            [0.0, ref.omega0, 0.0])
        if self._last_t is None:
            f.reset(self.q0, omega_abs0)
        else:
            cmd = msgs.get('cmd')
            dipole = vec3(cmd.dipole_body) if cmd is not None else np.zeros(3)
            if not all_finite(dipole):
                dipole = np.zeros(3)
            ok = f.predict((t_ns - self._last_t) / NS_PER_S, ref.omega0, dipole,
                           b_orbit_for_torque=ref.b_orbit)
            w = f.omega_body_eci_body
            if not ok or not all_finite(w) or float(np.linalg.norm(w)) > self.max_rate:
                # diverged (e.g. the literal update (38)): start again from the initial
                # estimate, as the paper's filter does at t0, instead of publishing nonsense
                self.resets += 1
                self._reject(f'filter diverged (|omega\'| beyond {self.max_rate:g} rad/s or '
                             f'not finite): reset to the initial estimate ({self.resets})')
                f.reset(self.q0, omega_abs0)
        mag = msgs.get('mag')
        if self._fresh(mag, t_ns):
            b_body = self._field_body(mag)
            if b_body is not None:
                res = f.update(b_body, ref.b_orbit)
                if res.get('accepted', False):
                    self.update_count += 1
                    self.innovation = [float(v) for v in res['innovation']]
                else:
                    self._reject(str(res.get('reason', 'update refused')))
        q = f.q_orbit_body
        omega = f.omega_body_eci_body
        if not all_finite(q, omega):
            self._reject('filter state not finite: not published')
            return False
        self._q_orbit_body = q
        self._omega_abs = omega
        p = f.P
        cov = np.zeros((6, 6))
        cov[:3, :3] = 4.0 * p[:3, :3]     # small angle: error angle ~ 2 mu (or 2 phi)
        cov[3:, 3:] = p[3:6, 3:6]
        cov[:3, 3:] = 2.0 * p[:3, 3:6]
        cov[3:, :3] = cov[:3, 3:].T
        self._cov = cov.reshape(-1)
        return True

    def _geometric_step(self, t_ns: int, ref, msgs: Dict[str, Any]) -> bool:
        mag, hor = msgs.get('mag'), msgs.get('horizon')
        if not (self._fresh(mag, t_ns) and self._fresh(hor, t_ns)):
            return self._q_prev is not None   # no fresh valid pair: hold the last estimate
        if not hor.valid or not math.isfinite(hor.roll) or not math.isfinite(hor.pitch):
            self._reject('horizon sensor sample invalid (out of view or not finite)')
            return self._q_prev is not None   # no fresh valid pair: hold the last estimate
        b_body = self._field_body(mag)
        if b_body is None:
            return self._q_prev is not None   # no fresh valid pair: hold the last estimate
        try:
            if self.algorithm == 'triad':
                q = triad_from_horizon_and_field(hor.roll, hor.pitch, b_body, ref.b_orbit)
            else:
                yaw = yaw_from_horizon_and_field(hor.roll, hor.pitch, b_body, ref.b_orbit)
                q = attitude_from_horizon_and_yaw(hor.roll, hor.pitch, yaw)
        except ValueError as exc:
            self._reject(f'{self.algorithm}: {exc}')
            return self._q_prev is not None   # no fresh valid pair: hold the last estimate
        if self._q_prev is not None and self._last_t is not None:
            dt = (t_ns - self._last_t) / NS_PER_S
            dq = att.multiply(att.conjugate(self._q_prev), q)
            self._omega_rel = att.to_rotation_vector(dq) / dt
            if float(q @ self._q_prev) < 0:
                q = -q
        self._q_prev = q
        self.update_count += 1
        self._q_orbit_body = q
        self._omega_abs = self._omega_rel + att.to_matrix(q).T @ np.array([0.0, ref.omega0, 0.0])
        return True

    # ------------------------------------------------------------------ output
    def _publish(self, t_ns: int, ref) -> None:
        q_orbit_body = self._q_orbit_body
        q_eci_body = att.multiply(ref.q_eci_orbit, q_orbit_body)
        omega_rel = self._omega_abs - att.to_matrix(q_orbit_body).T @ np.array(
            [0.0, ref.omega0, 0.0])
        msg = AttitudeState()
        msg.header.stamp = self.stamp(t_ns)
        msg.header.frame_id = 'body'
        msg.q_eci_body = to_quat(q_eci_body)
        msg.q_orbit_body = to_quat(q_orbit_body)
        msg.omega_body_eci_body = to_vec3(self._omega_abs)
        msg.omega_body_orbit_body = to_vec3(omega_rel)
        msg.covariance = [float(c) for c in self._cov]
        self.est_pub.publish(msg)
        self.tf_pub.send(estimate_transforms(msg.header.stamp, ref.r_eci, q_eci_body))
        d = FilterDiagnostics()
        d.header = msg.header
        d.algorithm = self.algorithm
        d.innovation = self.innovation
        d.covariance_trace = float(np.trace(self.filter.P)) \
            if self.algorithm == 'magnetic_filter' else 0.0
        d.update_count = self.update_count
        d.rejected_count = self.rejected_count
        d.last_rejection = self.last_rejection
        self.diag_pub.publish(d)


def main(args=None) -> int:
    """``ros2 run adcs_nodes estimator``."""
    return runtime.run(EstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
