"""``star_tracker`` node: the simulated star tracker (attitude w.r.t. ECI).

Subscribes ``sim/state`` and ``sim/environment`` (both every frame, like every sensor node, so
the launcher wires all sensors alike; only the state is used); every ``period_s`` of sim time
t publishes ``sensors/star_tracker`` (``sensor_msgs/Imu``)
stamped t: ``orientation`` = measured ``q_eci_body`` (the tracker's mounting is taken as the
body frame), ``orientation_covariance`` = ``diag(noise_std_rad^2)`` (small-angle error,
body axes), ``angular_velocity_covariance[0] = linear_acceleration_covariance[0] = -1``
(ROS convention: not provided), ``header.frame_id`` = ``frame_id`` (default ``star_tracker``).
Errors: :class:`sim_node.models.sensors.StarTracker`. A missing or non-finite truth publishes
nothing and logs a warning.

Parameters (SI, radians): ``period_s`` (1.0), ``noise_std_rad`` (paper 001's 0.02 deg
3-sigma: 0.00667 deg = 1.1636e-4 rad per axis), ``frame_id`` ('star_tracker'), plus the common
ones of :class:`~adcs_nodes.nodes.lockstep_node.LockstepNode`. Seed: ``derive_seed(seed, node
name)``.
"""
from __future__ import annotations


from sensor_msgs.msg import Imu

from adcs_nodes.nodes import runtime
from sim_node.nodes.sensor_node import SensorNode


class StarTrackerNode(SensorNode):
    """Publishes star-tracker attitude samples of the truth (see module docstring)."""

    def __init__(self, name: str = 'star_tracker', **kwargs) -> None:
        super().__init__(name, 'star_tracker', Imu, **kwargs)
        self.start()


def main(args=None) -> int:
    """``ros2 run sim_node star_tracker``."""
    return runtime.run(StarTrackerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
