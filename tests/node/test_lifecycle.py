"""Managed (lifecycle) flight-software nodes, driven through the standard services.

The state machine is ROS 2's (``lifecycle_msgs``): a node started with ``autostart:=false``
must be ``unconfigured`` with no topic at all; ``configure`` creates its endpoints but it
publishes nothing (``inactive``); ``activate`` starts the output; ``deactivate`` stops it
(frames go on, nothing is published); ``cleanup`` removes the endpoints; a bad parameter
makes ``configure`` fail with the reason logged and no traceback. Every transition goes
through the real ``lifecycle_msgs/srv/ChangeState`` and ``GetState`` services with a
deadline; "publishes nothing" is checked over frames the node processed (a condition), not
over a fixed sleep. The launcher and the composed runner drive the same transitions.
"""
import os

import pytest
import rclpy
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter

from adcs_msgs.msg import ActuatorCommand, AttitudeTarget
from adcs_nodes.nodes.controller import ControllerNode
from adcs_nodes.nodes.controller_manager import ControllerManagerNode
from adcs_nodes.msgs.fields import stamp_ns
from adcs_nodes.nodes.estimator import EstimatorNode
from adcs_nodes.nodes.guidance import GuidanceNode
from adcs_nodes.nodes.managed import ManagedLockstepNode

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TOPIC = '/adcs/controllers/bdot/command'
SUCCESS = TransitionCallbackReturn.SUCCESS


class _Services:
    """Client side of a node's standard lifecycle services."""

    def __init__(self, ctx, spin, node):
        self.spin, self.node = spin, node
        self.probe = rclpy.create_node('lifecycle_probe', context=ctx)
        name = node.get_name()
        self.change = self.probe.create_client(ChangeState, f'/{name}/change_state')
        self.get = self.probe.create_client(GetState, f'/{name}/get_state')
        assert spin([node, self.probe], lambda: self.change.service_is_ready()
                    and self.get.service_is_ready()), 'lifecycle services not found'

    #: State each transition of the test leads to when it succeeds.
    GOAL = {Transition.TRANSITION_CONFIGURE: State.PRIMARY_STATE_INACTIVE,
            Transition.TRANSITION_ACTIVATE: State.PRIMARY_STATE_ACTIVE,
            Transition.TRANSITION_DEACTIVATE: State.PRIMARY_STATE_INACTIVE,
            Transition.TRANSITION_CLEANUP: State.PRIMARY_STATE_UNCONFIGURED,
            Transition.TRANSITION_ACTIVE_SHUTDOWN: State.PRIMARY_STATE_FINALIZED}

    def _call(self, client, request, timeout=10.0):
        """The answer, or None when none came within ``timeout`` (Fast DDS under load now
        and then fails to send a service answer: "failed to send response (timeout)")."""
        future = client.call_async(request)
        if not self.spin([self.node, self.probe], future.done, timeout=timeout):
            return None
        return future.result()

    def state(self) -> int:
        for _ in range(3):              # asking the state again is harmless
            answer = self._call(self.get, GetState.Request())
            if answer is not None:
                return answer.current_state.id
        raise AssertionError('get_state: no answer to 3 requests of 10 s')

    def transition(self, transition_id: int) -> bool:
        request = ChangeState.Request()
        request.transition.id = transition_id
        answer = self._call(self.change, request)
        if answer is not None:
            return answer.success
        # a lost answer: never resend a transition (the node may have done it), ask its state
        return self.state() == self.GOAL[transition_id]


