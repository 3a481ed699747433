"""The launcher's lifecycle driver survives a lost service answer.

Under load Fast DDS can drop a service reply ("failed to send response (timeout)") after the
node did the transition; a clean-clone CI run lost a run that way (guidance never answered
``configure`` and the launcher waited its 120 s deadline). The truth here is the
``lifecycle_msgs`` state machine: after a lost answer the driver asks ``get_state`` and sends
only the transition due from the node's actual state, never one the node already did.
The clients are fakes whose futures complete only when the test says so (an unanswered
future is a lost reply).
"""
from lifecycle_msgs.msg import State, Transition
from rclpy.task import Future

from adcs_nodes.tools.run.launcher.lifecycle import Transitions as _Transitions


class _Client:
    def __init__(self, service):
        self.service, self.sent = service, []

    def service_is_ready(self):
        return True

    def call_async(self, request):
        future = Future()
        self.sent.append((request, future))
        return future


class _Node:
    def __init__(self):
        self.clients = {}

    def create_client(self, _srv, service):
        self.clients[service] = _Client(service)
        return self.clients[service]


def _answer_change(future, success=True):
    from lifecycle_msgs.srv import ChangeState
    response = ChangeState.Response()
    response.success = success
    future.set_result(response)


def _answer_state(future, state_id):
    from lifecycle_msgs.srv import GetState
    response = GetState.Response()
    response.current_state.id = state_id
    future.set_result(response)


def _driver():
    node = _Node()
    tr = _Transitions(node, ['guidance'], deadline_s=60.0)
    tr.RESEND_S = 0.0          # any unanswered request counts as lost at the next poll
    return node, tr


def test_answers_drive_configure_then_activate():
    node, tr = _driver()
    change = node.clients['/guidance/change_state']
    assert tr.poll() is None
    (req, fut), = change.sent
    assert req.transition.id == Transition.TRANSITION_CONFIGURE
    _answer_change(fut)
    assert change.sent[1][0].transition.id == Transition.TRANSITION_ACTIVATE
    _answer_change(change.sent[1][1])
    assert not tr.pending and tr.step['guidance'] == 'active'


def test_lost_configure_answer_asks_state_and_activates_without_reconfiguring():
    node, tr = _driver()
    change = node.clients['/guidance/change_state']
    tr.poll()                                   # configure sent; its answer is lost
    late_configure = change.sent[0][1]
    tr.poll()                                   # no answer within RESEND_S: ask the state
    get = node.clients['/guidance/get_state']
    assert len(get.sent) == 1 and tr.resent['guidance'] == 1
    _answer_state(get.sent[0][1], State.PRIMARY_STATE_INACTIVE)   # it did configure
    ids = [r.transition.id for r, _ in change.sent]
    assert ids == [Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE]
    _answer_change(late_configure)              # a late, superseded answer changes nothing
    assert len(change.sent) == 2
    _answer_change(change.sent[1][1])
    assert tr.step['guidance'] == 'active' and not tr.failed


def test_lost_request_is_sent_again_when_the_node_is_still_unconfigured():
    node, tr = _driver()
    change = node.clients['/guidance/change_state']
    tr.poll()
    tr.poll()
    _answer_state(node.clients['/guidance/get_state'].sent[0][1],
                  State.PRIMARY_STATE_UNCONFIGURED)
    ids = [r.transition.id for r, _ in change.sent]
    assert ids == [Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_CONFIGURE]


def test_node_found_active_is_done_and_a_transitioning_state_is_asked_again():
    node, tr = _driver()
    tr.poll()
    tr.poll()
    get = node.clients['/guidance/get_state']
    _answer_state(get.sent[0][1], State.TRANSITION_STATE_CONFIGURING)
    assert tr.step['guidance'] == 'get_state'    # still under way: nothing sent
    tr.poll()                                     # asked again
    assert len(get.sent) == 2
    _answer_state(get.sent[1][1], State.PRIMARY_STATE_ACTIVE)
    assert not tr.pending


def test_refused_transition_is_reported_and_deadline_still_holds():
    node, tr = _driver()
    tr.poll()
    _answer_change(node.clients['/guidance/change_state'].sent[0][1], success=False)
    assert tr.poll() == ('guidance', 'configure')
    node2, tr2 = _Node(), None
    tr2 = _Transitions(node2, ['estimator'], deadline_s=-1.0)
    assert tr2.poll() == ('estimator', 'deadline')
