"""``guidance`` node: publishes the attitude target from the scenario's profile.

Every ``period_s`` of sim time t it publishes ``adcs/attitude_target``
(``adcs_msgs/AttitudeTarget``) stamped t, ``header.frame_id`` = the profile's frame
(``orbit`` or ``eci``): target attitude, rate, acceleration, time to go and the segment type.
The profile is either quaternion segments (:mod:`adcs_nodes.core.guidance`: hold, slew,
track; per-segment array parameters; the default holds the orbital frame, paper 000's target)
or, with ``euler312_profile`` (JSON text), paper 001's maneuvers, holds and sine tracking in
its LVLH 3-1-2 Euler angles (:mod:`adcs_nodes.core.guidance_profiles`, converted to the orbit
frame at that module's boundary).

It also hosts the ``adcs/slew`` action (:class:`~adcs_nodes.nodes.slew_action.SlewActionServer`):
an accepted goal replaces the profile by a hold of the goal attitude from the next frame on
(and asks the manager to switch to the goal's controller, if one is named); a cancel holds
the current attitude. Goals arrive in wall time, so a run with slew goals is not
deterministic (a scripted profile is).
"""
from __future__ import annotations

import json
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
from std_msgs.msg import Header

from adcs_msgs.msg import AttitudeTarget
from adcs_msgs.srv import SwitchController
from adcs_nodes.core.guidance import FRAMES, SEGMENT_TYPES, TargetSample, guidance_from_params
from adcs_nodes.core.guidance_profiles import profile_from_dicts
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.convert import to_quat, to_vec3
from adcs_nodes.nodes.managed import ManagedLockstepNode
from adcs_nodes.nodes.messages import make
from adcs_nodes.nodes.slew_action import SlewActionServer
from adcs_nodes.registry import Param

PARAMS = (
    Param('period_s', 'float', 2.0, 's', 'publication period', positive=True, read_only=True),
    Param('frame', 'str', 'orbit', '-', 'frame of the profile attitudes', choices=FRAMES,
          read_only=True),
    Param('profile_t_s', 'float[]', [0.0], 's', 'start time of each segment', min=0.0,
          read_only=True),
    Param('profile_type', 'str[]', ['hold'], '-', 'type of each segment: '
          + ', '.join(SEGMENT_TYPES), read_only=True),
    Param('profile_q_xyzw', 'float[]', [0.0, 0.0, 0.0, 1.0], '-', 'attitude of each segment '
          '(4 values each, scalar last)', min=-1.0, max=1.0, read_only=True),
    Param('profile_duration_s', 'float[]', [0.0], 's', 'slew duration of each segment',
          min=0.0, read_only=True),
    Param('profile_axis_body', 'float[]', [0.0, 0.0, 1.0], '-', 'tracking axis of each '
          'segment (3 values each)', read_only=True),
    Param('profile_amplitude_deg', 'float[]', [0.0], 'deg', 'tracking amplitude of each '
          'segment', min=0.0, max=180.0, read_only=True),
    Param('profile_period_s', 'float[]', [0.0], 's', 'tracking period of each segment',
          min=0.0, read_only=True),
    Param('controllers', 'str[]', [''], '-', 'controllers a slew goal may name (the run\'s)',
          read_only=True),
    Param('euler312_profile', 'str', '', '-', "paper 001 profile as JSON: a list of "
          "{type: maneuver|hold|sine, start_s, end_s, ...} in LVLH 3-1-2 Euler degrees "
          "(replaces the segments; '': none)", read_only=True),
)


class _Euler312:
    """Adapter: a paper 001 :class:`Profile` with the quaternion guidance's ``at(t)``."""

    def __init__(self, text: str) -> None:
        try:
            items = json.loads(text)
        except ValueError as exc:
            raise ValueError(f'euler312_profile is not JSON: {exc}') from None
        self.profile = profile_from_dicts(items)

    def at(self, t: float) -> TargetSample:
        q, w, a, ttg, frame = self.profile.profile_at(t)
        kind = 'maneuver' if ttg > 0 else 'hold'
        return TargetSample(q, w, a, frame, ttg, kind)


class GuidanceNode(ManagedLockstepNode):
    """Publishes the target of the profile (see module docstring); a managed node."""

    def __init__(self, name: str = 'guidance', **kwargs: Any) -> None:
        super().__init__(name, **kwargs)

    def configure(self) -> None:
        """Parameters, profile, publisher and the slew action (lifecycle configure)."""
        p = node_params.declare_all(self, PARAMS)
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        if p['euler312_profile']:
            self.guidance = _Euler312(p['euler312_profile'])
        else:
            self.guidance = guidance_from_params(
                p['profile_t_s'], p['profile_type'], p['profile_q_xyzw'],
                p['profile_duration_s'], p['profile_axis_body'], p['profile_amplitude_deg'],
                p['profile_period_s'], p['frame'])
        self.pub = self.publisher(AttitudeTarget, 'adcs/attitude_target')
        self.override: Optional[TargetSample] = None     # a slew goal's hold target
        names = [n for n in p['controllers'] if n]
        self.switch_client = self.create_client(SwitchController, 'adcs/switch_controller')
        self.slew = SlewActionServer(self, self.set_goal_target, self.request_switch,
                                     known_controllers=names or None)
        self.lockstep_inputs({}, p['period_s'], self.on_frame)
        self.start_handshake()

    def set_goal_target(self, q_xyzw: np.ndarray, frame: str) -> None:
        """Slew action: hold ``q_xyzw`` in ``frame`` from the next frame on."""
        zero = np.zeros(3)
        self.override = TargetSample(np.asarray(q_xyzw, dtype=float), zero, zero, frame, 0.0,
                                     'slew_goal')

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
        s = self.override or self.guidance.at(t_ns / NS_PER_S)
        self.pub.publish(make(
            AttitudeTarget, header=make(Header, stamp=self.stamp(t_ns), frame_id=s.frame),
            q_ref_body=to_quat(s.q_ref_body), omega_body_ref_body=to_vec3(s.omega_body_ref_body),
            omega_dot_body_ref_body=to_vec3(s.omega_dot_body_ref_body),
            time_to_go_s=float(s.time_to_go_s), profile=s.profile))


def main(args=None) -> int:
    """``ros2 run adcs_nodes guidance``."""
    return runtime.run(GuidanceNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
