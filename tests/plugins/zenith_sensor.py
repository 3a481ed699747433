"""A test-only sensor that feeds a new input kind, added in four places and nothing else (issue
34): an Earth sensor measuring the zenith direction in body axes, and a controller that reads
it. The four places, all in this file:

1. the input record (``inputs.register``): the kind ``zenith``, its topic and message type,
   its period parameter, and its converter between the message and the core sample;
2. the sensor model: what it measures of the truth of a frame (``sample``);
3. the sensor's registry entry (parameters, the generic sensor node, the topic);
4. the consumer: a controller whose entry declares ``inputs=('zenith',)`` and reads the
   fresh sample from ``ControlInputs.samples``.

The controller points the body +z axis at the zenith with an ideal torque,
``tau = k (e_z x z_body)`` (clipped), and commands nothing without a fresh sample.
"""
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import Vector3Stamped
from std_msgs.msg import Header

from adcs_nodes import inputs
from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import Command
from adcs_nodes.msgs.convert import Converter
from adcs_nodes.msgs.fields import make, stamp_ns, to_stamp, to_vec3, vec3
from adcs_nodes.registry import Entry, Param, register

#: The generic sensor node (``sim_node.entries.SENSOR_NODE``; the flight nodes that load this
#: plugin need no simulator).
SENSOR_NODE = ('sim_node', 'sim_node.nodes.sensor_node', 'SensorNode')


@dataclass(frozen=True, slots=True)
class ZenithSample:
    """``sensors/zenith``: the measured zenith direction, body axes (unit vector)."""

    t_ns: int
    frame_id: str
    zenith_body: np.ndarray


# 1. the record, with its converter (``Vector3Stamped``: the vector, stamp and frame)
CONVERT = Converter(
    lambda x, e: make(Vector3Stamped, header=make(Header, stamp=to_stamp(e + x.t_ns),
                                                  frame_id=x.frame_id),
                      vector=to_vec3(x.zenith_body)),
    lambda msg, e: ZenithSample(stamp_ns(msg.header.stamp) - e, msg.header.frame_id,
                                vec3(msg.vector)))
inputs.register(inputs.Input('zenith', 'zenith', 'sensors/zenith',
                             'geometry_msgs/msg/Vector3Stamped', 'zenith_sensor',
                             'zenith_period_s', 1.0, f'{__name__}:CONVERT'))


# 2. the model
class ZenithSensor:
    """``z_body = R(q_eci_body)^T r_eci / |r_eci|`` plus white noise, renormalised."""

    truth = ('state', 'env')
    values = 'zenith_body'          # what a fault changes

    def __init__(self, noise_std, seed):
        self.noise_std = float(noise_std)
        self.rng = np.random.default_rng(seed)

    def sample(self, t_ns, truth, frame_id):
        r_eci, q_eci_body = truth['env'].r_eci_m, truth['state'].q_eci_body
        z = att.to_matrix(q_eci_body).T @ (r_eci / np.linalg.norm(r_eci))
        z = z + self.noise_std * self.rng.standard_normal(3)
        return ZenithSample(t_ns, frame_id, z / np.linalg.norm(z))


# 3. the entry
register(Entry(
    'sensor', 'zenith_sensor', 'test-only Earth sensor: the zenith direction in body axes',
    'zenith_sensor:ZenithSensor',
    (Param('period_s', 'float', 1.0, 's', 'sample period', positive=True),
     Param('noise_std', 'float', 1e-3, '-', 'white noise per axis of the unit vector',
           min=0.0, max=0.1)),
    lambda p, ctx: ZenithSensor(p['noise_std'], ctx['seed']),
    node=(*SENSOR_NODE, 'sensors/zenith', 'geometry_msgs/msg/Vector3Stamped')))


# 4. the consumer
class ZenithPointer:
    """``tau = k (e_z x z_body)``, each axis clipped to the limit; zero without a sample."""

    def __init__(self, gain_Nm, max_torque_Nm):
        self.gain, self.limit = float(gain_Nm), float(max_torque_Nm)

    def reset(self):
        """No state."""

    def update(self, inputs, t, dt):
        x = inputs.samples.get('zenith')
        if x is None:
            return Command.zero(0, 'no zenith sample')
        tau = self.gain * np.cross([0.0, 0.0, 1.0], x.zenith_body)
        return Command(np.zeros(3), np.zeros(0), np.clip(tau, -self.limit, self.limit))


register(Entry(
    'controller', 'zenith_pointer', 'test-only: +z to the zenith on the zenith sensor',
    'zenith_sensor:ZenithPointer',
    (Param('gain_Nm', 'float', 0.05, 'N m', 'torque per unit of pointing error',
           positive=True),
     Param('max_torque_Nm', 'float', 1.0, 'N m', 'torque limit per axis', positive=True)),
    lambda p, ctx: ZenithPointer(p['gain_Nm'], p['max_torque_Nm']),
    inputs=('zenith',), actuators=('torque',)))
