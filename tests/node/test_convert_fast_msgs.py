"""``convert.to_vec3/to_quat/to_stamp`` fill the message slots directly (issue 13): the
messages must serialize to the same bytes as the generated constructors' messages, compare
equal to them, and take field assignments afterwards."""
import numpy as np
import pytest

pytest.importorskip('rclpy')

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Quaternion, Vector3  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402

from adcs_nodes.msgs import fields as convert  # noqa: E402

VALUES = [np.array([1.0, -2.5, 3e-300]), np.array([np.nan, np.inf, -0.0]),
          [0.1, 0.2, 0.3], np.array([1e308, -1e308, 5e-324], dtype=np.float64)]


@pytest.mark.parametrize('v', VALUES)
def test_vec3_same_bytes(v):
    ref = Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))
    got = convert.to_vec3(v)
    assert type(got) is Vector3
    assert serialize_message(got) == serialize_message(ref)
    got.x = 7.0     # still a normal message: setters work
    assert got.x == 7.0 and serialize_message(got) != serialize_message(ref)


@pytest.mark.parametrize('q', [np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.5, -0.5, 0.5, -0.5]),
                               np.array([1e-17, np.nan, 2.0, -3.0]), (1, 2, 3, 4)])
def test_quat_same_bytes(q):
    ref = Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))
    got = convert.to_quat(q)
    assert type(got) is Quaternion
    assert serialize_message(got) == serialize_message(ref)
    if not np.isnan(np.asarray(q, float)).any():
        assert got == ref


@pytest.mark.parametrize('t_ns', [0, 1, 999_999_999, 1_000_000_000, 1_767_225_600_123_456_789,
                                  (2 ** 31 - 1) * 10 ** 9 + 999_999_999])
def test_stamp_same_bytes_and_round_trip(t_ns):
    ref = Time(sec=t_ns // 10 ** 9, nanosec=t_ns % 10 ** 9)
    got = convert.to_stamp(t_ns)
    assert type(got) is Time and got == ref
    assert serialize_message(got) == serialize_message(ref)
    assert convert.stamp_ns(got) == t_ns


def test_nested_in_a_message_same_bytes():
    from geometry_msgs.msg import Vector3Stamped
    ref = Vector3Stamped()
    ref.header.stamp = Time(sec=12, nanosec=34)
    ref.vector = Vector3(x=1.0, y=2.0, z=3.0)
    got = Vector3Stamped()
    got.header.stamp = convert.to_stamp(12 * 10 ** 9 + 34)
    got.vector = convert.to_vec3([1.0, 2.0, 3.0])
    assert serialize_message(got) == serialize_message(ref)


def test_reading_equals_the_fields_of_generated_and_deserialized_messages():
    """``vec3``/``quat``/``stamp_ns`` read the slots: the same values as the properties, for
    a message of the generated constructor and one from ``deserialize_message``."""
    from rclpy.serialization import deserialize_message
    v = Vector3(x=1.5, y=-np.inf, z=5e-324)
    q = Quaternion(x=0.1, y=0.2, z=np.nan, w=-0.9)
    t = Time(sec=2 ** 31 - 1, nanosec=999_999_999)
    for m in (v, deserialize_message(serialize_message(v), Vector3)):
        got = convert.vec3(m)
        assert got.dtype == np.float64 and got.shape == (3,)
        assert got.tolist() == [m.x, m.y, m.z]
    for m in (q, deserialize_message(serialize_message(q), Quaternion)):
        got = convert.quat(m)
        assert got.shape == (4,) and got[[0, 1, 3]].tolist() == [m.x, m.y, m.w]
        assert np.isnan(got[2]) and np.isnan(m.z)
    for m in (t, deserialize_message(serialize_message(t), Time)):
        assert convert.stamp_ns(m) == m.sec * 10 ** 9 + m.nanosec
        assert type(convert.stamp_ns(m)) is int
