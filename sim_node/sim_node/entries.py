"""Registry entries of the simulated sensor models (see :mod:`adcs_nodes.registry`).

Each entry's parameters are both the scenario keys ``sensors.<name>.*`` and the parameters of
the sensor's node; ``build(params, ctx)`` converts them (degrees -> radians) into the model
of :mod:`sim_node.models.sensors` with the node's random seed ``ctx['seed']``. A sensor node
is ``(package, module, class, topic, message type)`` (the generic sensor node); the flight
software reads only the topic, so a real driver publishing it replaces the node.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List

from adcs_nodes.registry import Entry, Param, register, register_section
from adcs_nodes.spec import SUBSTEPS

PERIOD_HELP = 'sample period'
#: The generic sensor node (``-p sensor:=NAME``; the launcher names the node after the sensor).
SENSOR_NODE = ('sim_node', 'sim_node.nodes.sensor_node', 'SensorNode')

#: The dynamics node's own parameters (the common ones: ``adcs_nodes.spec.COMMON``); the
#: simulated world is fixed by the scenario: every one is read-only (``nodes.params``).
DYNAMICS_PARAMS = (
    SUBSTEPS,
    Param('rate_factor', 'float', 1.0, '-', 'real-time mode: sim seconds per wall second',
          positive=True, max=1e6),
    Param('lockstep_max_rate', 'float', 0.0, '-', 'lockstep: at most this many sim seconds '
          'per wall second (0: as fast as the chain goes); the series do not change',
          min=0.0, max=1e6),
    Param('command_period_s', 'float', None, 's', 'period of adcs/actuator_command, a '
          'multiple of frame_period_s (not given: none awaited)', positive=True),
    Param('wait_for_nodes', 'str[]', [], '-', 'nodes whose lockstep/ready starts frame 0'),
    Param('result_file', 'str', '', '-', "JSON file written at the end of the run (frames/s, "
          "final state; '': none)"),
    Param('start_timeout_s', 'float', 120.0, 's', 'wall-clock wait for every node ready',
          positive=True, max=86400.0),
)


def _rad(values: List[float]) -> List[float]:
    return [math.radians(v) for v in values]


def _small(misalignment_deg: List[float]) -> List[float]:
    """The model's rule: a small rotation, |delta| <= pi/2 rad."""
    if math.sqrt(sum(a * a for a in _rad(misalignment_deg))) > math.pi / 2:
        raise ValueError('a small rotation (|delta| <= 90 deg); put a large mounting rotation '
                         'in q_body_sensor_xyzw')
    return misalignment_deg


def _unit(q: List[float]) -> List[float]:
    """The model's rule: a unit quaternion (within 1e-6)."""
    if abs(math.sqrt(sum(c * c for c in q)) - 1.0) > 1e-6:
        raise ValueError(f'a mounting quaternion must have unit norm, got {q}')
    return q


def _build_magnetometer(p: Dict[str, Any], ctx: Dict[str, Any]):
    from sim_node.models.sensors import Magnetometer
    return Magnetometer(
        noise_std_T=p['noise_std_T'], bias_T=p['bias_T'],
        misalignment_rad=_rad(p['misalignment_deg']),
        scale_factor_error=p['scale_factor_error'], lsb_T=p['lsb_T'],
        saturation_T=p['saturation_T'], dropout_probability=p['dropout_probability'],
        q_body_sensor=p['q_body_sensor_xyzw'], seed=ctx['seed'])


register(Entry(
    'sensor', 'magnetometer', 'three-axis magnetometer: noise, bias, misalignment, scale '
    'factor, quantisation, saturation, dropout',
    'sim_node.models.sensors:Magnetometer',
    (Param('period_s', 'float', 10.0, 's', 'sample period (paper 000: 10 s)', positive=True),
     Param('noise_std_T', 'float[]', [375e-9, 25e-9, 65e-9], 'T', 'white noise std per '
           'sensor axis (paper 000 example)', length=3, min=0.0),
     Param('bias_T', 'float[]', [0.0, 0.0, 0.0], 'T', 'constant bias, sensor axes', length=3,
           min=-1e-3, max=1e-3),
     Param('misalignment_deg', 'float[]', [0.0, 0.0, 0.0], 'deg', 'small rotation body -> '
           'sensor (rotation vector)', length=3, min=-90.0, max=90.0, check=_small),
     Param('scale_factor_error', 'float[]', [0.0, 0.0, 0.0], '-', 'measured = (1 + s) true, '
           'per axis', length=3, min=-0.99, max=10.0),
     Param('lsb_T', 'float', 20e-9, 'T', 'quantisation step (0: none)', min=0.0, max=1e-4),
     Param('saturation_T', 'float', 0.0, 'T', 'per-axis range (0: none)', min=0.0),
     Param('dropout_probability', 'float', 0.0, '-', 'probability that a sample is lost',
           min=0.0, max=1.0),
     Param('q_body_sensor_xyzw', 'float[]', [0.0, 0.0, 0.0, 1.0], '-', 'nominal mounting, '
           'sensor -> body, scalar last', length=4, min=-1.0, max=1.0, check=_unit)),
    _build_magnetometer, inputs=(),
    node=(*SENSOR_NODE, 'sensors/magnetometer', 'sensor_msgs/msg/MagneticField')))


