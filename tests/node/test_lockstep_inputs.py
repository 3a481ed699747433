"""LockstepNode.lockstep_inputs: fires in order when due inputs arrive; timeout fallback."""
import rclpy
from rclpy.parameter import Parameter
from std_msgs.msg import Header

from adcs_msgs.msg import LockstepStatus
from adcs_nodes.nodes.convert import to_stamp
from adcs_nodes.nodes.lockstep_node import LockstepNode

EPOCH_NS = 1767225600 * 10**9
S = 10**9


class Probe(LockstepNode):
    def __init__(self, context, timeout_s=5.0):
        super().__init__('probe_node', context=context, parameter_overrides=[
            Parameter('timeout_s', value=timeout_s)])
        self.fired = []
        self.lockstep_inputs({'a': (LockstepStatus, 'in/a', 1.0),
                              'b': (LockstepStatus, 'in/b', 2.0)}, 1.0, self.on_frame)

    def on_frame(self, t, msgs, missing):
        self.fired.append((t // S, msgs['a'] and msgs['a'].node, msgs['b'] and msgs['b'].node,
                           tuple(missing)))


def msg(t_s, tag):
    return LockstepStatus(header=Header(stamp=to_stamp(EPOCH_NS + t_s * S)), node=tag)


def test_fires_when_due_inputs_arrive_in_order(ros_context, spin):
    node = Probe(ros_context)
    src = rclpy.create_node('src', context=ros_context)
    pa = src.create_publisher(LockstepStatus, 'in/a', 10)
    pb = src.create_publisher(LockstepStatus, 'in/b', 10)
    assert spin([node, src], lambda: pa.get_subscription_count() and pb.get_subscription_count())
    pa.publish(msg(0, 'a0'))
    spin([node, src], lambda: False, timeout=0.2)
    assert node.fired == []                    # b is due at 0 and missing
    pb.publish(msg(0, 'b0'))
    pa.publish(msg(1, 'a1'))                   # at 1 s only a is due; b is latest (b0)
    pa.publish(msg(2, 'a2'))                   # at 2 s b is due again
    assert spin([node, src], lambda: len(node.fired) >= 2)
    spin([node, src], lambda: False, timeout=0.2)
    assert node.fired == [(0, 'a0', 'b0', ()), (1, 'a1', 'b0', ())]
    pb.publish(msg(2, 'b2'))
    assert spin([node, src], lambda: len(node.fired) >= 3)
    assert node.fired[2] == (2, 'a2', 'b2', ())
    assert node.missed_frames == 0
    src.destroy_node()
    node.destroy_node()


def test_missing_input_times_out_and_fires_with_latest(ros_context, spin):
    node = Probe(ros_context, timeout_s=0.3)
    src = rclpy.create_node('src', context=ros_context)
    pa = src.create_publisher(LockstepStatus, 'in/a', 10)
    pb = src.create_publisher(LockstepStatus, 'in/b', 10)
    assert spin([node, src], lambda: pa.get_subscription_count() and pb.get_subscription_count())
    pa.publish(msg(0, 'a0'))
    pb.publish(msg(0, 'b0'))
    pa.publish(msg(1, 'a1'))
    pa.publish(msg(2, 'a2'))                   # b2 never comes
    assert spin([node, src], lambda: len(node.fired) >= 3, timeout=5.0)
    assert node.fired[2] == (2, 'a2', 'b0', ('/in/b',))
    assert node.missed_frames == 1
    src.destroy_node()
    node.destroy_node()
