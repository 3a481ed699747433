"""Common part of the simulated sensor nodes.

Every sensor node reads its parameters (its registry entry's, in ``sim_node.entries``, plus the
common ones of :class:`~adcs_nodes.nodes.lockstep_node.LockstepNode`), draws its noise from
``derive_seed(seed, node name)``, and fires every ``period_s`` on the truth of that frame:
``sim/state`` and ``sim/environment`` (both published every frame). A missing or non-finite
truth publishes nothing and logs a warning. The entry builds the model; the frame step is the
sensor's component (:mod:`sim_node.components.sensors`), which the FrameLoop calls too.
"""
from __future__ import annotations

from typing import Any, Dict, List

from std_msgs.msg import String

from adcs_msgs.msg import AttitudeState, Environment, WheelState
from adcs_nodes.components.base import FrameClock
from adcs_nodes.core.lockstep import NS_PER_S, derive_seed
from adcs_nodes import registry
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes.adapter import node_log
from adcs_nodes.nodes.lockstep_node import QOS_DATA, LockstepNode
from adcs_nodes.registry import Param
from adcs_nodes.nodes.tf import TfPublisher, mount_transforms
from sim_node.components.sensors import SENSOR_COMPONENTS, sensor_faults
from sim_node.faults import FAULTS_PARAM, INJECT_TOPIC, SensorFaults, injected


class SensorNode(LockstepNode):
    """Base of the sensor nodes: parameters and model from the sensor's registry entry.

    Parameters
    ----------
    name : str
        Node name.
    sensor : str
        Registry name of the sensor model (``adcs list``); its parameters are the node's.
    msg_type
        Output message type (the topic is the entry's).
    """

    SIMULATED_WORLD = True      # the simulator: lockstep only

    def __init__(self, name: str, sensor: str, msg_type, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.entry = registry.get('sensor', sensor)
        frame = Param('frame_id', 'str', sensor, '-', 'header.frame_id of the samples and '
                      'the child frame of the body -> sensor mount on /tf_static',
                      read_only=True)
        self.p = node_params.declare_all(self, self.entry.params + (frame, FAULTS_PARAM))
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.frame_id = str(self.p['frame_id'])
        self.sensor_seed = derive_seed(self.seed, self.get_name())
        self.model = self.entry.build(self.p, {'seed': self.sensor_seed})
        self.component = SENSOR_COMPONENTS[sensor](
            self.model, self.frame_id, FrameClock(self.epoch_ns), node_log(self),
            sensor_faults(sensor, self.p['faults'], self.seed))
        self.pub = self.publisher(msg_type, self.entry.node[3])
        # live faults (adcs fault): not part of the lockstep handshake (QOS_DATA: reliable)
        self.create_subscription(String, INJECT_TOPIC, self._on_inject, QOS_DATA)
        # the mount, defined once (parameter q_body_sensor_xyzw, identity when the model has
        # none) and published for every consumer on /tf_static: body -> frame_id
        self.tf_static = TfPublisher(self, static=True)
        self.tf_static.send(mount_transforms(self.stamp(0), {
            self.frame_id: self.p.get('q_body_sensor_xyzw', [0.0, 0.0, 0.0, 1.0])}))

    def start(self) -> None:
        """Subscribe to the truth in lockstep and announce readiness (end of __init__)."""
        frame_s = self.frame_ns / NS_PER_S
        truth = {'state': (AttitudeState, 'sim/state', frame_s),
                 'env': (Environment, 'sim/environment', frame_s),
                 'wheels': (WheelState, 'sim/wheels', frame_s)}
        self.lockstep_inputs({k: truth[k] for k in self.component.truth},
                             float(self.p['period_s']), self._on_frame)
        self.start_handshake()

    def _on_inject(self, msg: String) -> None:
        """A live fault (``adcs fault``): this sensor's is applied from the next frame."""
        try:
            fault = injected(msg.data, self.sim_t_ns + 1, sensors=[self.entry.name])
        except ValueError as exc:
            self.get_logger().warning(f'live fault refused: {exc}')
            return
        if fault is None:
            return                                      # another sensor's
        if self.component.faults is None:
            self.component.faults = SensorFaults([], self.seed,
                                                 rotation=self.entry.name == 'star_tracker')
        self.component.faults.add(fault, self.seed)
        self.get_logger().warning(f'live fault {fault.describe()} from t = '
                                  f'{fault.start_ns / NS_PER_S:g} s (not deterministic)')

    def _on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        msg = self.component.step(t_ns, msgs)
        if msg is not None:
            self.pub.publish(msg)
