"""/diagnostics helper: one DiagnosticArray per sim second from the frame path, stamped with
that sim time, level WARN exactly in the periods where a problem counter grew or a fallback
is active, every value a string KeyValue; received by a plain subscriber as
``diagnostic_msgs/DiagnosticArray`` (what rqt_robot_monitor and Foxglove read)."""
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node

from adcs_nodes.msgs.fields import stamp_ns, to_stamp
from adcs_nodes.nodes.diagnostics import Diagnostics

EPOCH_NS = 1767225600 * 10**9


class _Node(Node):
    def __init__(self, context):
        super().__init__('fake_estimator', context=context)
        self.rejected_count = 0
        self.last_rejection = ''
        self.fallback = ''

    def stamp(self, t_ns):
        return to_stamp(EPOCH_NS + t_ns)

    def timing_diagnostics(self):
        return {'timing_mode': 'lockstep', 'frames': '7', 'missed_frames': '0'}

    def diagnostic_values(self):
        return {'active': 'magnetic', 'fallback': self.fallback}


def test_one_status_per_sim_second_with_levels(ros_context, spin):
    node = _Node(ros_context)
    diag = Diagnostics(node)
    probe = rclpy.create_node('probe', context=ros_context)
    got = []
    probe.create_subscription(DiagnosticArray, '/diagnostics', got.append, 100)
    assert spin([node, probe], lambda: diag.pub.get_subscription_count() == 1)
    published = []
    for k in range(9):                      # frames every 0.5 s: 0 .. 4 s
        t_ns = k * 500_000_000
        if k == 3:                          # 1.5 s: two rejected samples
            node.rejected_count, node.last_rejection = 2, 'stale'
        if k == 6:                          # 3.0 s: the manager falls back
            node.fallback = 'magnetic stale'
        published.append(diag.frame(t_ns))
    assert published == [True, False, True, False, True, False, True, False, True]
    assert spin([node, probe], lambda: len(got) == 5)
    assert [(stamp_ns(m.header.stamp) - EPOCH_NS) / 1e9 for m in got] == [0, 1, 2, 3, 4]
    levels = [m.status[0].level for m in got]
    ok, warn = DiagnosticStatus.OK, DiagnosticStatus.WARN
    assert levels == [ok, ok, warn, warn, warn]     # 2 s: rejections; 3, 4 s: fallback
    assert got[2].status[0].message == '2 rejected count'
    assert got[3].status[0].message == 'fallback: magnetic stale'
    st = got[0].status[0]
    assert st.name == 'fake_estimator' and st.hardware_id == 'adcs'
    values = {kv.key: kv.value for kv in st.values}
    assert values == {'timing_mode': 'lockstep', 'frames': '7', 'missed_frames': '0',
                      'rejected_count': '0', 'last_rejection': '', 'active': 'magnetic',
                      'fallback': ''}
    probe.destroy_node()
    node.destroy_node()


def test_bad_period_is_refused(ros_context):
    node = _Node(ros_context)
    try:
        Diagnostics(node, period_s=0.0)
    except ValueError as exc:
        assert 'positive' in str(exc)
    else:
        raise AssertionError('period 0 accepted')
    finally:
        node.destroy_node()


def test_nothing_is_built_while_nobody_reads_diagnostics(ros_context, spin):
    node = _Node(ros_context)
    diag = Diagnostics(node)
    built = []
    real_status = diag.status
    diag.status = lambda: built.append(1) or real_status()
    assert diag.pub.get_subscription_count() == 0
    assert [diag.frame(k * 500_000_000) for k in range(4)] == [False] * 4     # 0 .. 1.5 s
    assert built == []
    probe = rclpy.create_node('probe', context=ros_context)
    got = []
    probe.create_subscription(DiagnosticArray, '/diagnostics', got.append, 100)
    assert spin([node, probe], lambda: diag.pub.get_subscription_count() == 1)
    # a reader now: the next period boundary (2 s) publishes, stamped with it
    assert [diag.frame(k * 500_000_000) for k in (4, 5)] == [True, False]
    assert spin([node, probe], lambda: len(got) == 1)
    assert stamp_ns(got[0].header.stamp) - EPOCH_NS == 2_000_000_000 and built == [1]
    probe.destroy_node()
    node.destroy_node()


def test_the_estimator_reports_its_filter_restarts(ros_context):
    """Issue 23: docs/topics.md promises filter restarts on /diagnostics: the estimator node
    reports the core's ``resets`` (paper 000's filter resets a diverged estimate)."""
    from rclpy.parameter import Parameter

    from adcs_nodes.nodes.estimator import EstimatorNode
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('timing_mode', value='lockstep')])
    values = dict(node.diagnostics.values())
    assert values['resets'] == 0
    node.component.core.resets = 2        # as the filter counts a divergence reset
    assert dict(node.diagnostics.values())['resets'] == 2
    node.destroy_node()


def test_the_first_frame_logs_the_process_cpu_once(ros_context, spin):
    """``start cost {json}`` at the node's first frame (the bench's start-up row reads it)."""
    import json
    import time

    from rcl_interfaces.msg import Log

    from adcs_nodes.nodes.runtime import START_COST_PREFIX
    node = _Node(ros_context)
    diag = Diagnostics(node)
    probe = rclpy.create_node('probe', context=ros_context)
    lines = []
    sub = probe.create_subscription(Log, '/rosout', lambda m: lines.append(m.msg)
                                    if m.name == 'fake_estimator' else None, 100)
    assert spin([node, probe], lambda: sub.get_publisher_count() >= 2)
    for k in (5, 6, 7):                     # a node that joins at t = 5 s
        diag.frame(k * 1_000_000_000)
    cpu_now = time.process_time()
    node.get_logger().info('end of test')   # (in order after any line the frames logged)
    assert spin([node, probe], lambda: 'end of test' in lines)
    costs = [json.loads(x[len(START_COST_PREFIX):]) for x in lines
             if x.startswith(START_COST_PREFIX)]
    assert len(costs) == 1
    assert costs[0]['t_s'] == 5.0 and 0.0 < costs[0]['cpu_s'] <= cpu_now
