"""The launcher's self-healing decisions before frame 0 (issue 20), without ROS processes:
which node is restarted when the start handshake is stuck, who goes with it, when the run
fails instead, and the lifecycle driver's 'unanswered' verdict and reset after a restart.
The launched version (a node that never matches, restarted once): tests/graph/
test_self_healing.py."""
import time

from adcs_nodes.tools.run.launcher.healing import heal_decision, restart_plan
from adcs_nodes.tools.run.launcher.lifecycle import Transitions as _Transitions

NODES = ['environment', 'dynamics', 'magnetometer', 'estimator', 'guidance',
         'magnetic_controller', 'controller_manager', 'recorder']
GUARDS = {'environment': ['dynamics'], 'controller_manager': ['dynamics'],
          'magnetic_controller': ['controller_manager']}


def _decide(ready, waiting, restarts=None, wait_s=30.0):
    return heal_decision(NODES, ready, waiting, 'dynamics', restarts or {}, GUARDS, wait_s, 1)


def test_nothing_while_a_node_is_still_starting_or_not_long_stuck():
    ready = set(NODES) - {'guidance', 'dynamics'}
    assert _decide(ready, {}) is None                       # no handshake line yet
    assert _decide(ready, {'guidance': (20.0, 'sub:/clock 0/1 (discovery knows 0)'),
                           'dynamics': (40.0, 'pub:/clock 7/8')}) is None
    assert _decide(set(NODES), {}) is None                  # everyone ready: frame 0 is due


def test_the_stuck_node_is_restarted_not_the_clock_master():
    ready = set(NODES) - {'guidance', 'dynamics'}
    verdict = _decide(ready, {'guidance': (30.0, 'sub:/clock 0/1 (discovery knows 0)'),
                              'dynamics': (30.0, 'pub:/clock 7/8 (discovery knows 7)')})
    assert verdict[0] == 'restart'
    assert [n for n, _ in verdict[1]] == ['guidance']
    assert 'sub:/clock 0/1 (discovery knows 0)' in verdict[1][0][1]


def test_the_master_alone_stuck_is_restarted():
    ready = set(NODES) - {'dynamics'}
    verdict = _decide(ready, {'dynamics': (30.0, 'pub:/clock 7/8 (discovery knows 8)')})
    assert [n for n, _ in verdict[1]] == ['dynamics']


def test_a_ready_guard_and_then_the_master_go_with_a_restarted_producer():
    # the manager said ready (locked the controller's publisher), the controller did not
    ready = set(NODES) - {'magnetic_controller', 'dynamics'}
    verdict = _decide(ready, {'magnetic_controller': (31.0, 'sub:/clock 0/1'),
                              'dynamics': (31.0, 'pub:/clock 7/8')})
    assert [n for n, _ in verdict[1]] == ['magnetic_controller', 'controller_manager',
                                          'dynamics']
    # a guard that is not ready yet locks at its own handshake: not restarted
    assert restart_plan([('environment', 'x')], set(NODES) - {'environment', 'dynamics'},
                        'dynamics', GUARDS) == [('environment', 'x')]


def test_stuck_again_after_its_restart_fails_with_the_reason():
    ready = set(NODES) - {'guidance', 'dynamics'}
    verdict = _decide(ready, {'guidance': (30.0, 'sub:/clock 0/1 (discovery knows 0)'),
                              'dynamics': (30.0, 'pub:/clock 7/8')}, restarts={'guidance': 1})
    assert verdict == ('fail', 'guidance', 'node guidance still has unmatched endpoints after '
                       '1 restart(s) before frame 0: sub:/clock 0/1 (discovery knows 0)')


class _Future:
    """A request that is never answered (no rclpy in the unit tier)."""

    def add_done_callback(self, callback):
        pass


class _Client:
    def __init__(self):
        self.sent = []

    def service_is_ready(self):
        return True

    def call_async(self, request):
        self.sent.append(_Future())
        return self.sent[-1]


class _Node:
    def create_client(self, _srv, _name):
        return _Client()


def test_unanswered_lifecycle_requests_are_reported_and_a_reset_starts_again():
    tr = _Transitions(_Node(), ['estimator'], deadline_s=600.0)
    tr.RESEND_S = 0.0
    tr.unanswered_s = 0.2
    assert tr.poll() is None and tr.step['estimator'] == 'configure'
    time.sleep(0.3)
    assert tr.poll() == ('estimator', 'unanswered')      # configure, get_state: no answer
    tr.reset('estimator')
    assert tr.step['estimator'] == 'starting'
    assert tr.poll() is None and tr.step['estimator'] == 'configure'


def test_an_unanswered_node_that_uses_cpu_is_waited_for_an_idle_one_restarted(monkeypatch):
    """A node configuring (or compiling a kernel) keeps its executor busy and answers
    nothing: it is given more time. One that used no CPU in the window is restarted."""
    from types import SimpleNamespace

    from adcs_nodes.tools.run.launcher import healing, processes
    cpu = {'t': 10.0}
    monkeypatch.setattr(processes, 'cpu_seconds', lambda pid: cpu['t'])
    lines, restarted = [], []
    procs = SimpleNamespace(procs={'estimator': SimpleNamespace(pid=1)})
    healer = healing.Healer([], procs, 'dynamics', lambda name, note: restarted.append(name),
                            lines.append)
    transitions = _Transitions(_Node(), ['estimator'], deadline_s=600.0)
    monitor = SimpleNamespace(ready=set())
    assert healer.lifecycle(monitor, transitions, 'estimator') is None    # window starts
    cpu['t'] = 13.0                                                        # 3 s of CPU: busy
    assert healer.lifecycle(monitor, transitions, 'estimator') is None and not restarted
    assert 'is busy (3.0 s CPU' in lines[-1]
    assert healer.lifecycle(monitor, transitions, 'estimator') is None    # a new window
    assert healer.lifecycle(monitor, transitions, 'estimator') is None    # no CPU: stuck
    assert restarted == ['estimator']
    healer.lifecycle(monitor, transitions, 'estimator')
    assert healer.lifecycle(monitor, transitions, 'estimator') == ('estimator', 'unanswered')


def test_cpu_seconds_of_this_process():
    import os

    from adcs_nodes.tools.run.launcher.processes import cpu_seconds as _cpu_seconds
    t0 = _cpu_seconds(os.getpid())
    end = time.process_time() + 0.2
    while time.process_time() < end:
        pass
    assert _cpu_seconds(os.getpid()) - t0 >= 0.1
    assert _cpu_seconds(2 ** 22 + 12345) is None
