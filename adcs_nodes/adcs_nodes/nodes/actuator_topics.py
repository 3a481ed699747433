"""Per-actuator commands in standard ROS types, so a driver does not depend on ``adcs_msgs``.

The controller manager publishes, next to its ``adcs/actuator_command``
(``adcs_msgs/ActuatorCommand``, the graph's internal command) and with the same stamp:

* ``actuators/magnetorquer/command``: ``geometry_msgs/Vector3Stamped``, the commanded dipole
  [A m^2] in body axes (``header.frame_id`` = ``body``), when the spacecraft has magnetorquers;
* ``actuators/wheels/command``: ``sensor_msgs/JointState`` with ``name`` = the wheel names and
  ``effort`` = the commanded motor torques [N m] (``position``/``velocity`` empty), when it has
  reaction wheels.

Both are held by the driver until the next command (zero-order hold, as the simulated dynamics
does). The values are the manager's: always finite and inside the actuator limits. A topic
with no subscriber (no driver, no recorder: the simulated graph) is not built or published
(issue 13).
"""
from __future__ import annotations

from typing import Any, Optional, Sequence

from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from adcs_nodes.nodes.messages import make

MAGNETORQUER_TOPIC = 'actuators/magnetorquer/command'
WHEELS_TOPIC = 'actuators/wheels/command'


class ActuatorTopics:
    """Publishers of the standard per-actuator command topics (see module docstring).

    Parameters
    ----------
    node : rclpy.node.Node
        The publishing node (its ``publisher`` method is used when it has one, so the start
        handshake and QoS conventions cover the topics).
    magnetorquer : bool
        Publish the dipole topic.
    wheel_names : sequence of str
        Wheel joint names (empty: no wheel topic).
    """

    def __init__(self, node: Any, magnetorquer: bool, wheel_names: Sequence[str]) -> None:
        make = getattr(node, 'publisher', None) or (
            lambda t, topic: node.create_publisher(t, topic, 10))
        self.wheel_names = [str(n) for n in wheel_names]
        self.mtq_pub = make(Vector3Stamped, MAGNETORQUER_TOPIC) if magnetorquer else None
        self.wheel_pub = make(JointState, WHEELS_TOPIC) if self.wheel_names else None

    def publish(self, cmd: Any) -> None:
        """Publish the parts of ``cmd`` (an ``adcs_msgs/ActuatorCommand``) this craft has."""
        if self.mtq_pub is not None and self.mtq_pub.get_subscription_count() > 0:
            self.mtq_pub.publish(make(
                Vector3Stamped, header=make(Header, stamp=cmd.header.stamp, frame_id='body'),
                vector=cmd.dipole_body))
        if self.wheel_pub is not None and self.wheel_pub.get_subscription_count() > 0:
            j = JointState()
            j.header.stamp = cmd.header.stamp
            j.name = list(self.wheel_names)
            torque = list(cmd.wheel_torque)
            j.effort = [float(v) for v in torque] if len(torque) == len(self.wheel_names) \
                else [0.0] * len(self.wheel_names)
            self.wheel_pub.publish(j)


def wheel_names_for(count: int, names: Optional[Sequence[str]] = None) -> list:
    """``names`` when given (and of length ``count``), else ``wheel0 .. wheel<count-1>`` (the
    dynamics node's default names)."""
    names = [str(n) for n in (names or []) if str(n)]
    if names and len(names) != count:
        raise ValueError(f'{len(names)} wheel names for {count} wheels')
    return names or [f'wheel{i}' for i in range(count)]
