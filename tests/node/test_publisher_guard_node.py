"""Publisher identity of a lockstep input, in process (issue 12, ``publisher_guard``).

A lockstep consumer with ``expected_publishers: ["data=producer"]``, a node ``forger`` that is
on the domain before the handshake, then the node ``producer``:

* the consumer is not ready while only the forger publishes ``data`` (a matched publisher is
  not enough: it must be the named node's);
* at the handshake the forger is reported (``second_publisher``), not trusted;
* a forged message of frame 0 arriving first is dropped, the producer's one is used, a
  second message of the producer with the same stamp (other content) is dropped;
* each refusal is counted in the consumer's diagnostics and published on
  ``adcs/security_events`` (``diagnostic_msgs/DiagnosticArray``, topic, reason, GID).
Before the guard the frame used the forged value and nothing was reported.
"""
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.parameter import Parameter

from adcs_nodes.nodes.lockstep_node import QOS_DATA, LockstepNode, epoch_to_ns, parse_epoch
from adcs_nodes.nodes.publisher_guard import EVENTS_TOPIC

EPOCH = '2026-01-01T00:00:00Z'


class Consumer(LockstepNode):
    def __init__(self, **kwargs):
        super().__init__('consumer', **kwargs)
        self.got = []
        self.lockstep_inputs({'data': (Vector3Stamped, 'data', 1.0)}, 1.0, self.on_frame)
        self.start_handshake()

    def on_frame(self, t_ns, msgs, missing):
        m = msgs['data']
        self.got.append((t_ns, None if m is None else m.vector.x))


def _msg(t_s, x):
    m = Vector3Stamped()
    ns = epoch_to_ns(parse_epoch(EPOCH)) + int(t_s * 1e9)
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(ns, 1_000_000_000)
    m.vector.x = float(x)
    return m


def test_only_the_named_publisher_feeds_a_guarded_input(ros_context, spin):
    overrides = [Parameter('epoch', value=EPOCH), Parameter('timing_mode', value='lockstep'),
                 Parameter('frame_period_s', value=1.0),
                 Parameter('expected_matches', value=['sub:data=1']),
                 Parameter('expected_publishers', value=['data=producer'])]
    consumer = Consumer(context=ros_context, parameter_overrides=overrides)
    forger = Node('forger', context=ros_context)
    fpub = forger.create_publisher(Vector3Stamped, 'data', QOS_DATA)
    listener = Node('listener', context=ros_context)
    events = []
    listener.create_subscription(DiagnosticArray, EVENTS_TOPIC, events.append, QOS_DATA)
    nodes = [consumer, forger, listener]
    assert spin(nodes, lambda: consumer._subs['/data'].get_publisher_count() >= 1
                and fpub.get_subscription_count() >= 1
                and consumer._publisher_guard.pub.get_subscription_count() >= 1, timeout=20.0)
    # the handshake's count (1 publisher) is met by the forger, yet the consumer waits
    missing = consumer.unmatched()
    assert any('no publisher of producer' in m for m in missing), missing
    assert not consumer._ready_sent

    producer = Node('producer', context=ros_context)
    ppub = producer.create_publisher(Vector3Stamped, 'data', QOS_DATA)
    nodes.append(producer)
    assert spin(nodes, lambda: consumer._ready_sent and ppub.get_subscription_count() >= 1,
                timeout=20.0)
    guard = consumer._publisher_guard.core
    assert guard.counts['second_publisher'] == 1          # the forger, seen at the handshake

    fpub.publish(_msg(0.0, 666.0))                        # forged frame 0, first
    assert spin(nodes, lambda: guard.counts['foreign_publisher'] == 1, timeout=20.0)
    assert consumer.got == []                             # dropped, not stored
    ppub.publish(_msg(0.0, 1.0))                          # the true frame 0
    assert spin(nodes, lambda: consumer.got, timeout=20.0)
    assert consumer.got == [(0, 1.0)]
    ppub.publish(_msg(0.0, 2.0))                          # same stamp again, other content
    ppub.publish(_msg(1.0, 3.0))                          # next frame
    assert spin(nodes, lambda: len(consumer.got) == 2 and guard.counts['duplicate_stamp'] == 1,
                timeout=20.0)
    assert consumer.got == [(0, 1.0), (1_000_000_000, 3.0)]

    diag = consumer.timing_diagnostics()
    assert diag['security_foreign_publisher'] == '1'
    assert diag['security_duplicate_stamp'] == '1'
    assert int(diag['security_events']) == 3
    forger_gid = None
    for info in consumer.get_publishers_info_by_topic('data'):
        if info.node_name == 'forger':
            forger_gid = bytes(info.endpoint_gid).hex()
    assert spin(nodes, lambda: len(events) >= 3, timeout=20.0), events
    recorded = [{kv.key: kv.value for kv in e.status[0].values} for e in events]
    reasons = sorted(r['reason'] for r in recorded)
    assert reasons == ['duplicate_stamp', 'foreign_publisher', 'second_publisher'], recorded
    foreign = next(r for r in recorded if r['reason'] == 'foreign_publisher')
    assert foreign['topic'] == '/data' and foreign['publisher_gid'] == forger_gid
    assert foreign['expected_node'] == 'producer'
    assert all(e.status[0].level == e.status[0].WARN for e in events)
    for n in nodes:
        n.destroy_node()


def test_a_node_without_expected_publishers_accepts_every_publisher(ros_context, spin):
    overrides = [Parameter('epoch', value=EPOCH), Parameter('timing_mode', value='lockstep'),
                 Parameter('frame_period_s', value=1.0)]
    consumer = Consumer(context=ros_context, parameter_overrides=overrides)
    forger = Node('forger', context=ros_context)
    fpub = forger.create_publisher(Vector3Stamped, 'data', QOS_DATA)
    nodes = [consumer, forger]
    assert spin(nodes, lambda: fpub.get_subscription_count() >= 1, timeout=20.0)
    assert consumer._publisher_guard is None
    fpub.publish(_msg(0.0, 5.0))
    assert spin(nodes, lambda: consumer.got, timeout=20.0)
    assert consumer.got == [(0, 5.0)]
    assert 'security_events' not in consumer.timing_diagnostics()
    for n in nodes:
        n.destroy_node()


def test_bad_expected_publishers_is_a_configuration_error(ros_context):
    overrides = [Parameter('timing_mode', value='lockstep'),
                 Parameter('expected_publishers', value=['data'])]
    with pytest.raises(ValueError, match='expected_publishers'):
        Consumer(context=ros_context, parameter_overrides=overrides)
