"""A composed run: one node's exception ends that node only (issue 38 item 3, DESIGN section
6). Three nodes in one process, the composed runner's guard and in-process path: a talker's
timer publishes; a node whose callback raises on its third message is marked dead (said
once, nothing more runs in it); the listener and the talker go on."""
import pytest

pytest.importorskip('rclpy')

from rclpy.node import Node  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from adcs_nodes.nodes.runtime import make_executor  # noqa: E402
from adcs_nodes.tools.run.compose import InProcessBus, guard_callbacks  # noqa: E402


def test_a_raising_node_is_marked_dead_and_the_others_go_on(ros_context, spin, capfd):
    talker = Node('talker', context=ros_context)
    pub = talker.create_publisher(String, 'chatter', 10)
    sent = []

    def tick():
        sent.append(len(sent))
        pub.publish(String(data=str(sent[-1])))
    talker.create_timer(0.01, tick)
    crasher = Node('crasher', context=ros_context)
    listener = Node('listener', context=ros_context)
    calls, heard = [], []

    def crash(msg):
        calls.append(msg.data)
        if len(calls) == 3:
            raise IndexError('index 0 is out of bounds for axis 0 with size 0')
    crasher.create_subscription(String, 'chatter', crash, 10)
    listener.create_subscription(String, 'chatter', lambda m: heard.append(m.data), 10)
    nodes = [talker, crasher, listener]
    dead = guard_callbacks(nodes)
    InProcessBus(nodes)
    assert spin(nodes, lambda: len(heard) >= 20, executor=make_executor(ros_context))
    assert dead == {'crasher': 'IndexError: index 0 is out of bounds for axis 0 with size 0'}
    assert len(calls) == 3                         # nothing more ran in the dead node
    assert len(sent) >= 20
    err = capfd.readouterr().err
    assert err.count('[compose] node crasher died (IndexError') == 1
    assert 'the other nodes go on' in err
