"""``nodes/cdr.py`` (issue 13, raw CDR in graph mode): for every message type of adcs_msgs and
the std types used on the lockstep topics, random values (NaN, inf, -0.0, subnormals, integer
limits, empty and long sequences, non-ASCII and long strings) encode to the bytes of
``rclpy.serialization.serialize_message``, and decoding ``serialize_message``'s bytes gives a
message of the class equal to ``deserialize_message``'s (field by field, NaN equal to NaN,
same Python types), which serializes back to the same bytes.

Padding and length: ``serialize_message`` (Fast CDR) does not clear its alignment padding
(those bytes are whatever was in its buffer, seen: ``5a 55 db`` after a ``frame_id``; a typed
DDS publish does the same, ``tests/node/test_raw_cdr.py``), and its length is an estimate that
counts the alignment of the elements of an empty sequence and rounds up, while the bytes
written (and those a typed publish sends) do not align an empty sequence's elements: after an
empty ``float64[]`` its length can be 4-16 bytes more than the content, which rosbags then
refuses (size mismatch). The codec writes zeros in the padding and the exact length. So the
check is: the codec's bytes are a prefix of ``serialize_message``'s where every differing byte
is a zero of ours, and an independent CDR implementation (rosbags, which zero-pads and checks
the size) reads them back and writes exactly the same bytes."""
import array
import importlib
import math
import random
import struct
import sys

import numpy as np
import pytest

pytest.importorskip('rclpy')

import rosidl_parser.definition as rdef  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from adcs_nodes.nodes import cdr  # noqa: E402
from adcs_nodes.bag import ensure_type, make_typestore  # noqa: E402

ADCS_MSGS = ['ActuatorCommand', 'AppendageState', 'AttitudeState', 'AttitudeTarget',
             'ControllerStatus', 'Environment', 'FilterDiagnostics', 'HorizonSensor',
             'LockstepStatus', 'WheelState']
#: std types of the lockstep topics and a few with other field kinds (nested sequences of
#: messages, fixed uint8 arrays, int8/uint8/int16 fields).
STD = ['rosgraph_msgs.msg:Clock', 'std_msgs.msg:String', 'std_msgs.msg:Header',
       'builtin_interfaces.msg:Time', 'geometry_msgs.msg:Vector3',
       'geometry_msgs.msg:Quaternion', 'geometry_msgs.msg:Vector3Stamped',
       'sensor_msgs.msg:MagneticField', 'diagnostic_msgs.msg:DiagnosticArray',
       'tf2_msgs.msg:TFMessage', 'rcl_interfaces.msg:Log', 'std_msgs.msg:Int8MultiArray',
       'std_msgs.msg:Float32MultiArray', 'std_msgs.msg:UInt64', 'std_msgs.msg:Int16',
       'unique_identifier_msgs.msg:UUID', 'std_msgs.msg:Bool', 'std_msgs.msg:Byte']
TYPES = ([getattr(importlib.import_module('adcs_msgs.msg'), n) for n in ADCS_MSGS]
         + [getattr(importlib.import_module(s.split(':')[0]), s.split(':')[1]) for s in STD])
_SLEW = importlib.import_module('adcs_msgs.action').Slew
#: the Slew action's messages (goal, result, feedback, the feedback topic's message with its
#: uint8[16] goal id, the send-goal request)
TYPES += [_SLEW.Goal, _SLEW.Result, _SLEW.Feedback, _SLEW.Impl.FeedbackMessage,
          _SLEW.Impl.SendGoalService.Request]

INT_RANGE = {'int8': (-2 ** 7, 2 ** 7 - 1), 'uint8': (0, 2 ** 8 - 1),
             'int16': (-2 ** 15, 2 ** 15 - 1), 'uint16': (0, 2 ** 16 - 1),
             'int32': (-2 ** 31, 2 ** 31 - 1), 'uint32': (0, 2 ** 32 - 1),
             'int64': (-2 ** 63, 2 ** 63 - 1), 'uint64': (0, 2 ** 64 - 1)}
SPECIAL = [math.nan, math.inf, -math.inf, -0.0, 0.0, 5e-324, 1.7976931348623157e308, -1e-300]
STRINGS = ['', 'a', 'body', 'Ünïcödé ✓ 漢字 🚀', 'x' * 257, 'tab\tnew\nline']


