"""Service and action calls of ``adcs switch``, ``adcs slew`` and the launcher survive a
dropped answer (issue 20: under load Fast DDS now and then loses a service reply).

Each test drops the first answer on purpose (the server did the work, the client never hears
it) and the call still succeeds, without doing the work twice where that matters (one slew
goal, not two)."""
import threading
import time

import pytest
import rclpy
from rclpy.action import ActionClient, ActionServer
from rclpy.executors import SingleThreadedExecutor

from adcs_msgs.action import Slew


class _Spinner:
    """Spin ``nodes`` on their own executor in a thread (the server side of a test)."""

    def __init__(self, context, *nodes):
        self.executor = SingleThreadedExecutor(context=context)
        for n in nodes:
            self.executor.add_node(n)
        self._stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self._stop:
            self.executor.spin_once(timeout_sec=0.02)

    def close(self):
        self._stop = True
        self.thread.join(5.0)
        self.executor.shutdown()


def _drop_first_response(srv, dropped):
    """Make service ``srv`` skip its first answer (the callback still ran)."""
    send = srv.send_response

    def send_response(response, header):
        if not dropped:
            dropped.append(header)
            return
        send(response, header)
    srv.send_response = send_response


def test_adcs_switch_call_survives_a_dropped_answer(ros_context):
    import os

    from adcs_msgs.srv import SwitchController
    from adcs_nodes.tools.run.live import _Session
    server = rclpy.create_node('controller_manager', context=ros_context)
    requests, dropped = [], []

    def switch(request, response):
        requests.append(request.name)             # idempotent: the same name, same answer
        response.success, response.active = True, request.name
        response.message = f'switching to {request.name}'
        return response
    srv = server.create_service(SwitchController, '/adcs/switch_controller', switch)
    _drop_first_response(srv, dropped)
    spinner = _Spinner(ros_context, server)
    session = _Session({'domain': int(os.environ['ROS_DOMAIN_ID'])}, deadline=False)
    try:
        res = session.call(SwitchController, '/adcs/switch_controller',
                           SwitchController.Request(name='bdot'), timeout_s=30.0)
    finally:
        session.close()
        spinner.close()
        server.destroy_node()
    assert res.success and res.active == 'bdot'
    assert len(dropped) == 1 and len(requests) >= 2 and set(requests) == {'bdot'}


def _slew_server(context, goals):
    node = rclpy.create_node('guidance', context=context)

    def on_goal(goal):
        from rclpy.action import GoalResponse
        goals.append(goal)
        return GoalResponse.ACCEPT

    def execute(handle):
        time.sleep(0.3)
        handle.succeed()
        result = Slew.Result()
        result.message = 'reached'
        result.settling_time_s = 1.5
        return result
    server = ActionServer(node, Slew, 'adcs/slew', execute, goal_callback=on_goal)
    return node, server


@pytest.mark.parametrize('drop', [('goal',), ('result',), ('goal', 'result')])
def test_adcs_slew_survives_dropped_goal_and_result_answers(ros_context, monkeypatch, drop):
    """The client never hears the first goal answer and/or the first result answer: it sends
    the same goal id again (the server refuses the duplicate, so one slew runs) and asks for
    the result again; the call succeeds."""
    from adcs_nodes.tools.run.slew import make_goal, run_goal
    dropped = []
    execute = ActionClient.execute

    async def lossy_execute(self, taken_data):
        for key in drop:
            if key in taken_data and key not in dropped:
                dropped.append(key)
                taken_data = {k: v for k, v in taken_data.items() if k != key}
        await execute(self, taken_data)
    monkeypatch.setattr(ActionClient, 'execute', lossy_execute)
    goals = []
    server_node, server = _slew_server(ros_context, goals)
    spinner = _Spinner(ros_context, server_node)
    client_node = rclpy.create_node('adcs_cli', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(client_node)
    try:
        status, result = run_goal(client_node, executor, make_goal([0, 0, 0, 1], 'orbit'),
                                  server_wait_s=30.0, deadline_s=60.0, answer_s=1.0)
    finally:
        executor.shutdown()
        client_node.destroy_node()
        spinner.close()
        server.destroy()
        server_node.destroy_node()
    assert (status, result.message) == ('succeeded', 'reached')
    assert sorted(dropped) == sorted(drop)
    assert len(goals) == 1          # the resent goal was a duplicate: one slew, not two


def test_a_refused_goal_is_still_refused(ros_context):
    from rclpy.action import GoalResponse

    from adcs_nodes.tools.run.slew import make_goal, run_goal
    server_node = rclpy.create_node('guidance', context=ros_context)
    server = ActionServer(server_node, Slew, 'adcs/slew', lambda h: Slew.Result(),
                          goal_callback=lambda g: GoalResponse.REJECT)
    spinner = _Spinner(ros_context, server_node)
    client_node = rclpy.create_node('adcs_cli', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(client_node)
    try:
        status, _ = run_goal(client_node, executor, make_goal([0, 0, 0, 1], 'orbit'),
                             server_wait_s=30.0, deadline_s=10.0, answer_s=1.0)
    finally:
        executor.shutdown()
        client_node.destroy_node()
        spinner.close()
        server.destroy()
        server_node.destroy_node()
    assert status == 'rejected'


def test_launcher_lifecycle_driver_survives_a_dropped_answer(ros_context):
    """A node whose first ``change_state`` answer is lost (it did configure) is asked its
    state, then activated: the launcher's driver ends with the node active."""
    from lifecycle_msgs.msg import State, Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    from adcs_nodes.tools.run.launcher.lifecycle import Transitions as _Transitions
    node = rclpy.create_node('estimator', context=ros_context)
    state = {'id': State.PRIMARY_STATE_UNCONFIGURED}
    done, dropped = [], []

    def change(request, response):
        done.append(request.transition.id)
        nxt = {Transition.TRANSITION_CONFIGURE: State.PRIMARY_STATE_INACTIVE,
               Transition.TRANSITION_ACTIVATE: State.PRIMARY_STATE_ACTIVE}
        state['id'] = nxt[request.transition.id]
        response.success = True
        return response

    def get(request, response):
        response.current_state.id = state['id']
        return response
    _drop_first_response(node.create_service(ChangeState, '/estimator/change_state', change),
                         dropped)
    node.create_service(GetState, '/estimator/get_state', get)
    spinner = _Spinner(ros_context, node)
    launcher = rclpy.create_node('adcs_launcher', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(launcher)
    tr = _Transitions(launcher, ['estimator'], deadline_s=60.0)
    tr.RESEND_S = 1.0
    try:
        end = time.monotonic() + 60.0
        while tr.pending and time.monotonic() < end:
            assert tr.poll() is None
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        launcher.destroy_node()
        spinner.close()
        node.destroy_node()
    assert tr.step['estimator'] == 'active'
    assert len(dropped) == 1 and tr.resent['estimator'] >= 1
    assert done == [Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE]
