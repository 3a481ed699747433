"""Message <-> numpy conversion at the node edge (the core never sees a message)."""
from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Quaternion, Vector3

from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.nodes.messages import checks_off


# Fast construction (issue 13): the generated ``__init__`` of a message takes keyword
# arguments through ``dict.get`` and sets every field through a property; the node glue
# builds about 30 of these small messages a frame. With field checks off (the rosidl default,
# ``ROS_PYTHON_CHECK_FIELDS`` not 1) the same object is made by filling its slots; with checks
# on the generated constructor (which checks) is used. Tested byte for byte against
# ``serialize_message`` of the generated constructor's message.
_FAST = all(checks_off(cls) for cls in (Vector3, Quaternion, Time))
_new = object.__new__

# Reading: the fields are read from their slots (``msg._x`` is what the property ``msg.x``
# returns, with or without field checks), half the time of the generated getters (about 40
# reads a frame, issue 13).


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


#: Arrays up to this many values are checked value by value (:func:`all_finite`).
_SMALL = 16


def all_finite(*arrays) -> bool:
    """True when every value of every array is finite (NaN/inf guard for incoming messages).

    The same answer as ``np.all(np.isfinite(a))`` for each: a small array (the 3-vectors and
    quaternions of messages, up to ``_SMALL`` values) is checked value by value with
    ``math.isfinite`` on its ``tolist()``, 0.16 us for a 3-vector against 1.0 us for
    ``np.isfinite(a).all()`` (13 calls a frame in paper000_control, issue 13); a larger one
    with numpy."""
    isfinite = math.isfinite
    for a in arrays:
        a = np.asarray(a)
        if a.size > _SMALL:
            if not np.isfinite(a).all():
                return False
            continue
        for x in a.ravel().tolist():
            if not isfinite(x):
                return False
    return True