def _build_horizon(p: Dict[str, Any], ctx: Dict[str, Any]):
    from sim_node.models.sensors import HorizonSensor
    return HorizonSensor(noise_std_rad=_rad(p['noise_std_deg']), bias_rad=_rad(p['bias_deg']),
                         scale_factor_error=p['scale_factor_error'],
                         fov_rad=math.radians(p['fov_deg']), seed=ctx['seed'])


register(Entry(
    'sensor', 'horizon_sensor', 'Earth horizon sensor: roll and pitch of the orbit frame, '
    'noise, bias, scale factor, field of view',
    'sim_node.models.sensors:HorizonSensor',
    (Param('period_s', 'float', 1.0, 's', PERIOD_HELP, positive=True),
     Param('noise_std_deg', 'float[]', [0.1, 0.1], 'deg', 'white noise std of roll, pitch '
           '(ASSUMPTION)', length=2, min=0.0, max=90.0),
     Param('bias_deg', 'float[]', [0.0, 0.0], 'deg', 'bias of roll, pitch', length=2,
           min=-90.0, max=90.0),
     Param('scale_factor_error', 'float[]', [0.0, 0.0], '-', 'scale-factor error of roll, '
           'pitch (paper 004: 0.05 on one channel)', length=2, min=-0.99, max=10.0),
     Param('fov_deg', 'float', 30.0, 'deg', 'largest |roll|, |pitch| with a valid output',
           positive=True, max=90.0)),
    _build_horizon,
    node=(*SENSOR_NODE,
          'sensors/horizon', 'adcs_msgs/msg/HorizonSensor')))


def _build_star_tracker(p: Dict[str, Any], ctx: Dict[str, Any]):
    from sim_node.models.sensors import StarTracker
    return StarTracker(noise_std_rad=_rad(p['noise_std_deg']), seed=ctx['seed'])


register(Entry(
    'sensor', 'star_tracker', 'star tracker: inertial attitude with small-angle noise',
    'sim_node.models.sensors:StarTracker',
    (Param('period_s', 'float', 1.0, 's', PERIOD_HELP, positive=True),
     Param('noise_std_deg', 'float[]', [0.02 / 3] * 3, 'deg', 'attitude noise std per body '
           'axis (paper 001: 0.02 deg 3-sigma)', length=3, min=0.0, max=90.0)),
    _build_star_tracker,
    node=(*SENSOR_NODE,
          'sensors/star_tracker', 'sensor_msgs/msg/Imu')))


def _build_gyro(p: Dict[str, Any], ctx: Dict[str, Any]):
    from sim_node.models.sensors import Gyro
    return Gyro(noise_std_rad_s=_rad(p['noise_std_deg_s']),
                bias_initial_rad_s=[math.radians(v) / 3600.0 for v in p['bias_initial_deg_h']],
                bias_walk_std_rad_s_sqrt_s=[math.radians(v) / 3600.0 / 60.0
                                            for v in p['bias_walk_deg_h_sqrt_h']],
                seed=ctx['seed'])


register(Entry(
    'sensor', 'gyro', 'three-axis rate gyro: white noise, initial bias, bias random walk',
    'sim_node.models.sensors:Gyro',
    (Param('period_s', 'float', 1.0, 's', PERIOD_HELP, positive=True),
     Param('noise_std_deg_s', 'float[]', [1e-4] * 3, 'deg/s', 'rate white noise std '
           '(ASSUMPTION)', length=3, min=0.0, max=10.0),
     Param('bias_initial_deg_h', 'float[]', [0.0, 0.0, 0.0], 'deg/h', 'initial bias',
           length=3, min=-3600.0, max=3600.0),
     Param('bias_walk_deg_h_sqrt_h', 'float[]', [0.01 / 3] * 3, 'deg/h/sqrt(h)', 'bias '
           'random walk density (paper 001: drift 0.01 deg/h 3-sigma)', length=3, min=0.0,
           max=3600.0)),
    _build_gyro,
    node=(*SENSOR_NODE, 'sensors/gyro', 'sensor_msgs/msg/Imu')))


def _build_tachometer(p: Dict[str, Any], ctx: Dict[str, Any]):
    from sim_node.models.sensors import WheelTachometer
    return WheelTachometer(noise_std_rad_s=p['noise_std_rad_s'],
                           quantization_rad_s=p['quantization_rad_s'], seed=ctx['seed'])


register(Entry(
    'sensor', 'wheel_tachometer', 'reaction-wheel tachometer: measured wheel speeds with '
    'noise and quantisation, as sensor_msgs/JointState (what a wheel driver publishes)',
    'sim_node.models.sensors:WheelTachometer',
    (Param('period_s', 'float', 1.0, 's', PERIOD_HELP, positive=True),
     Param('noise_std_rad_s', 'float', 0.01, 'rad/s', 'white noise std of each speed '
           '(ASSUMPTION)', min=0.0, max=100.0),
     Param('quantization_rad_s', 'float', 2 * math.pi / 4096 / 0.1, 'rad/s', 'speed '
           'resolution (ASSUMPTION: 4096 counts/rev over a 0.1 s gate); 0: none', min=0.0,
           max=100.0)),
    _build_tachometer,
    node=(*SENSOR_NODE,
          'sensors/wheels', 'sensor_msgs/msg/JointState')))

# the fault kinds of the world register themselves (sim_node.faults); the spacecraft and its
# initial state are scenario sections (sim_node.models.spacecraft_config)
import sim_node.faults  # noqa: E402,F401
from sim_node.models.spacecraft_config import INITIAL, SPACECRAFT  # noqa: E402

register_section(SPACECRAFT)
register_section(INITIAL)