def rand_basic(rng, name):
    if name in ('double', 'float'):
        x = (rng.choice(SPECIAL) if rng.random() < 0.4
             else rng.gauss(0.0, 10.0 ** rng.randint(-9, 9)))
        if name == 'float':
            x = float(np.float32(x)) if math.isfinite(x) and abs(x) < 3e38 else \
                (x if not math.isfinite(x) else 1.5)
        return x
    if name == 'boolean':
        return rng.random() < 0.5
    if name == 'octet':
        return bytes([rng.randint(0, 255)])
    lo, hi = INT_RANGE[name]
    return rng.choice([lo, hi, 0, rng.randint(lo, hi)])


def rand_value(rng, t):
    if isinstance(t, rdef.BasicType):
        return rand_basic(rng, t.typename)
    if isinstance(t, rdef.AbstractString):
        s = rng.choice(STRINGS + [''.join(chr(rng.randint(32, 0x2FFF)) for _ in range(9))])
        return s[:t.maximum_size] if isinstance(t, rdef.BoundedString) else s
    if isinstance(t, rdef.NamespacedType):
        ns = '.'.join(t.namespaces)
        importlib.import_module(ns)
        cls = next(getattr(m, t.name) for n, m in sorted(sys.modules.items())
                   if (n == ns or n.startswith(ns + '.')) and hasattr(m, t.name))
        return rand_msg(rng, cls)
    if isinstance(t, (rdef.Array, rdef.AbstractSequence)):
        if isinstance(t, rdef.Array):
            n = t.size
        else:
            n = rng.choice([0, 0, 1, 2, 3, 17, 1000 if isinstance(t.value_type, rdef.BasicType)
                            else 5])
            if isinstance(t, rdef.BoundedSequence):
                n = min(n, t.maximum_size)
        return [rand_value(rng, t.value_type) for _ in range(n)]
    raise AssertionError(f'no generator for {t!r}')


def rand_msg(rng, cls):
    kwargs = {}
    for name, t in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES):
        kwargs[name] = rand_value(rng, t)
    return cls(**kwargs)


def same(a, b, path='msg'):
    """Field-by-field equality with NaN == NaN and -0.0 != 0.0, and the same Python types."""
    assert type(a) is type(b), f'{path}: {type(a)} vs {type(b)}'
    if hasattr(type(a), 'SLOT_TYPES'):
        for name in type(a).get_fields_and_field_types():
            same(getattr(a, name), getattr(b, name), f'{path}.{name}')
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, path
        assert a.tobytes() == b.tobytes(), path
        assert a.flags.writeable == b.flags.writeable, path
    elif isinstance(a, array.array):
        assert a.typecode == b.typecode and a.tobytes() == b.tobytes(), path
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f'{path}[{i}]')
    elif isinstance(a, float):
        assert struct.pack('<d', a) == struct.pack('<d', b) or (math.isnan(a) and math.isnan(b)), \
            f'{path}: {a!r} vs {b!r}'
    else:
        assert a == b, f'{path}: {a!r} vs {b!r}'


STORE = make_typestore()


def rosbags_type(cls):
    """``pkg/msg/Name`` of ``cls`` when rosbags knows it (action messages: None)."""
    pkg, kind = cls.__module__.split('.')[:2]
    name = f'{pkg}/{kind}/{cls.__name__}'
    return name if kind == 'msg' and ensure_type(STORE, name) else None


def same_but_padding(got, ref, prefix=False):
    """Same length (``prefix``: ``got`` no longer than ``ref``), and every byte that differs
    is a zero of ``got`` (padding)."""
    if len(got) != len(ref) and not (prefix and len(got) <= len(ref)):
        return False
    return all(a == b or a == 0 for a, b in zip(got, ref))


@pytest.mark.parametrize('cls', TYPES, ids=lambda c: f'{c.__module__.split(".")[0]}/{c.__name__}')
def test_random_messages_same_bytes_both_ways(cls):
    c = cdr.codec(cls)
    msgtype = rosbags_type(cls)
    assert c.generated, f'{cls.__name__}: fell back to rclpy ({getattr(c, "why", "")})'
    rng = random.Random(hash(cls.__name__) & 0xFFFF)
    for k in range(60):
        msg = cls() if k == 0 else rand_msg(rng, cls)     # k = 0: all defaults (empty)
        ref = serialize_message(msg)
        got = c.encode(msg)
        assert type(got) is bytes
        assert same_but_padding(got, ref, prefix=True), \
            f'{cls.__name__} #{k}:\n{got.hex()}\n{ref.hex()}'
        if msgtype is not None:     # rosbags: an independent, zero-padding serializer
            assert got == STORE.serialize_cdr(STORE.deserialize_cdr(got, msgtype), msgtype)
        dec = c.decode(ref)
        same(dec, deserialize_message(ref, cls))
        same(c.decode(got), dec)
        assert c.encode(dec) == got


