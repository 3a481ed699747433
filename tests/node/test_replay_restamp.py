"""adcs replay: a restamped message decodes (with rclpy's own deserialiser, the truth) to the
original with the new stamp. (Was in ``tests/unit/test_replay_input.py``; rclpy in process:
node tier.)"""
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from adcs_nodes.tools import replay

EPOCH_NS = 1767225600 * 10**9


@pytest.fixture
def small_bag(tmp_path):
    store = get_typestore(Stores.ROS2_KILTED)
    out = tmp_path / 'bag'
    w = Writer(out, version=8, storage_plugin=StoragePlugin.MCAP)
    w.open()
    mag = w.add_connection('/sensors/magnetometer', 'sensor_msgs/msg/MagneticField',
                           typestore=store)
    clock = w.add_connection('/clock', 'rosgraph_msgs/msg/Clock', typestore=store)
    Time = store.types['builtin_interfaces/msg/Time']
    Header = store.types['std_msgs/msg/Header']
    Vector3 = store.types['geometry_msgs/msg/Vector3']
    MagneticField = store.types['sensor_msgs/msg/MagneticField']
    for k in (2, 0, 1):                  # written out of stamp order
        t = EPOCH_NS + k * 10 * 10**9
        m = MagneticField(header=Header(stamp=Time(sec=t // 10**9, nanosec=t % 10**9),
                                        frame_id='magnetometer'),
                          magnetic_field=Vector3(x=1e-5 * k, y=2e-5, z=-3e-5),
                          magnetic_field_covariance=np.zeros(9))
        w.write(mag, t, store.serialize_cdr(m, 'sensor_msgs/msg/MagneticField'))
        c = store.types['rosgraph_msgs/msg/Clock'](clock=Time(sec=t // 10**9, nanosec=0))
        w.write(clock, t, store.serialize_cdr(c, 'rosgraph_msgs/msg/Clock'))
    w.close()
    return str(out)


def test_restamp_equals_rclpy_serialisation(small_bag):
    serialization = pytest.importorskip('rclpy.serialization')
    from sensor_msgs.msg import MagneticField
    _, timed, _ = replay.load_samples(small_bag)
    new = EPOCH_NS + 123_456_789
    msg = serialization.deserialize_message(timed[1].data, MagneticField)
    msg.header.stamp.sec, msg.header.stamp.nanosec = new // 10**9, new % 10**9
    got = serialization.deserialize_message(replay._restamp(timed[1].data, new), MagneticField)
    assert got == msg       # (raw bytes may differ in CDR padding, which is unspecified)
    assert (got.header.stamp.sec, got.header.stamp.nanosec) == (new // 10**9, new % 10**9)
    assert len(replay._restamp(timed[1].data, new)) == len(timed[1].data)
