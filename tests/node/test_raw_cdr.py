"""Raw CDR endpoints of lockstep nodes (issue 13, graph mode; ``nodes/cdr.py``).

* What a typed DDS publish sends (the bytes a raw subscriber, e.g. the recorder, receives) is
  what the codec writes, for random messages of every lockstep type: same length, same bytes
  except the alignment padding, which Fast CDR leaves uncleared and the codec zeroes.
* ``LockstepNode.publisher()``/``subscription()`` publish bytes and take bytes; the node's
  callback gets a message equal to the published one, a typed subscriber of another node gets
  the same message, a callback taking the message info (``publisher_guard``) gets the
  publisher's GID, with both executors' calling conventions.
* ``ADCS_RAW_CDR=0``: typed endpoints. An inactive lifecycle publisher sends nothing.
"""
import math
import os
import random
import sys

import pytest
from rclpy.lifecycle import LifecyclePublisher
from rclpy.node import Node
from rclpy.parameter import Parameter

from adcs_msgs.msg import (ActuatorCommand, AttitudeState, AttitudeTarget, ControllerStatus,
                           Environment, FilterDiagnostics, LockstepStatus, WheelState)
from adcs_nodes.nodes import cdr
from adcs_nodes.nodes.lockstep_node import QOS_DATA, LockstepNode
from adcs_nodes.nodes.publisher_guard import WithInfo
from adcs_nodes.nodes.runtime import make_executor
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import MagneticField

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..', 'unit'))
from test_cdr import rand_msg, same, same_but_padding  # noqa: E402

LOCKSTEP_TYPES = [Clock, Environment, AttitudeState, ActuatorCommand, AttitudeTarget,
                  MagneticField, LockstepStatus, ControllerStatus, FilterDiagnostics, WheelState]
PARAMS = [Parameter('epoch', value='2026-01-01T00:00:00Z'),
          Parameter('timing_mode', value='lockstep')]


def _matched(pub, sub):
    return lambda: pub.get_subscription_count() >= 1 and sub.get_publisher_count() >= 1


def test_typed_dds_publish_sends_the_codec_bytes(ros_context, spin):
    node = Node('probe', context=ros_context)
    rng = random.Random(13)
    for cls in LOCKSTEP_TYPES:
        got = []
        topic = f'raw_{cls.__name__}'
        pub = node.create_publisher(cls, topic, QOS_DATA)
        sub = node.create_subscription(cls, topic, got.append, QOS_DATA, raw=True)
        assert spin([node], _matched(pub, sub))
        msgs = [cls()] + [rand_msg(rng, cls) for _ in range(25)]
        for m in msgs:
            pub.publish(m)
        assert spin([node], lambda: len(got) >= len(msgs)), cls.__name__
        c = cdr.codec(cls)
        assert c.generated
        for m, data in zip(msgs, got):
            mine = c.encode(m)
            assert same_but_padding(mine, data), f'{cls.__name__}\n{mine.hex()}\n{data.hex()}'
            same(c.decode(data), c.decode(mine))


class Talker(LockstepNode):
    def __init__(self, **kw):
        super().__init__('talker', **kw)
        self.pub = self.publisher(Environment, 'sim/environment')


class Listener(LockstepNode):
    def __init__(self, with_info, **kw):
        super().__init__('listener', **kw)
        self.got, self.infos = [], []
        if with_info:
            def cb(msg, info):
                self.got.append(msg)
                self.infos.append(info)
            callback = WithInfo(cb)
        else:
            callback = self.got.append
        self.sub = self.subscription(Environment, 'sim/environment', callback)


def _env(k):
    m = Environment()
    m.header.stamp.sec, m.header.frame_id = 1000 + k, 'eci'
    m.r_eci.x, m.v_eci.y, m.orbit_rate = 7.0e6 + k, -0.0, math.nan if k == 1 else 1e-3
    m.q_eci_orbit.w = 1.0
    return m


def _spin_with(executor_kind, ros_context, spin, nodes, until, timeout=30.0):
    executor = make_executor(ros_context) if executor_kind == 'events' else None
    return spin(nodes, until, timeout, executor=executor)


