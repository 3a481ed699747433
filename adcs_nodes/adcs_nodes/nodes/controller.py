"""Controller nodes: ``magnetic_controller`` (paper 000) and ``bdot_controller`` (safe mode).

One process per controller. Every controller computes every frame of its period ("shadow
mode", so a switch is bumpless) and publishes ``adcs/controllers/<name>/command``
(``adcs_msgs/ActuatorCommand``, stamped with the frame it was computed for); the controller
manager forwards the active one.

Inputs: ``adcs/attitude_estimate`` (when the scenario has an estimator), the magnetometer
``sensors/magnetometer`` (rotated from the sensor frame into body axes) and the latest
``adcs/attitude_target``. Between magnetometer samples:

* ``magnetic``: the field in body axes is the onboard model ``n* = R(q_orbit_body)^T B*``
  from the estimate (paper 000's alternative to the measured ``n``; the digest's control
  update every 2 s with measurements every 10 s needs it);
* ``bdot``: the last command is held (the derivative needs a new sample).
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional

import numpy as np
from sensor_msgs.msg import MagneticField

from adcs_msgs.msg import ActuatorCommand, AttitudeState, AttitudeTarget
from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import Command, Estimate, Target
from adcs_nodes.core.control.bdot import BdotController
from adcs_nodes.core.control.magnetic import MagneticController
from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.convert import all_finite, quat, stamp_ns, to_vec3, vec3
from adcs_nodes.nodes.lockstep_node import LockstepNode
from adcs_nodes.nodes.tf import MountTable

KINDS = ('magnetic', 'bdot')
DEFAULT_ORBIT = {'type': 'circular', 'altitude_km': 690.0, 'inclination_deg': 98.0,
                 'raan_deg': 0.0, 'arg_latitude0_deg': 0.0}
DEFAULT_FIELD = {'model': 'dipole'}


def estimate_from_msg(msg: Optional[AttitudeState]) -> Optional[Estimate]:
    """Controller-core estimate from ``adcs/attitude_estimate`` (None if absent).

    The orbit rate is recovered from the two rates in the message:
    ``|omega_body_eci_body - omega_body_orbit_body| = omega0``.
    """
    if msg is None:
        return None
    w_abs, w_rel = vec3(msg.omega_body_eci_body), vec3(msg.omega_body_orbit_body)
    q = quat(msg.q_orbit_body)
    valid = all_finite(q, w_abs, w_rel)
    omega0 = float(np.linalg.norm(w_abs - w_rel)) if valid else 0.0
    return Estimate(q, w_abs, omega0, valid)


def command_msg(cmd: Command, stamp, source: str) -> ActuatorCommand:
    """Core command -> ``adcs_msgs/ActuatorCommand``."""
    msg = ActuatorCommand()
    msg.header.stamp = stamp
    msg.header.frame_id = 'body'
    msg.dipole_body = to_vec3(cmd.dipole_body)
    msg.wheel_torque = [float(v) for v in np.asarray(cmd.wheel_torque, dtype=float)]
    msg.torque_body = to_vec3(cmd.torque_body)
    msg.source = source
    return msg


class ControllerNode(LockstepNode):
    """A controller core wrapped as a lockstep node (see module docstring)."""

    def __init__(self, name: Optional[str] = None, kind: str = 'magnetic',
                 **kwargs: Any) -> None:
        super().__init__(name or f'{kind}_controller', **kwargs)
        kind = str(self.param('kind', kind))
        if kind not in KINDS:
            raise ValueError(f'unknown controller kind {kind!r}; known: {KINDS}')
        self.kind = kind
        self.short = str(self.param('controller_name', kind))
        period_s = float(self.param('period_s', 2.0))
        est_period_s = float(self.param('estimator_period_s', 2.0))
        mag_period_s = float(self.param('magnetometer_period_s', 10.0))
        self.mounts = MountTable(self)    # sensor mounts from /tf_static, by header.frame_id
        n_wheels = int(self.param('n_wheels', 0))
        limits = list(self.param('max_dipole_Am2', [40.0, 40.0, 40.0]))
        if kind == 'magnetic':
            beta = float(self.param('beta', 0.0))
            self.core = MagneticController(
                mode=str(self.param('mode', 'three_axis')),
                alpha=float(self.param('alpha_per_s', 3e-3)),
                k=float(self.param('k_Nms', 0.2)), max_dipole_Am2=limits,
                beta=beta if beta > 0 else None,
                switch_angle_deg=float(self.param('switch_angle_deg', 15.0)),
                switch_rate_deg_s=float(self.param('switch_rate_deg_s', 0.2)),
                n_wheels=n_wheels)
            self.reference = make_onboard_reference(
                self.section('onboard_orbit', DEFAULT_ORBIT, merge=False),
                self.section('onboard_field', DEFAULT_FIELD, merge=False), self.epoch)
        else:
            self.core = BdotController(
                gain=float(self.param('gain_Am2s_per_T', 1.0e6)), max_dipole_Am2=limits,
                filter_time_constant_s=float(self.param('filter_time_constant_s', 0.0)),
                n_wheels=n_wheels)
            self.reference = None
        inputs: Dict[str, tuple] = {
            'mag': (MagneticField, 'sensors/magnetometer', mag_period_s),
            'target': (AttitudeTarget, 'adcs/attitude_target', 0.0)}
        if est_period_s > 0:
            inputs['est'] = (AttitudeState, 'adcs/attitude_estimate', est_period_s)
        self.pub = self.publisher(ActuatorCommand, f'adcs/controllers/{self.short}/command')
        self._last_cmd = Command.zero(n_wheels, 'no command yet')
        self._last_t: Optional[int] = None
        self.lockstep_inputs(inputs, period_s, self.on_frame)
        self.start_handshake()

    def _field_body(self, msg: Optional[MagneticField], t_ns: int) -> Optional[np.ndarray]:
        """Fresh magnetometer sample in body axes, or None."""
        if msg is None or self.elapsed_ns(stamp_ns(msg.header.stamp)) != t_ns:
            return None
        b = vec3(msg.magnetic_field)
        q_body_sensor = self.mounts.lookup(msg.header.frame_id)   # None: no mount known yet
        if q_body_sensor is None or not all_finite(b):
            return None
        return att.rotate(q_body_sensor, b)

    def on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """Compute and publish this controller's command for frame ``t_ns``."""
        t = t_ns / NS_PER_S
        dt = 0.0 if self._last_t is None else (t_ns - self._last_t) / NS_PER_S
        self._last_t = t_ns
        estimate = estimate_from_msg(msgs.get('est'))
        tgt = msgs.get('target')
        target = None if tgt is None else Target(quat(tgt.q_ref_body),
                                                 vec3(tgt.omega_body_ref_body))
        b_body = self._field_body(msgs.get('mag'), t_ns)
        if self.kind == 'bdot':
            if b_body is None:
                cmd = self._last_cmd              # no new sample: hold the last dipole
            else:
                cmd = self.core.update(estimate, target, b_body, t, dt)
        else:
            if b_body is None and estimate is not None and estimate.valid:
                b_orbit = self.reference.at(t).b_orbit        # n* = R^T B* (onboard model)
                b_body = att.to_matrix(estimate.q_orbit_body).T @ b_orbit
            cmd = self.core.update(estimate, target, b_body, t, dt)
        self._last_cmd = cmd
        self.pub.publish(command_msg(cmd, self.stamp(t_ns), self.short))


def main(args=None) -> int:
    """``python -m adcs_nodes.nodes.controller``: the kind comes from parameter ``kind``."""
    return runtime.run(ControllerNode, args)


def main_magnetic(args=None) -> int:
    """``ros2 run adcs_nodes magnetic_controller``."""
    return runtime.run(lambda: ControllerNode(kind='magnetic'), args)


def main_bdot(args=None) -> int:
    """``ros2 run adcs_nodes bdot_controller``."""
    return runtime.run(lambda: ControllerNode(kind='bdot'), args)


class MagneticControllerNode(ControllerNode):
    """Composable class of the magnetic controller (``adcs run --compose``)."""

    def __init__(self, name: str = 'magnetic_controller', **kwargs: Any) -> None:
        super().__init__(name, kind='magnetic', **kwargs)


class BdotControllerNode(ControllerNode):
    """Composable class of the B-dot controller (``adcs run --compose``)."""

    def __init__(self, name: str = 'bdot_controller', **kwargs: Any) -> None:
        super().__init__(name, kind='bdot', **kwargs)


if __name__ == '__main__':
    raise SystemExit(main())