def test_transitions_through_the_standard_services(ros_context, spin):
    node = ControllerNode(controller='bdot', context=ros_context, parameter_overrides=[
        Parameter('autostart', value=False), Parameter('period_s', value=0.1)])
    srv = _Services(ros_context, spin, node)
    got = []
    srv.probe.create_subscription(ActuatorCommand, TOPIC, got.append, 100)

    # unconfigured: no parameters read, no topic, no timer
    assert srv.state() == State.PRIMARY_STATE_UNCONFIGURED
    assert srv.probe.count_publishers(TOPIC) == 0 and not list(node.timers)
    assert not node.has_parameter('period_s') or node.describe_parameter('period_s') \
        .description == ''                       # (given, but not declared by the node yet)

    # configure -> inactive: the endpoints exist, frames are processed, nothing published
    assert srv.transition(Transition.TRANSITION_CONFIGURE)
    assert srv.state() == State.PRIMARY_STATE_INACTIVE
    assert node.describe_parameter('period_s').description   # declared with its spec now
    assert spin([node, srv.probe], lambda: srv.probe.count_publishers(TOPIC) == 1
                and node.pub.get_subscription_count() == 1)
    frames = node.frames
    assert spin([node, srv.probe], lambda: node.frames >= frames + 3)
    assert got == []

    # activate -> published
    assert srv.transition(Transition.TRANSITION_ACTIVATE)
    assert srv.state() == State.PRIMARY_STATE_ACTIVE
    assert spin([node, srv.probe], lambda: len(got) >= 3), 'no command after activate'

    # deactivate -> no message of a frame processed afterwards
    assert srv.transition(Transition.TRANSITION_DEACTIVATE)
    assert srv.state() == State.PRIMARY_STATE_INACTIVE
    last_active = node.stamp(node.sim_t_ns)
    frames = node.frames
    assert spin([node, srv.probe], lambda: node.frames >= frames + 3)
    assert all(stamp_ns(m.header.stamp) <= stamp_ns(last_active) for m in got)

    # cleanup -> unconfigured, the topic is gone; configure works again
    assert srv.transition(Transition.TRANSITION_CLEANUP)
    assert srv.state() == State.PRIMARY_STATE_UNCONFIGURED
    assert spin([node, srv.probe], lambda: srv.probe.count_publishers(TOPIC) == 0)
    assert not list(node.timers) and not list(node.subscriptions)
    assert srv.transition(Transition.TRANSITION_CONFIGURE)
    assert srv.state() == State.PRIMARY_STATE_INACTIVE
    assert node.get_parameter('period_s').value == 0.1    # the given value, read again
    assert srv.transition(Transition.TRANSITION_ACTIVATE)
    before = len(got)
    assert spin([node, srv.probe], lambda: len(got) >= before + 2), 'silent after re-activate'

    # shutdown ends the node (the runtime's spin loop stops on `done`)
    assert srv.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
    assert srv.state() == State.PRIMARY_STATE_FINALIZED
    assert node.done
    srv.probe.destroy_node()
    node.destroy_node()


@pytest.mark.parametrize('bad, reason', [
    (Parameter('period_s', value=-1.0), 'period_s'),
    (Parameter('perod_s', value=2.0), "did you mean 'period_s'"),
    (Parameter('algorithm', value='kalman9000'), 'kalman9000'),
])
def test_bad_parameter_fails_configure_with_the_reason(ros_context, spin, capfd, bad, reason):
    node = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('autostart', value=False), bad])
    srv = _Services(ros_context, spin, node)
    assert not srv.transition(Transition.TRANSITION_CONFIGURE)
    assert srv.state() == State.PRIMARY_STATE_UNCONFIGURED
    assert reason in node.configure_error
    err = capfd.readouterr().err
    logged = [ln for ln in err.splitlines() if 'configuration error:' in ln]
    assert logged and reason in logged[-1] and '[estimator]' in logged[-1], err[-2000:]
    assert 'Traceback' not in err
    assert not list(node.timers) and not list(node.subscriptions)   # nothing left behind
    srv.probe.destroy_node()
    node.destroy_node()


@pytest.mark.parametrize('cls', [EstimatorNode, ControllerNode, ControllerManagerNode,
                                 GuidanceNode])
def test_autostart_default_is_active_and_a_bad_value_still_raises(ros_context, cls):
    node = cls(context=ros_context)
    assert node.lifecycle_state == 'active' and node.active
    node.destroy_node()
    with pytest.raises(ValueError, match='period'):
        cls(context=ros_context, parameter_overrides=[Parameter('period_s', value=-2.0)])


def test_inactive_guidance_is_not_ready_and_publishes_nothing(ros_context, spin):
    """The start handshake: a managed node says ``lockstep/ready`` only once active."""
    node = GuidanceNode(context=ros_context, parameter_overrides=[
        Parameter('autostart', value=False), Parameter('period_s', value=0.1)])
    got = []
    probe = rclpy.create_node('probe', context=ros_context)
    probe.create_subscription(AttitudeTarget, '/adcs/attitude_target', got.append, 100)
    assert node.trigger_configure() == SUCCESS
    assert spin([node, probe], lambda: node.pub.get_subscription_count() == 1)
    frames = node.frames
    assert spin([node, probe], lambda: node.frames >= frames + 3)
    assert not node._ready_sent and got == []
    assert any('not active' in m for m in node.unmatched())
    assert node.trigger_activate() == SUCCESS
    assert spin([node, probe], lambda: node._ready_sent and len(got) >= 2)
    probe.destroy_node()
    node.destroy_node()


