"""A test-only controller that reads the gyro and the star tracker (issue 19: a registered
controller may declare any input kind; one class and one registry entry, nothing else).

It damps the body rate with an ideal body torque, ``tau = -k omega_gyro`` (clipped to the
limit), but only once the star tracker has given an attitude: no star-tracker sample, no
command. So the rate decays only when both inputs reach it.
"""
import numpy as np

from adcs_nodes.core.control import Command
from adcs_nodes.registry import Entry, Param, register


class GyroDamper:
    """Rate damping on the gyro, armed by the star tracker (see the module docstring)."""

    def __init__(self, gain_Nms, max_torque_Nm):
        self.gain = float(gain_Nms)
        self.limit = float(max_torque_Nm)
        self.star_samples = 0
        self.gyro_samples = 0

    def reset(self):
        """Forget the star tracker."""
        self.star_samples = 0

    def update(self, inputs, t, dt):
        """``-k omega`` once a star-tracker attitude has arrived."""
        if inputs.q_eci_body_meas is not None:
            self.star_samples += 1
        if inputs.gyro_rate_body is None or self.star_samples == 0:
            return Command.zero(0, 'waiting for the gyro and the star tracker')
        self.gyro_samples += 1
        tau = np.clip(-self.gain * inputs.gyro_rate_body, -self.limit, self.limit)
        return Command(np.zeros(3), np.zeros(0), tau)


register(Entry(
    'controller', 'gyro_damper', 'test-only rate damper on the gyro, armed by the star tracker',
    'gyro_damper:GyroDamper',
    (Param('gain_Nms', 'float', 20.0, 'N m s', 'rate gain k', positive=True),
     Param('max_torque_Nm', 'float', 1.0, 'N m', 'torque limit per axis', positive=True)),
    lambda p, ctx: GyroDamper(p['gain_Nms'], p['max_torque_Nm']),
    inputs=('gyro', 'star_tracker'), actuators=('torque',)))
