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


import numpy as np

from adcs_msgs.msg import AttitudeState, Environment, HorizonSensor as HorizonMsg
from adcs_nodes.core import attitude as att
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.convert import quat, vec3
from sim_node.nodes.sensor_node import SensorNode


class HorizonSensorNode(SensorNode):
    """Publishes roll/pitch samples of the truth attitude (see module docstring)."""

    def __init__(self, name: str = 'horizon_sensor', **kwargs) -> None:
        super().__init__(name, 'horizon_sensor', HorizonMsg, **kwargs)
        self.invalid = 0
        self.start()

    def sample(self, t_ns: int, state: AttitudeState, env: Environment) -> None:
        """Measure roll and pitch at sim time ``t_ns`` and publish them (see module)."""
        q_eci_body, r_eci = quat(state.q_eci_body), vec3(env.r_eci)
        if not self.truth_ok(t_ns, 'q_eci_body or r_eci', q_eci_body, r_eci):
            return
        zenith_body = att.to_matrix(q_eci_body).T @ (r_eci / np.linalg.norm(r_eci))
        m = self.model.measure_zenith(zenith_body)
        if not m.valid:
            self.invalid += 1
        var = self.model.variance
        msg = self.header(HorizonMsg(), t_ns)
        msg.roll = float(m.roll)
        msg.pitch = float(m.pitch)
        msg.roll_variance = float(var[0])
        msg.pitch_variance = float(var[1])
        msg.valid = bool(m.valid)
        self.pub.publish(msg)


def main(args=None) -> int:
    """``ros2 run sim_node horizon_sensor``."""
    return runtime.run(HorizonSensorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