def test_the_graph_lists_the_managed_classes():
    from adcs_nodes.graph import build_graph
    from adcs_nodes.tools.run.launch_graph import MANAGED_CLASSES, is_managed
    from adcs_nodes.scenario import load_scenario

    import importlib
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper000_control.yaml'))
    nodes = build_graph(sc, 20.0, record=True)
    for spec in nodes:
        cls = getattr(importlib.import_module(spec.module), spec.cls)
        assert is_managed(spec) == issubclass(cls, ManagedLockstepNode), spec.cls
    assert {n.cls for n in nodes if is_managed(n)} == set(MANAGED_CLASSES)


def test_composed_runner_drives_the_transitions_and_reports_a_refusal(ros_context):
    from adcs_nodes.tools.run.compose import drive_lifecycle

    good = ControllerNode(controller='bdot', context=ros_context, parameter_overrides=[
        Parameter('autostart', value=False)])
    already = GuidanceNode(context=ros_context)               # autostart: left as it is
    assert drive_lifecycle([good, already]) == ''
    assert good.lifecycle_state == 'active' and already.lifecycle_state == 'active'
    bad = EstimatorNode(context=ros_context, parameter_overrides=[
        Parameter('autostart', value=False), Parameter('period_s', value=-1.0)])
    why = drive_lifecycle([bad])
    assert why.startswith('estimator: ') and 'period_s' in why
    for n in (good, already, bad):
        n.destroy_node()


def test_recorder_records_the_transition_events(ros_context, spin, tmp_path):
    """Recording every topic, the recorder takes ``~/transition_event`` like any topic."""
    from adcs_nodes.nodes.recorder import RecorderNode

    node = ControllerNode(controller='bdot', context=ros_context, parameter_overrides=[
        Parameter('autostart', value=False)])
    recorder = RecorderNode(context=ros_context, parameter_overrides=[
        Parameter('output', value=str(tmp_path / 'bag')),
        Parameter('discovery_period_s', value=0.1)])
    topic = '/bdot_controller/transition_event'
    try:
        assert spin([node, recorder], lambda: topic in recorder.topics)
        node.trigger_configure()
        node.trigger_activate()
        assert spin([node, recorder], lambda: recorder.counts.get(topic, 0) >= 2)
    finally:
        recorder.close()
        recorder.destroy_node()
        node.destroy_node()


def test_launcher_reports_a_node_refusing_configure(tmp_path):
    """``adcs run``: a managed node whose configure fails stops the run with exit code 2 and
    the node's reason (the launcher drives the transitions through the services)."""
    from adcs_nodes.tools.run.launcher import Launcher
    from adcs_nodes.scenario import load_scenario

    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper000_control.yaml'))
    launcher = Launcher(sc, duration_s=20.0, progress=False, run_dir=str(tmp_path / 'run'),
                        log=lambda *a, **k: None)
    manager = next(n for n in launcher.nodes if n.name == 'controller_manager')
    manager.params['stale_after_s'] = 'soon'       # a string where a float is due
    result = launcher.run()
    assert result.exit_code == 2, result.message
    assert result.message.startswith('node controller_manager refused its configuration '
                                     '(lifecycle configure failed): '), result.message
    assert 'stale_after_s' in result.message.splitlines()[0], result.message
    with open(tmp_path / 'run' / 'params.yaml') as fh:
        assert 'autostart: false' in fh.read()


def test_a_delivery_taken_before_a_cleanup_is_dropped(ros_context):
    """The executor may hold a message or a timer call of a subscription that a cleanup has
    just destroyed: its callback runs on a node whose configuration is gone. It is dropped
    (it killed B-dot in a graph run: ``'ControllerNode' object has no attribute
    'epoch_ns'``)."""
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import MagneticField
    node = ControllerNode(controller='bdot', context=ros_context, parameter_overrides=[
        Parameter('autostart', value=False)])
    try:
        assert node.trigger_configure() == SUCCESS
        timing = node.timing
        name = next(iter(timing.topics))
        stale = (timing.input_cb(name), timing.on_clock_tick, timing.watchdog)
        assert node.trigger_cleanup() == SUCCESS
        msg = MagneticField()
        msg.header.stamp.sec = 1_774_000_000
        stale[0](msg)
        stale[1](Clock())
        stale[2]()
        assert node.trigger_configure() == SUCCESS      # and it configures again
    finally:
        node.destroy_node()
