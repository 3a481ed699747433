"""adcs replay: bad input gives exit code 2 with a clear message; the default selection is the
sensor topics. (A restamped message decoding with rclpy to the original with the new stamp:
``tests/node/test_replay_restamp.py``.)"""
import argparse

import pytest

from adcs_nodes.tools import replay
from replay_bag import EPOCH_NS, write_small_bag


@pytest.fixture
def small_bag(tmp_path):
    return write_small_bag(tmp_path / 'bag')


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
