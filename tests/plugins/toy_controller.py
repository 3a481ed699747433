"""A toy controller, defined in a test only: one class and one registry entry (issue 8).

It commands a constant magnetorquer dipole and needs only the magnetometer. The integration
test loads this file as a scenario plugin and switches to it in a launched graph, showing
that adding a controller touches no other file.
"""
import numpy as np

from adcs_nodes.core.control import Command
from adcs_nodes.registry import Entry, Param, register


class ToyController:
    """Commands ``dipole_Am2`` whenever a fresh field sample arrives, else holds it."""

    def __init__(self, dipole_Am2):
        self.dipole = np.asarray(dipole_Am2, dtype=float)

    def reset(self):
        """No state."""

    def update(self, inputs, t, dt):
        """The constant dipole (zero before the first field sample)."""
        if inputs.b_body is None:
            return Command.zero(0, 'no field sample')
        return Command(self.dipole.copy(), np.zeros(0), np.zeros(3))


register(Entry(
    'controller', 'toy', 'test-only constant-dipole controller',
    'toy_controller:ToyController',
    (Param('dipole_Am2', 'float[]', [1.0, -2.0, 3.0], 'A m^2', 'the constant dipole',
           length=3, min=-40.0, max=40.0),),
    lambda p, ctx: ToyController(p['dipole_Am2']),
    inputs=('magnetometer',), actuators=('magnetorquer',)))
