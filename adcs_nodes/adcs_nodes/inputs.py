"""The input vocabulary: one record per kind of input (DESIGN section 6), iterated by all
that wires inputs; a plugin adds one with :func:`register`. No rclpy, no message import."""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Dict, Optional, Tuple


@dataclass(frozen=True)
class Input:
    """One kind of input: ``key`` of its sample in a frame, the simulated ``sensor`` providing
    it (None: a flight node), the producer's period parameter [s], ``convert``
    (``'module:NAME'``), ``kind`` ``'frame'`` (awaited) or ``'previous'`` (the producer's last
    frame before ``t``), ``mounted`` (rotated by its ``/tf_static`` mount)."""

    name: str
    key: str
    topic: str
    msg_type: str
    sensor: Optional[str]
    period_param: str
    default_period_s: float
    convert: str
    kind: str = 'frame'
    mounted: bool = False

    def message_class(self) -> type:
        """The generated message class of :attr:`msg_type` (imports no rclpy)."""
        pkg, _, name = self.msg_type.split('/')
        return getattr(importlib.import_module(f'{pkg}.msg'), name)

    def converter(self) -> Any:
        """Its converter (``to_msg(sample, epoch_ns)``, ``to_core(msg, epoch_ns)``)."""
        return _resolve(self.convert)


def _resolve(ref: str) -> Any:
    got = _RESOLVED.get(ref)
    if got is None:
        module, _, name = ref.partition(':')
        try:
            got = _RESOLVED[ref] = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError, ValueError) as exc:
            raise ValueError(f'converter {ref!r} cannot be loaded: {exc}') from None
    return got


_RESOLVED: Dict[str, Any] = {}
_CONVERT = 'adcs_nodes.msgs.convert:'


INPUTS: Tuple[Input, ...] = (
    Input('estimate', 'est', 'adcs/attitude_estimate', 'adcs_msgs/msg/AttitudeState', None,
          'estimator_period_s', 2.0, _CONVERT + 'ATTITUDE_STATE'),
    Input('target', 'target', 'adcs/attitude_target', 'adcs_msgs/msg/AttitudeTarget', None,
          'target_period_s', 2.0, _CONVERT + 'TARGET'),
    Input('magnetometer', 'mag', 'sensors/magnetometer', 'sensor_msgs/msg/MagneticField',
          'magnetometer', 'magnetometer_period_s', 10.0, _CONVERT + 'MAGNETOMETER',
          mounted=True),
    Input('wheel_speeds', 'wheels', 'sensors/wheels', 'sensor_msgs/msg/JointState',
          'wheel_tachometer', 'tachometer_period_s', 1.0, _CONVERT + 'WHEEL_SPEEDS'),
    Input('horizon', 'horizon', 'sensors/horizon', 'adcs_msgs/msg/HorizonSensor',
          'horizon_sensor', 'horizon_period_s', 1.0, _CONVERT + 'HORIZON', mounted=True),
    Input('star_tracker', 'star', 'sensors/star_tracker', 'sensor_msgs/msg/Imu',
          'star_tracker', 'star_tracker_period_s', 1.0, _CONVERT + 'STAR_TRACKER',
          mounted=True),
    Input('gyro', 'gyro', 'sensors/gyro', 'sensor_msgs/msg/Imu', 'gyro', 'gyro_period_s', 1.0,
          _CONVERT + 'GYRO', mounted=True),
    Input('actuator_command', 'cmd', 'adcs/actuator_command', 'adcs_msgs/msg/ActuatorCommand',
          None, 'command_period_s', 0.0, _CONVERT + 'COMMAND', kind='previous'),
)

#: The records by registry name (built-ins, then the plugins' :func:`register`).
BY_NAME: Dict[str, Input] = {i.name: i for i in INPUTS}
#: Built-in registry names, in order.
NAMES: Tuple[str, ...] = tuple(BY_NAME)


def register(record: Input) -> Input:
    """Add a plugin's input kind (the same name twice: an error unless identical)."""
    have = BY_NAME.get(record.name)
    if have is not None and have != record:
        raise ValueError(f'input {record.name!r} is registered twice')
    clash = [i.name for i in BY_NAME.values() if i.name != record.name
             and (i.key == record.key or i.topic == record.topic)]
    if clash:
        raise ValueError(f'input {record.name!r}: key or topic of {clash[0]!r}')
    BY_NAME[record.name] = record
    return record


def converter(topic: str) -> Any:
    """The converter of ``topic``: its input record's, else the message layer's; KeyError."""
    name = topic.lstrip('/') if topic != '/clock' else topic
    for rec in BY_NAME.values():
        if rec.topic == name:
            return rec.converter()
    got = _resolve(_CONVERT + 'for_topic')(name)
    if got is None:
        raise KeyError(topic)
    return got


def get(name: str) -> Input:
    """The record of input ``name`` (``ValueError`` naming the known ones)."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise ValueError(f'unknown input {name!r}; known: {", ".join(BY_NAME)}') from None


def period_params(names) -> Tuple:
    """Registry ``Param`` specs of the producer periods of inputs ``names``."""
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
    """``{key: (message class, topic, period_s, kind)}`` of inputs ``names``."""
    out = {}
    for name in names:
        rec = get(name)
        out[rec.key] = (rec.message_class(), rec.topic, periods[rec.period_param], rec.kind)
    return out
