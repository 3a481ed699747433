"""``magnetometer`` node: the simulated three-axis magnetometer.

Subscribes ``sim/state`` and ``sim/environment`` (both every frame); every ``period_s`` of sim
time t publishes ``sensors/magnetometer`` (``sensor_msgs/MagneticField``) stamped t: the field
in the sensor frame [T], ``header.frame_id`` = ``frame_id`` (default ``magnetometer``),
covariance ``diag(noise_std_T^2)``. Truth: ``b_body = R(q_eci_body)^T b_eci``; errors:
:class:`sim_node.models.sensors.Magnetometer`. A dropout publishes a NaN field for that frame
(counted in ``dropouts``); a missing or non-finite truth publishes nothing and logs a warning.

Parameters (SI, radians; defaults: paper 000's noise and LSB, no other error):
``period_s`` (1.0), ``noise_std_T`` ([375e-9, 25e-9, 65e-9]), ``bias_T`` ([0, 0, 0]),
``misalignment_rad`` ([0, 0, 0]), ``scale_factor_error`` ([0, 0, 0]), ``lsb_T`` (20e-9),
``saturation_T`` (0.0: none; scalar or 3 values), ``dropout_probability`` (0.0),
``q_body_sensor`` ([0, 0, 0, 1]), ``frame_id`` ('magnetometer'), plus the common ones of
:class:`~adcs_nodes.nodes.lockstep_node.LockstepNode`. Seed: ``derive_seed(seed, node name)``.
"""
from __future__ import annotations


import numpy as np
from sensor_msgs.msg import MagneticField

from adcs_msgs.msg import AttitudeState, Environment
from adcs_nodes.core import attitude as att
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.convert import quat, to_vec3, vec3
from sim_node.nodes.sensor_node import SensorNode


class MagnetometerNode(SensorNode):
    """Publishes magnetometer samples of the truth field (see module docstring)."""

    def __init__(self, name: str = 'magnetometer', **kwargs) -> None:
        super().__init__(name, 'magnetometer', MagneticField, **kwargs)
        self.covariance = self.model.covariance.reshape(-1).tolist()
        self.dropouts = 0
        self.start()

    def sample(self, t_ns: int, state: AttitudeState, env: Environment) -> None:
        """Measure the field at sim time ``t_ns`` and publish it (NaN on a dropout)."""
        q_eci_body, b_eci = quat(state.q_eci_body), vec3(env.b_eci)
        if not self.truth_ok(t_ns, 'q_eci_body or b_eci', q_eci_body, b_eci):
            return
        b_sensor = self.model.measure(att.to_matrix(q_eci_body).T @ b_eci)
        if b_sensor is None:
            # a lost sample is published as NaN (the ROS convention for "no data"), so the
            # lockstep goes on and the estimator counts it as rejected instead of waiting
            self.dropouts += 1
            self.get_logger().debug(f't={t_ns / NS_PER_S:.3f} s: dropout ({self.dropouts})')
            b_sensor = np.full(3, np.nan)
        msg = self.header(MagneticField(), t_ns)
        msg.magnetic_field = to_vec3(b_sensor)
        msg.magnetic_field_covariance = self.covariance
        self.pub.publish(msg)


def main(args=None) -> int:
    """``ros2 run sim_node magnetometer``."""
    return runtime.run(MagnetometerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
