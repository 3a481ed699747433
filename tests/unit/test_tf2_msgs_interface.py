"""The tf2_msgs the project publishes /tf with (installed, or the fallback built by
ros2_ws/bootstrap.sh from ros2_ws/extra/tf2_msgs) has the upstream type: its RIHS01 type hash
equals the one rosbags computes independently from its own copy of the ROS 2 definitions, so
RViz, Foxglove and ``ros2 bag`` accept our /tf and /tf_static."""
import json
import os

import pytest

ament = pytest.importorskip('ament_index_python.packages')
from rosbags.typesys import Stores, get_typestore  # noqa: E402

FALLBACK = os.path.join(os.path.dirname(__file__), '..', '..', 'ros2_ws', 'extra', 'tf2_msgs')


def test_tfmessage_type_hash_is_upstreams():
    try:
        share = ament.get_package_share_directory('tf2_msgs')
    except ament.PackageNotFoundError:
        pytest.fail('tf2_msgs is neither installed nor built (run ros2_ws/bootstrap.sh)')
    with open(os.path.join(share, 'msg', 'TFMessage.json'), encoding='utf-8') as fh:
        hashes = {h['type_name']: h['hash_string'] for h in json.load(fh)['type_hashes']}
    upstream = {get_typestore(s).hash_rihs01('tf2_msgs/msg/TFMessage')
                for s in (Stores.ROS2_JAZZY, Stores.ROS2_KILTED)}
    assert upstream == {hashes['tf2_msgs/msg/TFMessage']}


def test_fallback_is_ignored_by_a_plain_colcon_build():
    """On a ROS 2 install `colcon build` in ros2_ws must never overlay the real tf2_msgs."""
    extra = os.path.dirname(os.path.abspath(FALLBACK))
    assert os.path.isfile(os.path.join(extra, 'COLCON_IGNORE'))
    assert not os.path.exists(os.path.join(FALLBACK, 'COLCON_IGNORE'))  # bootstrap builds it
    with open(os.path.join(FALLBACK, 'msg', 'TFMessage.msg'), encoding='utf-8') as fh:
        assert fh.read().split() == ['geometry_msgs/TransformStamped[]', 'transforms']
