"""adcs replay: a restamped message decodes (with rclpy's own deserialiser, the truth) to the
original with the new stamp. (Was in ``tests/unit/test_replay_input.py``; rclpy in process:
node tier.)"""
import pytest

from adcs_nodes.tools import replay
from replay_bag import EPOCH_NS, write_small_bag


@pytest.fixture
def small_bag(tmp_path):
    return write_small_bag(tmp_path / 'bag')


def test_restamp_equals_rclpy_serialisation(small_bag):
    serialization = pytest.importorskip('rclpy.serialization')
    from sensor_msgs.msg import MagneticField
    _, timed, _ = replay.load_samples(small_bag)
    new = EPOCH_NS + 123_456_789
    msg = serialization.deserialize_message(timed[1].data, MagneticField)
    msg.header.stamp.sec, msg.header.stamp.nanosec = new // 10**9, new % 10**9
    got = serialization.deserialize_message(replay.restamp(timed[1].data, new), MagneticField)
    assert got == msg       # (raw bytes may differ in CDR padding, which is unspecified)
    assert (got.header.stamp.sec, got.header.stamp.nanosec) == (new // 10**9, new % 10**9)
    assert len(replay.restamp(timed[1].data, new)) == len(timed[1].data)
