"""``controller_manager`` node: forwards the active controller's command to the actuators.

Wraps :class:`adcs_nodes.core.manager.ControllerManagerCore` (switching at frame boundaries
with one zero frame, schedule, automatic mode sequence, fallback to the safe controller on a
stale, NaN or out-of-range command; the command sent is always finite and inside the limits).

Awaits ``adcs/controllers/<name>/command`` of every controller each command frame and, when
``estimator_period_s > 0``, ``adcs/attitude_estimate`` (a stale or invalid one: the safe
controller for the controllers in ``estimate_users``, and the automatic sequence holds).
Publishes ``adcs/actuator_command`` and the latched ``adcs/controller_status``; serves
``adcs/switch_controller`` and ``adcs/list_controllers``. Topics, services, safe mode and
switch requests: ``docs/topics.md``. A dead producer stops being awaited (``LockstepNode``).

Live mode (``timing_mode: live``): stamps are not on a frame grid, so ``stale_after_s``
defaults to 1.5 x the longest of the manager, controller and estimator periods (ASSUMPTION).
"""
from __future__ import annotations

import time
from typing import Any, Dict, List, Optional, Tuple

from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import JointState

from adcs_msgs.msg import ActuatorCommand, AttitudeState, ControllerStatus
from adcs_msgs.srv import ListControllers, SwitchController
from adcs_nodes.components.manager import (MAGNETORQUER_TOPIC, MANAGER_PARAMS, WHEELS_TOPIC,
                                           ManagerComponent, actuator_commands, manager_core,
                                           status_key, wheel_names_for)
from adcs_nodes.core.manager import AUTO_SEQUENCE
from adcs_nodes.msgs import convert
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.adapter import ToCore, node_log
from adcs_nodes.nodes.lockstep_node import QOS_LATCHED
from adcs_nodes.nodes.managed import ManagedLockstepNode


#: Service names (relative: under the node's namespace; ``/adcs/...`` when started at the root).
SWITCH_SERVICE = 'adcs/switch_controller'
LIST_SERVICE = 'adcs/list_controllers'


