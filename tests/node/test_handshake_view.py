"""The start handshake's warning tells "discovered but not matched" from "never discovered".

Once in CI a node's ``/clock`` subscription stayed at 0 of 1 publishers for 60 s while every
other endpoint pair of the same processes matched; the log could not say whether discovery had
never delivered the writer or had delivered it and the match failed. ``unmatched(graph_view=
True)`` (used by the "still waiting for endpoints" warning) adds how many peer endpoints the
node's discovery knows on the topic. Independent truth here: a best-effort writer is discovered
but never matched by a reliable reader (the DDS request/offer rule), a reliable one matches.
"""
from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data

from adcs_nodes.nodes.lockstep_node import QOS_DATA, LockstepNode


class Consumer(LockstepNode):
    def __init__(self, **kwargs):
        super().__init__('consumer', **kwargs)
        self.lockstep_inputs({'data': (Vector3Stamped, 'data', 1.0)}, 1.0, lambda *a: None)


def test_waiting_endpoint_says_what_discovery_knows(ros_context, spin):
    consumer = Consumer(context=ros_context, parameter_overrides=[
        Parameter('epoch', value='2026-01-01T00:00:00Z'),
        Parameter('timing_mode', value='lockstep'), Parameter('frame_period_s', value=1.0),
        Parameter('expected_matches', value=['sub:data=1'])])
    assert consumer.unmatched(graph_view=True) == ['sub:/data 0/1 (discovery knows 0)']

    other = Node('best_effort_driver', context=ros_context)
    other.create_publisher(Vector3Stamped, 'data', qos_profile_sensor_data)   # best effort
    assert spin([consumer, other], lambda: consumer.count_publishers('/data') >= 1)
    # discovered, not matched: a reliable reader does not match a best-effort writer
    assert consumer.unmatched(graph_view=True) == ['sub:/data 0/1 (discovery knows 1)']
    assert consumer.unmatched() == ['sub:/data 0/1']

    producer = Node('producer', context=ros_context)
    producer.create_publisher(Vector3Stamped, 'data', QOS_DATA)
    assert spin([consumer, other, producer], lambda: not consumer.unmatched(graph_view=True))
    assert consumer._subs['/data'].get_publisher_count() == 1
    for node in (producer, other, consumer):
        node.destroy_node()
