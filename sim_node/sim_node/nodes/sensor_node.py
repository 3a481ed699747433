"""Common part of the simulated sensor nodes.

Every sensor node reads its parameters (its registry entry's, in ``sim_node.entries``, plus the
common ones of :class:`~adcs_nodes.nodes.lockstep_node.LockstepNode`), draws its noise from
``derive_seed(seed, node name)``, and fires every ``period_s`` on the truth of that frame:
``sim/state`` and ``sim/environment`` (both published every frame). A missing or non-finite
truth publishes nothing and logs a warning. The entry builds the model; the subclass implements
:meth:`SensorNode.sample`.
"""
from __future__ import annotations

import abc
from typing import Any, Dict, List

import numpy as np

from adcs_msgs.msg import AttitudeState, Environment
from adcs_nodes.core.lockstep import NS_PER_S, derive_seed
from adcs_nodes.nodes.convert import all_finite
from adcs_nodes import registry
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes.lockstep_node import LockstepNode
from adcs_nodes.registry import Param
from adcs_nodes.nodes.tf import TfPublisher, mount_transforms


class SensorNode(LockstepNode, metaclass=abc.ABCMeta):
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
        self.p = node_params.declare_all(self, self.entry.params + (frame,))
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.frame_id = str(self.p['frame_id'])
        self.sensor_seed = derive_seed(self.seed, self.get_name())
        self.model = self.entry.build(self.p, {'seed': self.sensor_seed})
        self.pub = self.publisher(msg_type, self.entry.node[3])
        # the mount, defined once (parameter q_body_sensor_xyzw, identity when the model has
        # none) and published for every consumer on /tf_static: body -> frame_id
        self.tf_static = TfPublisher(self, static=True)
        self.tf_static.send(mount_transforms(self.stamp(0), {
            self.frame_id: self.p.get('q_body_sensor_xyzw', [0.0, 0.0, 0.0, 1.0])}))

    def start(self) -> None:
        """Subscribe to the truth in lockstep and announce readiness (end of __init__)."""
        frame_s = self.frame_ns / NS_PER_S
        self.lockstep_inputs({'state': (AttitudeState, 'sim/state', frame_s),
                              'env': (Environment, 'sim/environment', frame_s)},
                             float(self.p['period_s']), self._on_frame)
        self.start_handshake()

    def _on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        state, env = msgs['state'], msgs['env']
        if state is None or env is None:
            self.get_logger().warning(f't={t_ns / NS_PER_S:.3f} s: no truth yet, no sample')
            return
        self.sample(t_ns, state, env)

    def truth_ok(self, t_ns: int, what: str, *arrays: np.ndarray) -> bool:
        """True when every truth array is finite and non-zero; else warn (no sample)."""
        if all_finite(*arrays) and all(np.any(a) for a in arrays):
            return True
        self.get_logger().warning(
            f't={t_ns / NS_PER_S:.3f} s: non-finite truth ({what}), no sample')
        return False

    def header(self, msg: Any, t_ns: int) -> Any:
        """Stamp ``msg`` with frame ``t_ns`` and this sensor's frame id; returns it."""
        msg.header.stamp = self.stamp(t_ns)
        msg.header.frame_id = self.frame_id
        return msg

    @abc.abstractmethod
    def sample(self, t_ns: int, state: AttitudeState, env: Environment) -> None:
        """Measure at frame ``t_ns`` from the truth and publish."""
