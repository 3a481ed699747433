"""Message <-> numpy conversion at the node edge (the core never sees a message)."""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Quaternion, Vector3

from adcs_nodes.core.lockstep import NS_PER_S


def vec3(msg: Vector3) -> np.ndarray:
    """``geometry_msgs/Vector3`` -> (3,) array."""
    return np.array([msg.x, msg.y, msg.z])


def to_vec3(v) -> Vector3:
    """(3,) array -> ``geometry_msgs/Vector3``."""
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def quat(msg: Quaternion) -> np.ndarray:
    """``geometry_msgs/Quaternion`` -> (4,) array, scalar last."""
    return np.array([msg.x, msg.y, msg.z, msg.w])


def to_quat(q) -> Quaternion:
    """(4,) array, scalar last -> ``geometry_msgs/Quaternion``."""
    return Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def stamp_ns(stamp: Time) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def to_stamp(t_ns: int) -> Time:
    """Integer nanoseconds -> ``builtin_interfaces/Time``."""
    t_ns = int(t_ns)
    return Time(sec=t_ns // NS_PER_S, nanosec=t_ns % NS_PER_S)


def all_finite(*arrays) -> bool:
    """True when every value of every array is finite (NaN/inf guard for incoming messages).

    ``ndarray.all`` on the ``isfinite`` mask, in a plain loop: the same answer as
    ``np.all(np.isfinite(a))`` without ``np.all``'s dispatch and a generator (13 calls a frame
    in paper000_control, issue 13)."""
    isfinite = np.isfinite
    for a in arrays:
        if not isfinite(a).all():
            return False
    return True
