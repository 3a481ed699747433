"""``guidance`` node: publishes the attitude target from the scenario's profile.

Every ``period_s`` of sim time t it publishes ``adcs/attitude_target``
(``adcs_msgs/AttitudeTarget``) stamped t, ``header.frame_id`` = the profile's frame
(``orbit`` or ``eci``): target attitude, rate, acceleration, time to go and the segment type.
The profile is either quaternion segments (:mod:`adcs_nodes.core.guidance`: hold, slew,
track; per-segment array parameters; the default holds the orbital frame, paper 000's target)
or, with ``euler312_profile`` (JSON text), paper 001's maneuvers, holds and sine tracking in
its LVLH 3-1-2 Euler angles (:mod:`adcs_nodes.core.guidance_profiles`, converted to the orbit
frame at that module's boundary).

It hosts the ``adcs/slew`` action (:class:`~adcs_nodes.nodes.slew_action.SlewActionServer`):
a goal replaces the profile by a hold of its attitude from the next frame (not deterministic:
goals arrive in wall time).
"""
from __future__ import annotations

from typing import Any, Dict, List, Tuple

import numpy as np

from adcs_msgs.msg import AttitudeTarget
from adcs_msgs.srv import SwitchController
from adcs_nodes.components.guidance import PARAMS, GuidanceComponent
from adcs_nodes.msgs.convert import TARGET
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.managed import ManagedLockstepNode
from adcs_nodes.nodes.slew_action import SlewActionServer


class GuidanceNode(ManagedLockstepNode):
    """Publishes the target of the profile (see module docstring); a managed node."""

    def __init__(self, name: str = 'guidance', **kwargs: Any) -> None:
        super().__init__(name, **kwargs)

    def configure(self) -> None:
        """Parameters, profile, publisher and the slew action (lifecycle configure)."""
        p = node_params.declare_all(self, PARAMS)
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.component = GuidanceComponent(p)
        self.pub = self.publisher(AttitudeTarget, 'adcs/attitude_target')
        names = [n for n in p['controllers'] if n]
        self.switch_client = self.create_client(SwitchController, 'adcs/switch_controller')
        self.slew = SlewActionServer(self, self.set_goal_target, self.request_switch,
                                     known_controllers=names or None)
        self.lockstep_inputs({}, p['period_s'], self.on_frame)
        self.start_handshake()

    def set_goal_target(self, q_xyzw: np.ndarray, frame: str) -> None:
        """Slew action: hold ``q_xyzw`` in ``frame`` from the next frame on."""
        self.component.hold(q_xyzw, frame)

    def request_switch(self, name: str) -> Tuple[bool, str]:
        """Slew action: ask the manager to switch to ``name`` (answered asynchronously)."""
        if not self.switch_client.service_is_ready():
            return False, 'no controller manager (adcs/switch_controller) in this graph'
        request = SwitchController.Request()
        request.name = name
        self.switch_client.call_async(request)
        return True, f'switch to {name} requested'

    def on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """Publish the target of frame ``t_ns``."""
        self.pub.publish(TARGET.to_msg(self.component.step(t_ns), self.epoch_ns))


def main(args=None) -> int:
    """``ros2 run adcs_nodes guidance``."""
    return runtime.run(GuidanceNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
