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


from sensor_msgs.msg import MagneticField

from adcs_nodes.nodes import runtime
from sim_node.nodes.sensor_node import SensorNode


class MagnetometerNode(SensorNode):
    """Publishes magnetometer samples of the truth field (see module docstring)."""

    dropouts = property(lambda self: self.component.dropouts)

    def __init__(self, name: str = 'magnetometer', **kwargs) -> None:
        super().__init__(name, 'magnetometer', MagneticField, **kwargs)
        self.start()


def main(args=None) -> int:
    """``ros2 run sim_node magnetometer``."""
    return runtime.run(MagnetometerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
