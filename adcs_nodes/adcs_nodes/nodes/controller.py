"""Generic controller node: runs any registered controller, chosen by parameter ``controller``.

One process per controller. Every controller computes every frame of its period ("shadow
mode", so a switch is bumpless) and publishes ``adcs/controllers/<name>/command``
(``adcs_msgs/ActuatorCommand``, stamped with the frame it was computed for); the controller
manager forwards the active one.

What the node subscribes to comes from the registry entry's ``inputs`` (nothing else):

* ``estimate``: ``adcs/attitude_estimate`` (``adcs_msgs/AttitudeState``);
* ``target``: ``adcs/attitude_target`` (``adcs_msgs/AttitudeTarget``, from ``guidance``);
* ``magnetometer``: ``sensors/magnetometer`` (``sensor_msgs/MagneticField``, rotated from the
  sensor frame into body axes with the mount from ``/tf_static``); with ``estimate`` too, the
  onboard-model field ``n* = R(q_orbit_body)^T B*`` is offered between samples
  (``ControlInputs.b_body_model``);
* ``wheel_speeds``: ``sensors/wheels`` (``sensor_msgs/JointState`` velocities [rad/s]).

So B-dot, whose entry declares only the magnetometer, keeps working when the estimator dies
(the safe-mode rule). The parameters are the entry's own (``ros2 param describe`` shows each
with unit and range) plus the spacecraft context below, all declared from typed specs.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Dict, List, Optional

import numpy as np
from sensor_msgs.msg import JointState, MagneticField
from std_msgs.msg import Header

from adcs_msgs.msg import ActuatorCommand, AttitudeState, AttitudeTarget
from adcs_nodes import registry
from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import Command, ControlInputs, Estimate, Target
from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.entries import wheel_momentum
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.convert import all_finite, quat, to_vec3, vec3
from adcs_nodes.nodes.managed import ManagedLockstepNode
from adcs_nodes.nodes.messages import make
from adcs_nodes.nodes.tf import MountTable
from adcs_nodes.registry import Param

#: Onboard models of a node started alone (paper 000's orbit, a dipole field).
DEFAULT_ORBIT = {'type': 'circular', 'altitude_km': 690.0, 'inclination_deg': 98.0,
                 'raan_deg': 0.0, 'arg_latitude0_deg': 0.0}
DEFAULT_FIELD = {'model': 'dipole'}

#: The spacecraft context every controller node knows (defaults: paper 000's satellite).
CONTEXT_PARAMS = (
    Param('expected_mounts', 'str[]', [], '-', 'sensor frames whose /tf_static mount must '
          'have arrived before the node is ready (the launcher sets them)', read_only=True),
    Param('controller', 'str', 'magnetic', '-', 'registered controller this node runs',
          read_only=True),
    Param('period_s', 'float', 2.0, 's', 'control period', positive=True, read_only=True),
    Param('estimator_period_s', 'float', 2.0, 's', 'period of adcs/attitude_estimate',
          positive=True, read_only=True),
    Param('target_period_s', 'float', 2.0, 's', 'period of adcs/attitude_target (guidance)',
          positive=True, read_only=True),
    Param('magnetometer_period_s', 'float', 10.0, 's', 'period of sensors/magnetometer',
          positive=True, read_only=True),
    Param('tachometer_period_s', 'float', 1.0, 's', 'period of sensors/wheels',
          positive=True, read_only=True),
    Param('inertia_kgm2', 'float[]', [118.0, 118.0, 19.6], 'kg m^2',
          "the controller's own inertia: 3 diagonal values or 9 (row-major)",
          read_only=True),
    Param('max_dipole_Am2', 'float[]', [40.0, 40.0, 40.0], 'A m^2',
          'magnetorquer limits per body axis (all zero: no magnetorquer)', length=3, min=0.0,
          read_only=True),
    Param('wheel_axes_body', 'float[]', [], '-', 'wheel spin axes, body axes, 3 per wheel',
          read_only=True),
    Param('wheel_max_torque_Nm', 'float[]', [], 'N m', 'wheel motor torque limits',
          positive=True, read_only=True),
    Param('wheel_max_momentum_Nms', 'float[]', [], 'N m s', 'wheel momentum limits',
          positive=True, read_only=True),
    Param('wheel_inertia_kgm2', 'float[]', [], 'kg m^2', 'wheel inertias about their axes',
          positive=True, read_only=True),
)


def inertia_matrix(values) -> np.ndarray:
    """3 diagonal values or 9 row-major -> (3, 3) [kg m^2]; ValueError otherwise."""
    a = np.asarray(values, dtype=float)
    if a.size == 3:
        return np.diag(a)
    if a.size == 9:
        return a.reshape(3, 3)
    raise ValueError(f'inertia_kgm2 needs 3 or 9 values, got {a.size}')


def estimate_from_msg(msg: Optional[AttitudeState]) -> Optional[Estimate]:
    """Controller-core estimate from ``adcs/attitude_estimate`` (None if absent).

    The orbit rate is recovered from the two rates in the message:
    ``|omega_body_eci_body - omega_body_orbit_body| = omega0``.
    """
    if msg is None:
        return None
    w_abs, w_rel = vec3(msg.omega_body_eci_body), vec3(msg.omega_body_orbit_body)
    q, q_eci = quat(msg.q_orbit_body), quat(msg.q_eci_body)
    valid = all_finite(q, w_abs, w_rel, q_eci)
    omega0 = float(np.linalg.norm(w_abs - w_rel)) if valid else 0.0
    return Estimate(q, w_abs, omega0, valid, q_eci if valid else None)


def target_from_msg(msg: Optional[AttitudeTarget]) -> Optional[Target]:
    """Core target from ``adcs/attitude_target`` (None if absent or malformed)."""
    if msg is None:
        return None
    q = quat(msg.q_ref_body)
    w, a = vec3(msg.omega_body_ref_body), vec3(msg.omega_dot_body_ref_body)
    frame = msg.header.frame_id or 'orbit'
    if frame not in ('orbit', 'eci') or not all_finite(q, w, a) or np.linalg.norm(q) < 0.5:
        return None
    return Target(att.normalize(q), w, a, frame, float(msg.time_to_go_s))


def command_msg(cmd: Command, stamp, source: str) -> ActuatorCommand:
    """Core command -> ``adcs_msgs/ActuatorCommand``."""
    return make(ActuatorCommand, header=make(Header, stamp=stamp, frame_id='body'),
                dipole_body=to_vec3(cmd.dipole_body),
                wheel_torque=np.asarray(cmd.wheel_torque, dtype=float).tolist(),
                torque_body=to_vec3(cmd.torque_body), source=source)


class ControllerNode(ManagedLockstepNode):
    """A registered controller core wrapped as a lockstep node (see module docstring); a
    managed node (:mod:`adcs_nodes.nodes.managed`)."""

    def __init__(self, name: Optional[str] = None, controller: Optional[str] = None,
                 **kwargs: Any) -> None:
        self._fixed_controller = controller   # (configure runs inside super().__init__)
        super().__init__(name or f'{controller or "magnetic"}_controller', **kwargs)

    def configure(self) -> None:
        """Parameters, controller core and endpoints (lifecycle configure)."""
        controller = self._fixed_controller
        registry.load_plugins(self.param('plugins', []))
        specs = {s.name: s for s in CONTEXT_PARAMS}
        if controller is not None:   # the class fixes the controller: that is its default
            specs['controller'] = replace(specs['controller'], default=controller)
        ctx_p = node_params.declare_all(self, specs.values())
        self.entry = registry.get('controller', ctx_p['controller'])
        self.controller_name = self.entry.name
        own = node_params.declare_all(self, self.entry.params)
        self.mounts = MountTable(self)    # sensor mounts from /tf_static, by header.frame_id
        self.add_ready_check(lambda: self.mounts.missing(ctx_p['expected_mounts']))
        axes = np.asarray(ctx_p['wheel_axes_body'], dtype=float)
        n_wheels = len(ctx_p['wheel_max_torque_Nm'])
        if axes.size != 3 * n_wheels:
            raise ValueError(f'wheel_axes_body needs 3 values per wheel ({n_wheels} wheels), '
                             f'got {axes.size}')
        self.ctx: Dict[str, Any] = {
            'inertia_kgm2': inertia_matrix(ctx_p['inertia_kgm2']),
            'max_dipole_Am2': ctx_p['max_dipole_Am2'] if any(ctx_p['max_dipole_Am2']) else None,
            'wheel_axes_body': axes.reshape(n_wheels, 3),
            'wheel_max_torque_Nm': ctx_p['wheel_max_torque_Nm'],
            'wheel_max_momentum_Nms': ctx_p['wheel_max_momentum_Nms'],
            'wheel_inertia_kgm2': ctx_p['wheel_inertia_kgm2'],
            'period_s': ctx_p['period_s'], 'epoch': self.epoch, 'seed': self.seed,
            'reference': None}
        needs = set(self.entry.inputs)
        if 'magnetorquer' in self.entry.actuators and self.ctx['max_dipole_Am2'] is None:
            raise ValueError(f'controller {self.controller_name} commands magnetorquers but '
                             'max_dipole_Am2 is empty (no magnetorquer)')
        if 'wheels' in self.entry.actuators and n_wheels == 0:
            raise ValueError(f'controller {self.controller_name} commands wheels but none '
                             'are configured')
        if {'estimate', 'magnetometer'} <= needs:
            self.ctx['reference'] = make_onboard_reference(
                self.section('onboard_orbit', DEFAULT_ORBIT, merge=False),
                self.section('onboard_field', DEFAULT_FIELD, merge=False), self.epoch)
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.core = self.entry.build(own, self.ctx)
        self.n_wheels = n_wheels
        topics = {
            'estimate': ('est', AttitudeState, 'adcs/attitude_estimate',
                         ctx_p['estimator_period_s']),
            'target': ('target', AttitudeTarget, 'adcs/attitude_target',
                       ctx_p['target_period_s']),
            'magnetometer': ('mag', MagneticField, 'sensors/magnetometer',
                             ctx_p['magnetometer_period_s']),
            'wheel_speeds': ('wheels', JointState, 'sensors/wheels',
                             ctx_p['tachometer_period_s']),
        }
        inputs = {key: (mtype, topic, period) for need, (key, mtype, topic, period)
                  in topics.items() if need in needs}
        self.pub = self.publisher(ActuatorCommand,
                                  f'adcs/controllers/{self.controller_name}/command')
        self._last_t: Optional[int] = None
        self.lockstep_inputs(inputs, ctx_p['period_s'], self.on_frame)
        self.start_handshake()

    def _field_body(self, msg: Optional[MagneticField], t_ns: int) -> Optional[np.ndarray]:
        """Fresh magnetometer sample in body axes, or None."""
        if not self.fresh('mag', msg, t_ns):   # lockstep: stamped t; live: a newer sample
            return None
        b = vec3(msg.magnetic_field)
        q_body_sensor = self.mounts.lookup(msg.header.frame_id)   # None: no mount known yet
        if q_body_sensor is None or not all_finite(b):
            return None
        return att.rotate(q_body_sensor, b)

    def _wheel_speeds(self, msg: Optional[JointState]) -> Optional[np.ndarray]:
        if msg is None or len(msg.velocity) != self.n_wheels:
            return None
        w = np.asarray(msg.velocity, dtype=float)
        return w if all_finite(w) else None

    def inputs_for(self, t_ns: int, msgs: Dict[str, Any]) -> ControlInputs:
        """Messages of frame ``t_ns`` -> the core's :class:`ControlInputs`."""
        t = t_ns / NS_PER_S
        estimate = estimate_from_msg(msgs.get('est'))
        b_model = None
        ref = self.ctx['reference']
        if ref is not None and estimate is not None and estimate.is_usable():
            b_model = att.to_matrix(estimate.q_orbit_body).T @ ref.at(t).b_orbit  # n* = R^T B*
        speeds = self._wheel_speeds(msgs.get('wheels'))
        return ControlInputs(estimate, target_from_msg(msgs.get('target')),
                             self._field_body(msgs.get('mag'), t_ns), b_model, speeds,
                             wheel_momentum(speeds, self.ctx))

    def on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """Compute and publish this controller's command for frame ``t_ns``."""
        dt = 0.0 if self._last_t is None else (t_ns - self._last_t) / NS_PER_S
        self._last_t = t_ns
        cmd = self.core.update(self.inputs_for(t_ns, msgs), t_ns / NS_PER_S, dt)
        self.pub.publish(command_msg(cmd, self.stamp(t_ns), self.controller_name))


def main(args=None) -> int:
    """``ros2 run adcs_nodes controller --ros-args -p controller:=NAME``."""
    return runtime.run(ControllerNode, args)


def main_magnetic(args=None) -> int:
    """``ros2 run adcs_nodes magnetic_controller``."""
    return runtime.run(lambda: ControllerNode(controller='magnetic'), args)


def main_bdot(args=None) -> int:
    """``ros2 run adcs_nodes bdot_controller``."""
    return runtime.run(lambda: ControllerNode(controller='bdot'), args)


if __name__ == '__main__':
    raise SystemExit(main())
