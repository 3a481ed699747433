"""``lockstep/status`` is built only for a reader that keeps it (issue 13).

The launcher's monitor (node ``adcs_launcher``) takes only the clock master's statuses and
those with missed frames (its content filter); when it is the only reader, the other nodes
skip theirs. Any other reader (recorder, live view, ``ros2 topic echo``) gets every status.
"""
import rclpy
from rclpy.parameter import Parameter

from adcs_msgs.msg import LockstepStatus
from adcs_nodes.nodes.lockstep_node import MONITOR_NODE, MONITOR_STATUS_OF, LockstepNode


def _node(ctx, name):
    return LockstepNode(name, context=ctx, parameter_overrides=[
        Parameter('timing_mode', value='lockstep'), Parameter('duration_s', value=5.0)])


def _reader(ctx, name, got):
    node = rclpy.create_node(name, context=ctx, start_parameter_services=False)
    node.create_subscription(LockstepStatus, 'lockstep/status', got.append, 100)
    return node


def test_status_skipped_only_when_the_monitor_alone_would_drop_it(ros_context, spin):
    other = _node(ros_context, 'estimator')
    master = _node(ros_context, MONITOR_STATUS_OF)
    got = []
    monitor = _reader(ros_context, MONITOR_NODE, got)
    nodes = [other, master, monitor]
    # the names of the readers come with discovery: wait until both nodes know them
    assert spin(nodes, lambda: all(
        [i.node_name for i in n.get_subscriptions_info_by_topic('/lockstep/status')]
        == [MONITOR_NODE] for n in (other, master)), timeout=30.0)
    assert not other.status.wanted()           # the monitor's filter would drop it
    assert master.status.wanted()              # the clock master's: kept
    other.missed_frames = 1
    assert other.status.wanted()               # missed frames: the monitor keeps it
    other.missed_frames = 0
    for k in range(3):
        other.frames = master.frames = k + 1
        other.publish_status()
        master.publish_status()
    assert spin(nodes, lambda: len(got) >= 3, timeout=30.0)
    assert {m.node for m in got} == {MONITOR_STATUS_OF}

    # a second reader of any other name (a recorder, ros2 topic echo): every status again
    got2 = []
    echo = _reader(ros_context, 'echo', got2)
    nodes.append(echo)
    assert spin(nodes, lambda: other.status.pub.get_subscription_count() == 2
                and other.status.wanted(), timeout=30.0)
    other.publish_status()
    assert spin(nodes, lambda: any(m.node == 'estimator' for m in got2), timeout=30.0)
    for n in nodes:
        n.destroy_node()


def test_no_reader_no_status(ros_context):
    node = _node(ros_context, 'lonely')
    assert node.status.pub.get_subscription_count() == 0
    assert not node.status.wanted()
    node.destroy_node()


def test_master_status_to_the_monitor_alone_is_held_to_its_wall_period(ros_context, spin):
    """The clock master's periodic statuses go to the monitor alone at most once per
    MONITOR_STATUS_WALL_S of wall time (not once per sim second: 2000 a second at 2000 x real
    time); the final one, and every one while frames are missed, are never held back."""
    import time

    from adcs_nodes.nodes.lockstep_node import MONITOR_STATUS_WALL_S
    master = _node(ros_context, MONITOR_STATUS_OF)
    monitor = _reader(ros_context, MONITOR_NODE, [])
    nodes = [master, monitor]
    assert spin(nodes, lambda: [i.node_name for i in master.get_subscriptions_info_by_topic(
        '/lockstep/status')] == [MONITOR_NODE], timeout=30.0)
    assert master.status.wanted()       # (reads the readers' names)
    sent = []
    publish = master.status.pub.publish
    master.status.pub.publish = lambda m: (sent.append(m), publish(m))

    def frames(first, n, final_last=False):
        for k in range(first, first + n):
            master.frames = k + 1
            master.frame_done(k * master.frame_ns, final=final_last and k == first + n - 1)

    t0 = time.monotonic()
    frames(0, 200)
    elapsed = time.monotonic() - t0
    assert len(sent) <= 1 + elapsed / MONITOR_STATUS_WALL_S     # not 200
    n = len(sent)
    frames(200, 1, final_last=True)      # the final status: sent at once
    assert len(sent) == n + 1 and sent[-1].final
    master.status.pacer.final_sent = False
    master.missed_frames = 1             # missed frames: every sim second again
    frames(201, 20)
    assert len(sent) == n + 1 + 20

    # a second reader (ros2 topic echo, a recorder): every sim second
    master.missed_frames = 0
    echo = _reader(ros_context, 'echo', [])
    nodes.append(echo)
    assert spin(nodes, lambda: master.status.pub.get_subscription_count() == 2, timeout=30.0)
    n = len(sent)
    frames(221, 20)
    assert len(sent) == n + 20
    for node in nodes:
        node.destroy_node()
