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

from typing import Any

from sensor_msgs.msg import JointState

from adcs_nodes.nodes import runtime
from sim_node.nodes.sensor_node import SensorNode


class WheelTachometerNode(SensorNode):
    """Publishes measured wheel speeds (see module docstring)."""

    def __init__(self, name: str = 'wheel_tachometer', **kwargs: Any) -> None:
        super().__init__(name, 'wheel_tachometer', JointState, **kwargs)
        self.start()


def main(args=None) -> int:
    """``ros2 run sim_node wheel_tachometer``."""
    return runtime.run(WheelTachometerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
