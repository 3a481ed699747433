"""``horizon_sensor`` node: the simulated Earth horizon sensor (roll and pitch, paper 004).

Subscribes ``sim/state`` and ``sim/environment`` (both every frame); every ``period_s`` of sim
time t publishes ``sensors/horizon`` (``adcs_msgs/HorizonSensor``) stamped t, with
``header.frame_id`` = ``frame_id`` (default ``horizon_sensor``). The sensor sees the Earth:
the zenith in body axes is ``R(q_eci_body)^T r_eci / |r_eci|`` (the orbit frame's z axis), from
which :class:`sim_node.models.sensors.HorizonSensor` gives the 3-2-1 roll and pitch of the
body w.r.t. the orbit frame. It always publishes: ``valid = false`` (NaN angles) when the
Earth is outside the field of view, so the estimator can count invalid data. A missing or
non-finite truth publishes nothing and logs a warning.

Parameters (SI, radians; paper 004 gives no error model, the defaults are typical of a
static infrared Earth sensor): ``period_s`` (1.0), ``noise_std_rad`` (0.1 deg for roll and
pitch), ``bias_rad`` ([0, 0]), ``scale_factor_error`` ([0, 0]), ``fov_rad`` (30 deg; scalar or
[roll, pitch]), ``frame_id`` ('horizon_sensor'), plus the common ones of
:class:`~adcs_nodes.nodes.lockstep_node.LockstepNode`. Seed: ``derive_seed(seed, node name)``.
"""
from __future__ import annotations

from adcs_msgs.msg import HorizonSensor as HorizonMsg
from adcs_nodes.nodes import runtime
from sim_node.nodes.sensor_node import SensorNode


class HorizonSensorNode(SensorNode):
    """Publishes roll/pitch samples of the truth attitude (see module docstring)."""

    invalid = property(lambda self: self.component.invalid)

    def __init__(self, name: str = 'horizon_sensor', **kwargs) -> None:
        super().__init__(name, 'horizon_sensor', HorizonMsg, **kwargs)
        self.start()


def main(args=None) -> int:
    """``ros2 run sim_node horizon_sensor``."""
    return runtime.run(HorizonSensorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