def test_decoded_message_takes_assignments():
    """A decoded message is a normal message: its fields can be set and it compares equal."""
    from adcs_msgs.msg import Environment
    from geometry_msgs.msg import Vector3
    c = cdr.codec(Environment)
    m = Environment()
    m.header.frame_id = 'eci'
    m.r_eci = Vector3(x=7e6, y=-1.0, z=2.0)
    dec = c.decode(serialize_message(m))
    assert dec == m and dec.r_eci.x == 7e6 and dec.header.frame_id == 'eci'
    dec.r_eci.x = 1.0
    dec.orbit_rate = 0.001
    assert serialize_message(dec) != serialize_message(m)
    assert deserialize_message(c.encode(dec), Environment).orbit_rate == 0.001


def test_bytes_are_independent_of_alignment_truth():
    """Independent truth for the layout: ActuatorCommand with frame_id 'ab', an empty
    wheel_torque and source 'x', written out by hand from the XCDR1 rules."""
    from adcs_msgs.msg import ActuatorCommand
    m = ActuatorCommand(source='x')
    m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id = 5, 7, 'ab'
    m.dipole_body.x, m.torque_body.z = 1.5, -2.0
    body = struct.pack('<iiI3s', 5, 7, 3, b'ab\0')          # 15 bytes
    body += b'\0'                                            # align 8 -> 16
    body += struct.pack('<3d', 1.5, 0.0, 0.0)                # 40
    body += struct.pack('<I', 0)                             # 44: count 0
    body += b'\0' * 4                                        # 48: align of torque_body
    body += struct.pack('<3d', 0.0, 0.0, -2.0)               # 72
    body += struct.pack('<I2s', 2, b'x\0')                   # 78
    assert cdr.codec(ActuatorCommand).encode(m) == b'\x00\x01\x00\x00' + body


def test_empty_sequence_elements_not_aligned():
    """Independent truth: AppendageState bytes a typed DDS publish sent (probe of 2026-11-26,
    rmw_fastrtps_cpp): with eta empty the count of eta_dot follows at once (offset 20), its
    one double then at 24 (aligned); frequency_hz's count at 32."""
    from adcs_msgs.msg import AppendageState
    m = AppendageState(eta=[], eta_dot=[1.0], frequency_hz=[])
    body = struct.pack('<iiI1s3x', 0, 0, 1, b'\0')           # 16
    body += struct.pack('<III', 0, 1, 0)[:8]                 # 24: counts 0 and 1
    body += struct.pack('<dI', 1.0, 0)                       # 36
    assert cdr.codec(AppendageState).encode(m) == b'\x00\x01\x00\x00' + body
    m = AppendageState()
    body = struct.pack('<iiI1s3xIII', 0, 0, 1, b'\0', 0, 0, 0)  # 28: three counts
    assert cdr.codec(AppendageState).encode(m) == b'\x00\x01\x00\x00' + body


def test_nul_in_string_is_cut_like_rclpy():
    from std_msgs.msg import String
    m = String(data='ab\0cd')
    assert cdr.codec(String).encode(m) == serialize_message(m)


def test_uncovered_types_fall_back_to_rclpy():
    """wstring fields and bool arrays are not generated: the codec is rclpy's."""
    class WideText:
        __slots__ = ['_text', '_check_fields']
        SLOT_TYPES = (rdef.UnboundedWString(),)

    class Flags:
        __slots__ = ['_flags', '_check_fields']
        SLOT_TYPES = (rdef.Array(rdef.BasicType('boolean'), 3),)

    for cls, why in ((WideText, 'wstring'), (Flags, 'boolean')):
        c = cdr.codec(cls)
        assert not c.generated and why in c.why
        assert c.encode is serialize_message


def test_bad_values_are_refused():
    from adcs_msgs.msg import AttitudeState, LockstepStatus
    m = LockstepStatus()
    m._frames = -1        # out of uint64, bypassing the checks
    with pytest.raises(struct.error):
        cdr.codec(LockstepStatus).encode(m)
    s = AttitudeState()
    s._covariance = np.zeros(35)
    with pytest.raises(ValueError):
        cdr.codec(AttitudeState).encode(s)


def test_big_endian_payload_goes_to_rclpy():
    from std_msgs.msg import String
    be = b'\x00\x00\x00\x00' + struct.pack('>I', 3) + b'hi\0'
    assert cdr.codec(String).decode(be).data == 'hi'
