"""LockstepNode.lockstep_inputs: fires in order when due inputs arrive; timeout fallback;
dead producers; previous-frame inputs; status at sim seconds; timing mode; QoS overrides."""
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header

from adcs_msgs.msg import LockstepStatus
from adcs_nodes.msgs.fields import to_stamp
from adcs_nodes.nodes.lockstep_node import LockstepNode

EPOCH_NS = 1767225600 * 10**9
S = 10**9


#: Wall time a due input is waited for, unless a test wants a timeout: every input a test sends
#: arrives long before it, however slow this process is under load (a frame fires as soon as
#: its inputs are there, so a long timeout costs nothing when the node is right).
NO_TIMEOUT_S = 60.0


class Probe(LockstepNode):
    def __init__(self, context, timeout_s=NO_TIMEOUT_S, inputs=None, extra=()):
        super().__init__('probe_node', context=context, parameter_overrides=[
            Parameter('timeout_s', value=timeout_s), Parameter('timing_mode', value='lockstep'),
            *extra])
        self.fired = []
        self.arrived = []       # names of the inputs taken, in order (input_arrived hook)
        self.lockstep_inputs(inputs or {'a': (LockstepStatus, 'in/a', 1.0),
                                        'b': (LockstepStatus, 'in/b', 2.0)}, 1.0, self.on_frame)

    def input_arrived(self, name):
        self.arrived.append(name)

    def on_frame(self, t, msgs, missing):
        self.fired.append((t // S, *(msgs[k] and msgs[k].node for k in sorted(msgs)),
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
    # a0 taken (the frame would fire in its callback): b is due at 0 and missing
    assert spin([node, src], lambda: node.arrived == ['a'], timeout=30.0)
    assert node.fired == []
    pb.publish(msg(0, 'b0'))
    pa.publish(msg(1, 'a1'))                   # at 1 s only a is due; b is latest (b0)
    pa.publish(msg(2, 'a2'))                   # at 2 s b is due again
    assert spin([node, src], lambda: len(node.arrived) == 4, timeout=30.0)   # a2 taken too
    assert node.fired == [(0, 'a0', 'b0', ()), (1, 'a1', 'b0', ())]
    pb.publish(msg(2, 'b2'))
    assert spin([node, src], lambda: len(node.fired) >= 3, timeout=30.0)
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
    # (a0 and b0 are taken in one pass of the executor, before any timer can run: frame 0
    # cannot time out however slow this process is)
    assert spin([node, src], lambda: len(node.fired) >= 3, timeout=30.0)
    assert node.fired[:2] == [(0, 'a0', 'b0', ()), (1, 'a1', 'b0', ())]
    assert node.fired[2] == (2, 'a2', 'b0', ('/in/b',))
    assert node.missed_frames == 1
    src.destroy_node()
    node.destroy_node()


def _pubs(node, ros_context, spin, *topics):
    src = rclpy.create_node('src', context=ros_context)
    pubs = [src.create_publisher(LockstepStatus, t, 10) for t in topics]
    assert spin([node, src], lambda: all(p.get_subscription_count() for p in pubs))
    return src, pubs


def test_dead_producer_is_no_longer_awaited_until_it_publishes_again(ros_context, spin):
    """Issue 12: a dead producer cost a timeout per frame forever."""
    node = Probe(ros_context, timeout_s=0.3, extra=[Parameter('dead_after_frames', value=2)])
    src, (pa, pb) = _pubs(node, ros_context, spin, 'in/a', 'in/b')
    pb.publish(msg(0, 'b0'))
    for k in range(8):                       # b (due every 2 s) dies after t = 0
        pa.publish(msg(k, f'a{k}'))
    assert spin([node, src], lambda: len(node.fired) >= 8, timeout=30.0)
    missing = {f[0]: f[-1] for f in node.fired}
    assert missing[2] == ('/in/b',) and missing[4] == ('/in/b',)   # 2 timeouts ...
    assert missing[6] == ()                                        # ... then not awaited
    assert node.missed_frames == 2 and node.sync.is_dead('b')
    assert node.timing_diagnostics()['dead_inputs'] == '/in/b'
    # b8 (taken alone: it must revive b before a8 comes) makes frame 8 wait for a8 from then
    # on; with 0.3 s a stall of this process under load timed a8 out (injected: 0.35 s):
    # no timeout while this test still delivers, 0.3 s again where it wants one
    node.timeout_s = NO_TIMEOUT_S
    pb.publish(msg(8, 'b8'))                 # it publishes again: awaited again
    assert spin([node, src], lambda: not node.sync.is_dead('b'), timeout=30.0)
    from adcs_nodes.core.lockstep import REVIVE_HOLD_FRAMES
    end = 8 + REVIVE_HOLD_FRAMES                 # frames of 1 s: b is held to t = end
    pb.publish(msg(10, 'b10'))                   # within the hold: dropped
    for k in range(8, end + 2):
        pa.publish(msg(k, f'a{k}'))
    assert spin([node, src], lambda: len(node.fired) >= end + 2, timeout=30.0)
    # the reviving message and those of the hold are not used, and b is not awaited then
    # (FrameSync.add: otherwise a frame would depend on whether the revival came before the
    # node fired for it); b is awaited again from the frames after the hold
    assert all(f[2:] == ('b0', ()) for f in node.fired[8:end + 1])
    assert node.fired[8][:2] == (8, 'a8') and node.missed_frames == 2
    node.timeout_s = 0.3
    pa.publish(msg(end + 2, f'a{end + 2}'))      # b, due at end + 2, never comes: times out
    assert spin([node, src], lambda: len(node.fired) >= end + 3, timeout=30.0)
    assert node.fired[end + 2] == (end + 2, f'a{end + 2}', 'b0', ('/in/b',))
    assert node.missed_frames == 3
    src.destroy_node()
    node.destroy_node()


def test_previous_frame_input_gets_exactly_the_message_of_the_frame_before(ros_context, spin):
    node = Probe(ros_context, inputs={
        'a': (LockstepStatus, 'in/a', 1.0), 'c': (LockstepStatus, 'in/c', 1.0, 'previous')})
    src, (pa, pc) = _pubs(node, ros_context, spin, 'in/a', 'in/c')
    pa.publish(msg(0, 'a0'))
    pa.publish(msg(1, 'a1'))
    pc.publish(msg(1, 'c1'))                 # the command of frame 1 arrives first
    # all three taken (a1 last, it comes after a0 on its topic): frame 1 waits for c stamped 0
    assert spin([node, src], lambda: len(node.arrived) == 3, timeout=30.0)
    assert node.fired == [(0, 'a0', None, ())]
    pc.publish(msg(0, 'c0'))
    assert spin([node, src], lambda: len(node.fired) >= 2, timeout=30.0)
    assert node.fired[1] == (1, 'a1', 'c0', ())          # never "whatever arrived" (c1)
    src.destroy_node()
    node.destroy_node()


def test_status_is_stamped_with_sim_time_once_per_sim_second(ros_context, spin):
    """Issue 12: lockstep/status was recorded 1-7 times per run, all stamped t = 0."""
    node = Probe(ros_context, inputs={'a': (LockstepStatus, 'in/a', 1.0)},
                 extra=[Parameter('duration_s', value=5.0)])
    got = []
    src, (pa,) = _pubs(node, ros_context, spin, 'in/a')
    src.create_subscription(LockstepStatus, 'lockstep/status', got.append, 100)
    assert spin([node, src], lambda: node.status.pub.get_subscription_count() > 0)
    for k in range(6):
        pa.publish(msg(k, f'a{k}'))
    assert spin([node, src], lambda: any(m.final for m in got), timeout=30.0)
    stamps = [(m.header.stamp.sec * S + m.header.stamp.nanosec - EPOCH_NS) / S for m in got
              if m.frames > 0]
    assert stamps[:6] == [0, 1, 2, 3, 4, 5]
    assert got[-1].final and got[-1].frames == 6
    src.destroy_node()
    node.destroy_node()


def test_timing_mode_default_explicit_and_refused(ros_context):
    def make(*params, cls=LockstepNode):
        return cls('mode_probe', context=ros_context, parameter_overrides=list(params))
    alone = make()
    assert alone.timing_mode == 'live'                # started alone: live
    alone.destroy_node()
    launched = make(Parameter('duration_s', value=10.0))
    assert launched.timing_mode == 'lockstep'         # launcher parameters: lockstep
    launched.destroy_node()
    forced = make(Parameter('duration_s', value=10.0), Parameter('timing_mode', value='live'))
    assert forced.timing_mode == 'live'
    forced.destroy_node()
    with pytest.raises(ValueError, match='timing_mode'):
        make(Parameter('timing_mode', value='realtime'))

    class World(LockstepNode):
        SIMULATED_WORLD = True
    world = make(cls=World)
    assert world.timing_mode == 'lockstep'
    world.destroy_node()
    with pytest.raises(ValueError, match='simulated world'):
        make(Parameter('timing_mode', value='live'), cls=World)


def test_qos_overrides_let_a_best_effort_driver_match(ros_context, spin):
    best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
    plain = Probe(ros_context, inputs={'a': (LockstepStatus, 'in/a', 1.0)})
    src = rclpy.create_node('src', context=ros_context)
    pub = src.create_publisher(LockstepStatus, 'in/a', best_effort)
    spin([plain, src], lambda: pub.get_subscription_count() > 0, timeout=1.0)
    assert pub.get_subscription_count() == 0          # reliable subscription: no match
    plain.destroy_node()
    over = Probe(ros_context, inputs={'a': (LockstepStatus, 'in/a', 1.0)}, extra=[
        Parameter('qos_overrides./in/a.subscription.reliability', value='best_effort')])
    assert spin([over, src], lambda: pub.get_subscription_count() > 0)
    pub.publish(msg(0, 'a0'))
    assert spin([over, src], lambda: len(over.fired) >= 1, timeout=30.0)
    # the override applies to that subscription only, not to the shared profile (rclpy
    # applies overrides in place: in a composed process it would leak into every node)
    from adcs_nodes.nodes.lockstep_node import QOS_DATA
    assert QOS_DATA.reliability == ReliabilityPolicy.RELIABLE
    src.destroy_node()
    over.destroy_node()


def test_timing_diagnostics_of_the_clock_master_and_a_consumer(ros_context):
    """/diagnostics calls timing_diagnostics() on every node, the clock master included."""
    from sim_node.nodes.dynamics import DynamicsNode
    dyn = DynamicsNode(context=ros_context, parameter_overrides=[
        Parameter('command_period_s', value=1.0)])
    dyn.master.sync.add('env', 0, 'e0')
    for _ in range(3):
        dyn.master.sync.record_misses(0)
    d = dyn.timing_diagnostics()
    assert d['timing_mode'] == 'lockstep' and d['dead_inputs'] == 'adcs/actuator_command'
    dyn.destroy_node()
    probe = Probe(ros_context)
    assert probe.timing_diagnostics()['rejected_samples'] == '0'
    probe.destroy_node()
