"""The input vocabulary: every kind of input a registered estimator or controller may declare,
as one record each (DESIGN section 6, "one engine").

An :class:`Input` names the input (the registry's word, e.g. ``'gyro'``), the key under which
a component finds its message in a frame, the topic and message type, the simulated sensor
that provides it (its scenario section under ``sensors:``), the node parameter that holds the
producer's period, whether it is awaited for the frame or taken from the previous producer
frame, and whether its samples are rotated into body axes by the sensor mount from
``/tf_static``. Everything that wires inputs iterates these records: the graph builder, the
scenario validator, the estimator and controller nodes and components, and the FrameLoop.
The converters from message to core types are the components' (they differ in what a
rejection costs: the estimator counts it, a controller reads nothing).

Pure Python: no rclpy, no message import.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Dict, Optional, Tuple


@dataclass(frozen=True)
class Input:
    """One kind of input (see the module docstring).

    Attributes
    ----------
    name : str
        The registry's name (``Entry.inputs``).
    key : str
        Key of its message in a component's frame inputs.
    topic : str
        Topic (relative: under the node's namespace).
    msg_type : str
        ``pkg/msg/Name``.
    sensor : str or None
        Registry name (and scenario section) of the simulated sensor that provides it.
    period_param : str
        Node parameter with the producer's period [s].
    default_period_s : float
        That parameter's default (a node started alone).
    kind : str
        ``'frame'`` (awaited with the frame's stamp when due) or ``'previous'`` (exactly the
        producer's message of its last frame before ``t``: the estimator's applied command).
    mounted : bool
        Its samples carry a sensor ``frame_id`` whose ``/tf_static`` mount a consumer needs.
    """

    name: str
    key: str
    topic: str
    msg_type: str
    sensor: Optional[str]
    period_param: str
    default_period_s: float
    kind: str = 'frame'
    mounted: bool = False

    def message_class(self) -> type:
        """The generated message class of :attr:`msg_type` (imports no rclpy)."""
        pkg, _, name = self.msg_type.split('/')
        return getattr(importlib.import_module(f'{pkg}.msg'), name)


INPUTS: Tuple[Input, ...] = (
    Input('estimate', 'est', 'adcs/attitude_estimate', 'adcs_msgs/msg/AttitudeState', None,
          'estimator_period_s', 2.0),
    Input('target', 'target', 'adcs/attitude_target', 'adcs_msgs/msg/AttitudeTarget', None,
          'target_period_s', 2.0),
    Input('magnetometer', 'mag', 'sensors/magnetometer', 'sensor_msgs/msg/MagneticField',
          'magnetometer', 'magnetometer_period_s', 10.0, mounted=True),
    Input('wheel_speeds', 'wheels', 'sensors/wheels', 'sensor_msgs/msg/JointState',
          'wheel_tachometer', 'tachometer_period_s', 1.0),
    Input('horizon', 'horizon', 'sensors/horizon', 'adcs_msgs/msg/HorizonSensor',
          'horizon_sensor', 'horizon_period_s', 1.0, mounted=True),
    Input('star_tracker', 'star', 'sensors/star_tracker', 'sensor_msgs/msg/Imu',
          'star_tracker', 'star_tracker_period_s', 1.0, mounted=True),
    Input('gyro', 'gyro', 'sensors/gyro', 'sensor_msgs/msg/Imu', 'gyro', 'gyro_period_s', 1.0,
          mounted=True),
    Input('actuator_command', 'cmd', 'adcs/actuator_command', 'adcs_msgs/msg/ActuatorCommand',
          None, 'command_period_s', 0.0, kind='previous'),
)

#: The records by registry name.
BY_NAME: Dict[str, Input] = {i.name: i for i in INPUTS}
#: Registry names, in order.
NAMES: Tuple[str, ...] = tuple(BY_NAME)


def get(name: str) -> Input:
    """The record of input ``name`` (``ValueError`` naming the known ones)."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise ValueError(f'unknown input {name!r}; known: {", ".join(NAMES)}') from None


def period_params(names) -> Tuple:
    """Registry ``Param`` specs of the producer periods of inputs ``names`` (for a node's
    declared parameters: one name per input, the same in every consumer)."""
    from adcs_nodes.spec import Param
    out = []
    for name in names:
        rec = get(name)
        if rec.kind == 'previous':
            out.append(Param(rec.period_param, 'float', rec.default_period_s, 's',
                             f'period of {rec.topic} (0: the latest command)', min=0.0,
                             read_only=True))
        else:
            out.append(Param(rec.period_param, 'float', rec.default_period_s, 's',
                             f'period of {rec.topic}', positive=True, read_only=True))
    return tuple(out)


def lockstep_inputs(names, periods: Dict[str, float]) -> Dict[str, tuple]:
    """A consumer's inputs ``{key: (message class, topic, period_s, kind)}`` for
    ``LockstepNode.lockstep_inputs``, from the declared input ``names`` and the values of
    their period parameters ``periods`` (:func:`period_params`)."""
    out = {}
    for name in names:
        rec = get(name)
        out[rec.key] = (rec.message_class(), rec.topic, periods[rec.period_param], rec.kind)
    return out
