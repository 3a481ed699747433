"""adcs replay: bad input gives exit code 2 with a clear message; the default selection is the
sensor topics. (A restamped message decoding with rclpy to the original with the new stamp:
``tests/node/test_replay_restamp.py``.)"""
import argparse

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


def _args(default_bag, **kw):
    base = dict(bag=default_bag, topics=None, rate=1.0, time_offset=0.0, now=False, no_clock=False,
                wait=0.0, start=0.0, duration=None)
    return argparse.Namespace(**{**base, **kw})


def test_default_selection_and_stamp_order(small_bag):
    types, timed, static = replay.load_samples(small_bag)
    assert types == {'/sensors/magnetometer': 'sensor_msgs/msg/MagneticField'}
    assert [s.stamp_ns - EPOCH_NS for s in timed] == [0, 10 * 10**9, 20 * 10**9]
    assert static == []


@pytest.mark.parametrize('kw, text', [
    ({'bag': '/nonexistent/bag'}, 'not found'),
    ({'topics': ['/sensors/gyro']}, 'no topic /sensors/gyro'),
    ({'topics': ['/clock']}, 'no header.stamp'),
    ({'rate': 0.0}, '--rate'),
    ({'rate': float('nan')}, '--rate'),
    ({'now': True, 'rate': 2.0}, '--rate 1'),
    ({'duration': -1.0}, '--duration'),
])
def test_bad_input_exit_2(small_bag, capsys, kw, text):
    args = _args(small_bag, **kw)
    assert replay.run_from_args(args) == 2
    err = capsys.readouterr().err
    assert err.startswith('adcs replay: ') and text in err and 'Traceback' not in err
