"""``msgs.fields.make`` fills message slots directly (issue 13): for the messages the nodes
publish every frame, random field values (NaN, inf, -0.0, subnormals, the largest doubles,
integer limits, empty and long sequences, non-ASCII strings) give a message that equals the
generated constructor's message for the same values and serializes to the same bytes
(``rclpy.serialization.serialize_message``); a missing or unknown field is a TypeError; with
rosidl's field checks on, the generated constructor (which checks) is used.

Padding: ``serialize_message`` leaves its alignment padding uninitialised (seen: ``ab`` in one
call, ``00`` in the next), so both byte strings are compared after a round trip through
rosbags' independent, zero-padding CDR serializer; their lengths must be equal as they are."""
import array
import math
import random
import sys
import zlib

import numpy as np
import pytest

pytest.importorskip('rclpy')

import rosidl_parser.definition as rdef  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Quaternion, Vector3, Vector3Stamped  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import MagneticField  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from adcs_msgs.msg import (ActuatorCommand, AttitudeState, AttitudeTarget,  # noqa: E402
                           Environment, LockstepStatus)
from adcs_nodes.msgs import fields as messages  # noqa: E402
from adcs_nodes.bag import ensure_type, make_typestore  # noqa: E402

TYPES = [Header, Clock, Environment, AttitudeState, ActuatorCommand, AttitudeTarget,
         LockstepStatus, MagneticField, Vector3Stamped, Vector3, Quaternion, Time]
SPECIAL = [math.nan, math.inf, -math.inf, -0.0, 0.0, 5e-324, 1.7976931348623157e308, -1e-300]
STRINGS = ['', 'body', 'Ünïcödé ✓ 漢字', 'x' * 300]
INT_RANGE = {'int8': (-2 ** 7, 2 ** 7 - 1), 'uint8': (0, 2 ** 8 - 1),
             'int16': (-2 ** 15, 2 ** 15 - 1), 'uint16': (0, 2 ** 16 - 1),
             'int32': (-2 ** 31, 2 ** 31 - 1), 'uint32': (0, 2 ** 32 - 1),
             'int64': (-2 ** 63, 2 ** 63 - 1), 'uint64': (0, 2 ** 64 - 1)}


STORE = make_typestore()


def zero_padded(raw, cls):
    """CDR bytes ``raw`` of a ``cls`` message with zeros in the alignment padding."""
    pkg = cls.__module__.split('.')[0]
    msgtype = f'{pkg}/msg/{cls.__name__}'
    assert ensure_type(STORE, msgtype)
    return STORE.serialize_cdr(STORE.deserialize_cdr(raw, msgtype), msgtype)


def rand_float(rng):
    return rng.choice(SPECIAL) if rng.random() < 0.3 else rng.uniform(-1e6, 1e6)


def rand_value(rng, t):
    """A random value of rosidl type ``t``, built with the generated constructors only."""
    if isinstance(t, rdef.BasicType):
        if t.typename in ('double', 'float'):
            return rand_float(rng)
        if t.typename == 'boolean':
            return rng.random() < 0.5
        lo, hi = INT_RANGE[t.typename]
        return rng.choice([lo, hi, rng.randint(lo, hi)])
    if isinstance(t, rdef.AbstractString):
        return rng.choice(STRINGS)
    if isinstance(t, rdef.NamespacedType):
        mod = sys.modules['.'.join(t.namespaces)]
        cls = getattr(mod, t.name)
        return cls(**{n: rand_value(rng, st) for n, st in
                      zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES)})
    if isinstance(t, rdef.Array):
        vals = [rand_value(rng, t.value_type) for _ in range(t.size)]
        return np.array(vals) if rng.random() < 0.5 else vals      # both are accepted
    if isinstance(t, rdef.AbstractSequence):
        vals = [rand_value(rng, t.value_type) for _ in range(rng.choice([0, 1, 4, 50]))]
        return np.array(vals, dtype=float) if vals and rng.random() < 0.3 else vals
    raise AssertionError(f'no generator for {t}')


def rand_fields(rng, cls):
    return {n: rand_value(rng, t) for n, t in
            zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES)}


def same(a, b):
    """Field-by-field equality of two messages, NaN equal to NaN."""
    if hasattr(a, 'get_fields_and_field_types'):
        return type(a) is type(b) and all(
            same(getattr(a, n), getattr(b, n)) for n in a.get_fields_and_field_types())
    if isinstance(a, (np.ndarray, array.array, list)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return type(a) is type(b) and a == b


@pytest.mark.parametrize('cls', TYPES, ids=lambda c: c.__name__)
def test_same_message_and_bytes_as_the_generated_constructor(cls):
    assert messages.checks_off(cls)      # the project's default: the fast path is tested
    rng = random.Random(zlib.crc32(cls.__name__.encode()))
    for _ in range(60):
        fields = rand_fields(rng, cls)
        ref = cls(**fields)
        got = messages.make(cls, **fields)
        assert type(got) is cls and same(got, ref)
        raw_got, raw_ref = serialize_message(got), serialize_message(ref)
        assert len(raw_got) == len(raw_ref)
        assert zero_padded(raw_got, cls) == zero_padded(raw_ref, cls)
        assert same(deserialize_message(raw_got, cls), got)


def test_array_fields_are_converted_as_the_setters_do():
    cov = [float(i) for i in range(36)]
    got = messages.make(AttitudeState, header=Header(), q_eci_body=Quaternion(),
                        q_orbit_body=Quaternion(), omega_body_eci_body=Vector3(),
                        omega_body_orbit_body=Vector3(), covariance=cov)
    assert isinstance(got.covariance, np.ndarray) and got.covariance.dtype == np.float64
    cmd = messages.make(ActuatorCommand, header=Header(), dipole_body=Vector3(),
                        wheel_torque=np.array([1.0, 2.0]), torque_body=Vector3(), source='x')
    assert isinstance(cmd.wheel_torque, array.array) and cmd.wheel_torque.typecode == 'd'
    cmd.wheel_torque = [3.0]           # still a normal message: the setters work
    assert list(cmd.wheel_torque) == [3.0]


def test_every_field_is_required():
    with pytest.raises(TypeError):
        messages.make(Header, stamp=Time())                          # frame_id missing
    with pytest.raises(TypeError):
        messages.make(Header, stamp=Time(), frame_id='', seq=1)      # no such field


def test_checks_on_uses_the_checking_constructor(monkeypatch):
    """``ROS_PYTHON_CHECK_FIELDS=1`` (read by the generated module at import): a bad value
    is refused as by the generated constructor."""
    monkeypatch.setattr(sys.modules[Header.__module__], 'ros_python_check_fields', '1')
    monkeypatch.setattr(messages, '_BUILDERS', {})
    assert not messages.checks_off(Header)
    ok = messages.make(Header, stamp=Time(sec=1, nanosec=2), frame_id='body')
    assert ok == Header(stamp=Time(sec=1, nanosec=2), frame_id='body')
    with pytest.raises(AssertionError):
        messages.make(Header, stamp=Time(), frame_id=3)
