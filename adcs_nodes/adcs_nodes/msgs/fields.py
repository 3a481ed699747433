"""Message fields <-> numpy, and messages built by filling their slots.

The generated ``__init__`` of a message builds a default for every field and sets each one
through a property; :func:`make` (and :func:`to_vec3`, :func:`to_quat`, :func:`to_stamp`)
create the same object directly when rosidl's field checks are off (the default,
``ROS_PYTHON_CHECK_FIELDS`` not 1): each given field goes to its slot with the conversion
the generated setter applies when checks are off (fixed numeric arrays: ``numpy.array`` of
the field's dtype; numeric sequences: ``array.array`` of its typecode; anything else as
given). With checks on, the generated constructor is called. Every field must be given.
Reading goes through the slots (``msg._x``), what the properties return. Tested byte for
byte against ``serialize_message`` (``tests/node/test_messages_fast.py``).
"""
from __future__ import annotations

import array
import sys
from typing import Any, Callable, Dict

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Quaternion, Vector3

NS_PER_S = 1_000_000_000


def checks_off(cls: type) -> bool:
    """True when rosidl's field checks are off for message class ``cls``."""
    return getattr(sys.modules[cls.__module__], 'ros_python_check_fields', '1') != '1'


_FAST = all(checks_off(cls) for cls in (Vector3, Quaternion, Time))
_new = object.__new__


def vec3(msg: Vector3) -> np.ndarray:
    """``geometry_msgs/Vector3`` -> (3,) array."""
    return np.array((msg._x, msg._y, msg._z))


def to_vec3(v) -> Vector3:
    """(3,) array -> ``geometry_msgs/Vector3``."""
    if _FAST:
        m = _new(Vector3)
        m._check_fields = False
        m._x, m._y, m._z = float(v[0]), float(v[1]), float(v[2])
        return m
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def quat(msg: Quaternion) -> np.ndarray:
    """``geometry_msgs/Quaternion`` -> (4,) array, scalar last."""
    return np.array((msg._x, msg._y, msg._z, msg._w))


def to_quat(q) -> Quaternion:
    """(4,) array, scalar last -> ``geometry_msgs/Quaternion``."""
    if _FAST:
        m = _new(Quaternion)
        m._check_fields = False
        m._x, m._y, m._z, m._w = float(q[0]), float(q[1]), float(q[2]), float(q[3])
        return m
    return Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def stamp_ns(stamp: Time) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds."""
    return int(stamp._sec) * NS_PER_S + int(stamp._nanosec)


def to_stamp(t_ns: int) -> Time:
    """Integer nanoseconds -> ``builtin_interfaces/Time``."""
    t_ns = int(t_ns)
    if _FAST and 0 <= t_ns < 2 ** 31 * NS_PER_S:    # in int32 seconds (else: the checks)
        m = _new(Time)
        m._check_fields = False
        m._sec, m._nanosec = t_ns // NS_PER_S, t_ns % NS_PER_S
        return m
    return Time(sec=t_ns // NS_PER_S, nanosec=t_ns % NS_PER_S)


_BUILDERS: Dict[type, Callable[..., Any]] = {}


def make(cls: type, **fields: Any) -> Any:
    """A message of type ``cls`` with ``fields`` (every field of the type, by name), equal
    to ``cls(**fields)`` and serialized to the same bytes. Sub-messages are shared, not
    copied."""
    build = _BUILDERS.get(cls)
    if build is None:
        build = _BUILDERS[cls] = _builder(cls)
    return build(**fields)


def _builder(cls: type) -> Callable[..., Any]:
    """A function of the fields of ``cls`` (all keyword-only, all required) returning the
    message: slot filling when checks are off, the generated constructor when on."""
    names = list(cls.get_fields_and_field_types())
    args = ', '.join(names)
    if not checks_off(cls):
        body = [f'    return cls({", ".join(f"{n}={n}" for n in names)})']
    else:
        default = cls()
        body = ['    m = new(cls)', '    m._check_fields = False']
        for n in names:
            value = getattr(default, '_' + n)
            if isinstance(value, np.ndarray):
                body.append(f'    m._{n} = np_array({n}, dtype=np.{value.dtype.name})')
            elif isinstance(value, array.array):
                body.append(f'    m._{n} = py_array({value.typecode!r}, {n})')
            else:
                body.append(f'    m._{n} = {n}')
        body.append('    return m')
    source = f'def build(*, {args}):\n' + '\n'.join(body) + '\n'
    scope = {'cls': cls, 'new': object.__new__, 'np': np, 'np_array': np.array,
             'py_array': array.array}
    exec(compile(source, f'<adcs messages.make {cls.__name__}>', 'exec'), scope)  # noqa: S102
    return scope['build']