class ControllerManagerNode(ManagedLockstepNode):
    """Controller manager (see module docstring); a managed node (:mod:`.managed`)."""

    def __init__(self, name: str = 'controller_manager', **kwargs: Any) -> None:
        super().__init__(name, **kwargs)

    def configure(self) -> None:
        """Parameters, manager core, endpoints and services (lifecycle configure)."""
        p = node_params.declare_all(self, MANAGER_PARAMS)
        auto = self.section('auto', AUTO_SEQUENCE)
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.core = manager_core(p, auto, self.live, sample_timing=self.live or self.real_time)
        self.names: List[str] = list(self.core.names)
        period_s = float(p['period_s'])
        ctrl_period_s = float(p['controller_period_s']) or period_s
        est_period_s = float(p['estimator_period_s'])
        wheel_limits = list(p['max_wheel_torque_Nm'])
        self.component = ManagerComponent(self.core, node_log(self))
        inputs: Dict[str, tuple] = {
            n: (ActuatorCommand, f'adcs/controllers/{n}/command', ctrl_period_s)
            for n in self.names}
        if est_period_s > 0:
            inputs['_estimate'] = (AttitudeState, 'adcs/attitude_estimate', est_period_s)
        self.to_core = ToCore({n: convert.COMMAND.to_core for n in self.names}
                              | {'_estimate': convert.ATTITUDE_STATE.to_core}, self.epoch_ns)
        self.cmd_pub = self.publisher(ActuatorCommand, 'adcs/actuator_command')
        # the standard per-actuator topics, for drivers (published when someone reads them)
        self.wheel_names = wheel_names_for(0 if wheel_limits == [-1.0] else len(wheel_limits),
                                           p['wheel_names'])
        self.actuator_pubs = {MAGNETORQUER_TOPIC: self.publisher(Vector3Stamped,
                                                                 MAGNETORQUER_TOPIC)}
        if self.wheel_names:
            self.actuator_pubs[WHEELS_TOPIC] = self.publisher(JointState, WHEELS_TOPIC)
        self.status_pub = self.publisher(ControllerStatus, 'adcs/controller_status',
                                         QOS_LATCHED)
        self.create_service(SwitchController, SWITCH_SERVICE, self.on_switch)
        self.create_service(ListControllers, LIST_SERVICE, self.on_list)
        self._last_status: Optional[Tuple] = None
        self._last_status_wall = 0.0
        self.lockstep_inputs(inputs, period_s, self.on_frame)
        self.start_handshake()

    def activated(self) -> None:
        """Publish the latched status at once (its publisher drops what comes before)."""
        self._publish_status(force=True)

    # ------------------------------------------------------------------ services
    def on_switch(self, request, response):
        """``adcs/switch_controller``: validate now, apply at the next frame boundary."""
        ok, message = self.core.request_switch(request.name, self.component.t_last)
        response.success = ok
        response.message = message
        response.active = self.core.active
        text = f'switch_controller({request.name!r}): {message}'
        if ok:   # (rclpy refuses one call site logging at two severities)
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)
        return response

    def on_list(self, request, response):
        """``adcs/list_controllers``."""
        names, active, safe = self.core.list_controllers()
        response.names = names
        response.active = active
        response.safe = safe
        return response

    def diagnostic_values(self) -> Dict[str, str]:
        """What ``/diagnostics`` shows of the manager (``adcs_nodes.nodes.diagnostics``)."""
        st = self.core.status()
        return {'active_controller': str(st.get('active', self.core.active)),
                'mode': str(st.get('mode') or '-'),
                'forwarding': str(st.get('source') or 'zero'),
                'switches': str(st.get('switch_count', 0)),
                'stale_commands': str(st.get('missed_frames', 0)),
                'startup_frames': str(st.get('startup_frames', 0)),
                'fallback': str(st.get('fault') or ''),
                'last_fault': str(st.get('last_fault', '')),
                'stale_estimate_frames': str(st.get('estimate_stale_frames', 0)),
                'replaced_switch_requests': str(st.get('replaced_requests', 0))}

    # ------------------------------------------------------------------ frames
    def on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """Decide and publish the actuator command of frame ``t_ns``."""
        cmd, _ = self.component.step(t_ns, self.to_core(msgs))
        self.cmd_pub.publish(convert.COMMAND.to_msg(cmd, self.epoch_ns))
        for topic, x in actuator_commands(cmd, self.wheel_names):
            pub = self.actuator_pubs[topic]
            if pub.get_subscription_count() > 0:
                pub.publish(convert.for_topic(topic).to_msg(x, self.epoch_ns))
        # the last frame's status always goes out: a degraded run's missed-frame count is the
        # one the launcher reads from it (docs/reliability.md, engine parity of the count)
        self._publish_status(force=self.is_last_frame(t_ns, self._own_period_ns))

    def _publish_status(self, force: bool = False) -> None:
        st = self.core.status()
        # published on a change of what is forwarded and once per wall second
        key = status_key(st, self.core.active)
        now = time.monotonic()
        if not force and key == self._last_status and now - self._last_status_wall < 1.0:
            return
        if key != self._last_status and self._last_status is not None:
            self.get_logger().info(f'controller status: active {key[0]}, mode {key[1] or "-"}'
                                   f', switches {key[2]}, forwarding {key[3] or "zero"}')
        self._last_status, self._last_status_wall = key, now
        self.status_pub.publish(convert.CONTROLLER_STATUS.to_msg(
            self.component.status(self.sim_t_ns, st), self.epoch_ns))


def main(args=None) -> int:
    """``ros2 run adcs_nodes controller_manager``."""
    return runtime.run(ControllerManagerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
