"""The generic sensor node: any registered sensor model, chosen by parameter ``sensor``.

``ros2 run sim_node sensor_node --ros-args -p sensor:=gyro`` (the sensor defaults to the node's
name, which is what the launcher gives it); ``ros2 run sim_node gyro`` and the other sensor
names are aliases. The node reads its parameters (its registry entry's, plus ``frame_id``,
``faults`` and the common ones of :class:`~adcs_nodes.nodes.lockstep_node.LockstepNode`),
draws its noise from ``derive_seed(seed, node name)``, and every ``period_s`` fires on the
truth of that frame (``sim/state`` and ``sim/environment``, or ``sim/wheels`` for the
tachometer): the sensor's component (:mod:`sim_node.components.sensors`, the FrameLoop's too)
makes the sample, the topic's converter the message (:mod:`adcs_nodes.msgs.convert`; the
topics and messages: ``docs/topics.md``).

``header.frame_id`` is ``frame_id`` (default: the sensor's name), whose mount
(``q_body_sensor_xyzw``, identity when the model has none) the node puts on ``/tf_static``.
A missing or non-finite truth publishes nothing and logs a warning. A plugin's sensor (in
``plugins``) runs the same way.
"""
from __future__ import annotations

import importlib
from typing import Any, Dict, List, Optional

from std_msgs.msg import String

from adcs_msgs.msg import AttitudeState, Environment, WheelState
from adcs_nodes import inputs, registry
from adcs_nodes.core.lockstep import NS_PER_S, derive_seed
from adcs_nodes.msgs import convert
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.adapter import ToCore, node_log
from adcs_nodes.nodes.lockstep_node import QOS_DATA, LockstepNode
from adcs_nodes.nodes.tf import TfPublisher, mount_transforms
from adcs_nodes.registry import Param
from sim_node.components.sensors import component_class, sensor_faults
from sim_node.faults import FAULTS_PARAM, INJECT_TOPIC, SensorFaults, injected

#: The truth a sensor component reads: ``key: (message type, topic, converter)``.
TRUTH = {'state': (AttitudeState, 'sim/state', convert.ATTITUDE_STATE),
         'env': (Environment, 'sim/environment', convert.ENVIRONMENT),
         'wheels': (WheelState, 'sim/wheels', convert.WHEEL_STATE)}


class SensorNode(LockstepNode):
    """A registered sensor model as a lockstep node (see module docstring)."""

    SIMULATED_WORLD = True      # the simulator: lockstep only
    #: the magnetometer's lost samples, the horizon sensor's invalid ones (``/diagnostics``)
    dropouts = property(lambda self: self.component.dropouts)
    invalid = property(lambda self: self.component.invalid)

    def __init__(self, name: Optional[str] = None, sensor: Optional[str] = None,
                 **kwargs: Any) -> None:
        super().__init__(name or sensor or 'sensor', **kwargs)
        registry.load_plugins(self.param('plugins', []))
        sensor = self.param('sensor', sensor or self.get_name(),
                            'registered sensor model of this node (adcs list)')
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
        self.component = component_class(sensor)(
            self.model, self.frame_id, node_log(self),
            sensor_faults(sensor, self.p['faults'], self.seed))
        topic, msg_type = self.entry.node[3], self.entry.node[4]
        pkg, _, cls = msg_type.split('/')
        self.pub = self.publisher(getattr(importlib.import_module(f'{pkg}.msg'), cls), topic)
        self.to_msg = inputs.converter(topic).to_msg
        self.to_core = ToCore({k: TRUTH[k][2].to_core for k in self.component.truth},
                              self.epoch_ns)
        # live faults (adcs fault): not part of the lockstep handshake (QOS_DATA: reliable)
        self.create_subscription(String, INJECT_TOPIC, self._on_inject, QOS_DATA)
        # the mount, defined once (parameter q_body_sensor_xyzw, identity when the model has
        # none) and published for every consumer on /tf_static: body -> frame_id
        self.tf_static = TfPublisher(self, static=True)
        self.tf_static.send(mount_transforms(self.stamp(0), {
            self.frame_id: self.p.get('q_body_sensor_xyzw', [0.0, 0.0, 0.0, 1.0])}))
        frame_s = self.frame_ns / NS_PER_S
        self.lockstep_inputs({k: (TRUTH[k][0], TRUTH[k][1], frame_s)
                              for k in self.component.truth},
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
        x = self.component.step(t_ns, self.to_core(msgs))
        if x is not None:
            self.pub.publish(self.to_msg(x, self.epoch_ns))


def main(args=None, sensor: Optional[str] = None) -> int:
    """``ros2 run sim_node sensor_node --ros-args -p sensor:=NAME``: the node is named after
    its sensor (``-r __node:=`` wins; then the sensor defaults to the node name)."""
    sensor = sensor or runtime.given_parameter('sensor', args)
    return runtime.run(lambda: SensorNode(sensor=sensor), args)


def _alias(sensor: str):
    def main_sensor(args=None) -> int:
        return main(args, sensor)
    main_sensor.__doc__ = f'``ros2 run sim_node {sensor}``.'
    return main_sensor


main_magnetometer, main_gyro, main_star_tracker, main_horizon_sensor, main_wheel_tachometer = (
    _alias(s) for s in ('magnetometer', 'gyro', 'star_tracker', 'horizon_sensor',
                        'wheel_tachometer'))


if __name__ == '__main__':
    raise SystemExit(main())