@pytest.mark.parametrize('executor_kind', ['single', 'events'])
@pytest.mark.parametrize('with_info', [False, True])
def test_lockstep_endpoints_are_raw_and_transparent(ros_context, spin, monkeypatch,
                                                    executor_kind, with_info):
    monkeypatch.delenv(cdr.ENV, raising=False)
    talker = Talker(context=ros_context, parameter_overrides=PARAMS)
    listener = Listener(with_info, context=ros_context, parameter_overrides=PARAMS)
    typed = Node('typed', context=ros_context)
    typed_got = []
    tsub = typed.create_subscription(Environment, 'sim/environment', typed_got.append, QOS_DATA)
    assert listener.sub.raw and talker.pub.raw_codec is cdr.codec(Environment)
    nodes = [talker, listener, typed]
    assert _spin_with(executor_kind, ros_context, spin, nodes,
                      lambda: talker.pub.get_subscription_count() >= 2
                      and listener.sub.get_publisher_count() >= 1
                      and tsub.get_publisher_count() >= 1)
    sent = [_env(k) for k in range(3)]
    for m in sent:
        talker.pub.publish(m)
    assert _spin_with(executor_kind, ros_context, spin, nodes,
                      lambda: len(listener.got) >= 3 and len(typed_got) >= 3)
    for m, a, b in zip(sent, listener.got, typed_got):
        assert type(a) is Environment
        same(a, m)
        same(b, m)
    if with_info:      # the publisher guard's input: the talker's endpoint GID
        gids = {bytes(i.endpoint_gid) for i in
                listener.get_publishers_info_by_topic('/sim/environment')
                if i.node_name == 'talker'}
        assert len(listener.infos) == 3
        for info in listener.infos:
            assert bytes((info.get('publisher_gid') or {}).get('data') or b'') in gids
    for n in nodes:
        n.destroy_node()


def test_switch_off_gives_typed_endpoints(ros_context, spin, monkeypatch):
    monkeypatch.setenv(cdr.ENV, '0')
    talker = Talker(context=ros_context, parameter_overrides=PARAMS)
    listener = Listener(False, context=ros_context, parameter_overrides=PARAMS)
    assert not listener.sub.raw and talker.pub.raw_codec is None
    assert spin([talker, listener], _matched(talker.pub, listener.sub))
    talker.pub.publish(_env(0))
    assert spin([talker, listener], lambda: listener.got)
    same(listener.got[0], _env(0))


def test_inactive_lifecycle_publisher_sends_nothing(ros_context, spin, monkeypatch):
    monkeypatch.delenv(cdr.ENV, raising=False)
    node = Node('managed', context=ros_context)
    pub = cdr.raw_publisher(node.create_publisher(LockstepStatus, 'st', QOS_DATA,
                                                  publisher_class=LifecyclePublisher))
    assert pub.raw_codec is not None
    got = []
    sub = node.create_subscription(LockstepStatus, 'st', got.append, QOS_DATA)
    assert spin([node], _matched(pub, sub))
    pub.on_deactivate(None)
    pub.publish(LockstepStatus(node='off'))
    pub.on_activate(None)
    pub.publish(LockstepStatus(node='on'))
    assert spin([node], lambda: got)
    assert [m.node for m in got] == ['on']     # 'off' would have come first (reliable, FIFO)


@pytest.mark.parametrize('with_info', [False, True])
def test_malformed_payload_is_dropped_not_raised(ros_context, spin, monkeypatch, with_info):
    """A stranger's bytes that do not decode (truncated, invalid UTF-8, not CDR) are dropped
    with a warning; the node keeps running and takes the next good message."""
    monkeypatch.delenv(cdr.ENV, raising=False)
    listener = Listener(with_info, context=ros_context, parameter_overrides=PARAMS)
    stranger = Node('stranger', context=ros_context)
    spub = stranger.create_publisher(Environment, 'sim/environment', QOS_DATA)
    assert spin([listener, stranger], _matched(spub, listener.sub))
    good = cdr.codec(Environment).encode(_env(0))
    bad_utf8 = bytearray(good)
    bad_utf8[16:19] = b'\xff\xfe\xfd'      # frame_id 'eci' -> invalid UTF-8
    for data in (good[:30], bytes(bad_utf8), b'\x00\x00\x00\x00\x01', b'\x00\x01'):
        spub.publish(data)
    spub.publish(good)
    assert spin([listener, stranger], lambda: listener.got)
    assert len(listener.got) == 1
    same(listener.got[0], _env(0))
    assert listener.counts.rejected['undecodable'] == 4           # counted for /diagnostics
    assert listener.timing_diagnostics()['rejected_undecodable'] == '4'
    assert 'does not decode' in listener.counts.last_rejected


def test_decoding_reports_errors():
    errors, got = [], []
    cb = cdr.decoding(got.append, cdr.codec(Clock), errors.append)
    cb(b'\x00\x01\x00\x00\x01')
    assert not got and len(errors) == 1
    cb(Clock())                      # an object (in-process delivery) passes unchanged
    assert got and type(got[0]) is Clock
