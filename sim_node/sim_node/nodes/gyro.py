"""``gyro`` node: the simulated three-axis rate gyro.

Subscribes ``sim/state`` and ``sim/environment`` (both every frame, like every sensor node, so
the launcher wires all sensors alike; only the state is used); every ``period_s`` of sim time
t publishes ``sensors/gyro`` (``sensor_msgs/Imu``) stamped t:
``angular_velocity`` = measured ``omega_body_eci_body`` [rad/s, body axes],
``angular_velocity_covariance`` = ``diag(noise_std_rad_s^2)`` (white part only; the bias is
not in it), ``orientation_covariance[0] = linear_acceleration_covariance[0] = -1`` (ROS
convention: not provided), ``header.frame_id`` = ``frame_id`` (default ``gyro``; the gyro axes
are the body axes). Errors: :class:`sim_node.models.sensors.Gyro`, its bias random walk
integrated over the sim time between two samples (0 before the first). A missing or
non-finite truth publishes nothing and logs a warning (the bias walk then spans the gap).

Parameters (SI, radians; defaults from paper 001's "random drift 0.01 deg/h 3-sigma"):
``period_s`` (1.0), ``noise_std_rad_s`` (0.01/3 deg/h = 1.616e-8 rad/s per axis),
``bias_initial_rad_s`` ([0, 0, 0]), ``bias_walk_std_rad_s_sqrt_s`` (2.69e-10 rad/s/sqrt(s):
the bias reaches 0.01 deg/h 3-sigma after 1 h), ``frame_id`` ('gyro'), plus the common ones
of :class:`~adcs_nodes.nodes.lockstep_node.LockstepNode`. Seed: ``derive_seed(seed, node
name)``.
"""
from __future__ import annotations

from sensor_msgs.msg import Imu

from adcs_nodes.nodes import runtime
from sim_node.nodes.sensor_node import SensorNode


class GyroNode(SensorNode):
    """Publishes gyro samples of the truth rate (see module docstring)."""

    def __init__(self, name: str = 'gyro', **kwargs) -> None:
        super().__init__(name, 'gyro', Imu, **kwargs)
        self.start()


def main(args=None) -> int:
    """``ros2 run sim_node gyro``."""
    return runtime.run(GyroNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
