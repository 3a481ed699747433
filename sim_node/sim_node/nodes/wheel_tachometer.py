"""``wheel_tachometer`` node: measured reaction-wheel speeds, as a wheel driver publishes them.

Subscribes ``sim/wheels`` (``adcs_msgs/WheelState``, every frame); every ``period_s`` of sim
time t publishes ``sensors/wheels`` (``sensor_msgs/JointState``) stamped t: ``name`` = the
wheel names, ``velocity`` = measured speeds relative to the body [rad/s] (model
:class:`sim_node.models.sensors.WheelTachometer`: noise and quantisation), ``position`` and
``effort`` empty. A real wheel driver publishing the same topic replaces this node; the flight
software never reads ``sim/wheels``. Parameters: the ``wheel_tachometer`` registry entry
(``adcs schema``).
"""
from __future__ import annotations

from typing import Any, Dict, List

import numpy as np
from sensor_msgs.msg import JointState

from adcs_msgs.msg import WheelState
from adcs_nodes.nodes import runtime
from sim_node.nodes.sensor_node import SensorNode


class WheelTachometerNode(SensorNode):
    """Publishes measured wheel speeds (see module docstring)."""

    def __init__(self, name: str = 'wheel_tachometer', **kwargs: Any) -> None:
        super().__init__(name, 'wheel_tachometer', JointState, **kwargs)
        self.start()

    def start(self) -> None:
        """Subscribe to ``sim/wheels`` in lockstep (the wheels, not the attitude truth)."""
        frame_s = self.frame_ns / 1e9
        self.lockstep_inputs({'wheels': (WheelState, 'sim/wheels', frame_s)},
                             float(self.p['period_s']), self._on_wheels)
        self.start_handshake()

    def _on_wheels(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        wheels = msgs.get('wheels')
        if wheels is None:
            self.get_logger().warning(f't={t_ns / 1e9:.3f} s: no wheel truth yet, no sample')
            return
        speed = np.asarray(wheels.speed, dtype=float)
        if not np.all(np.isfinite(speed)):
            self.get_logger().warning(f't={t_ns / 1e9:.3f} s: non-finite wheel speed, no sample')
            return
        msg = self.header(JointState(), t_ns)
        msg.name = list(wheels.names)
        msg.velocity = [float(v) for v in self.model.measure(speed)]
        self.pub.publish(msg)

    def sample(self, t_ns: int, state, env) -> None:
        """Unused: this sensor samples the wheels, not the attitude truth."""


def main(args=None) -> int:
    """``ros2 run sim_node wheel_tachometer``."""
    return runtime.run(WheelTachometerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
