"""adcs/slew action server: goal checks, success with result numbers, preemption, cancel.

One executor for the whole test: the server's execute coroutine lives on the executor that
accepted the goal (the conftest ``spin`` fixture makes a new executor per call)."""
import math
import time

import numpy as np
import pytest
import rclpy
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient
from scipy.spatial.transform import Rotation, Slerp

from adcs_msgs.action import Slew
from adcs_msgs.msg import ActuatorCommand, AttitudeState
from adcs_nodes.msgs.fields import to_quat, to_stamp, to_vec3
from adcs_nodes.nodes.slew_action import SlewActionServer, check_goal
from adcs_nodes.tools.run.slew import goal_quaternion, make_goal

KNOWN = ['fuzzy', 'reference_slew']


def test_check_goal_reasons():
    q = [0.0, 0.0, 0.0, 1.0]
    assert check_goal(q, 'orbit', '', KNOWN) == ''
    assert check_goal(q, '', 'fuzzy', KNOWN) == ''
    assert 'not unit' in check_goal([0, 0, 0, 1.1], 'orbit', '', KNOWN)
    assert 'NaN' in check_goal([math.nan, 0, 0, 1], 'orbit', '', KNOWN)
    assert 'unknown controller' in check_goal(q, 'orbit', 'pid', KNOWN)
    assert 'unknown frame' in check_goal(q, 'body', '', KNOWN)
    assert 'cannot switch' in check_goal(q, 'orbit', 'fuzzy', KNOWN, can_switch=False)
    assert 'timeout_s' in check_goal(q, 'orbit', '', KNOWN, timeout_s=-1.0)


class Plant:
    """Fake estimator + manager: the attitude moves toward the last target (0.1 s per tick)."""

    def __init__(self, node, q0):
        self.node = node
        self.q = np.asarray(q0, dtype=float)
        self.target = None
        self.targets = []
        self.t = 0.0
        self.moving = True
        self.est_pub = node.create_publisher(AttitudeState, 'adcs/attitude_estimate', 10)
        self.cmd_pub = node.create_publisher(ActuatorCommand, 'adcs/actuator_command', 10)
        node.create_timer(0.005, self.tick)

    def set_target(self, q, frame):
        self.target = np.asarray(q, dtype=float)
        self.targets.append((self.target.copy(), frame))

    def tick(self):
        self.t += 0.1
        if self.moving and self.target is not None:
            rots = Rotation.from_quat([self.q, self.target])
            self.q = Slerp([0.0, 1.0], rots)(0.1).as_quat()
        w = np.zeros(3) if not self.moving else np.array([0.0, 0.0, 1e-5])
        msg = AttitudeState()
        msg.header.stamp = to_stamp(int(round(self.t * 1e9)))
        msg.q_orbit_body = to_quat(self.q)
        msg.q_eci_body = to_quat(self.q)
        msg.omega_body_orbit_body = to_vec3(w)
        msg.omega_body_eci_body = to_vec3(w)
        self.est_pub.publish(msg)
        cmd = ActuatorCommand()
        cmd.header.stamp = msg.header.stamp
        cmd.torque_body = to_vec3([0.5, -0.25, 0.0])
        self.cmd_pub.publish(cmd)


@pytest.fixture
def spin(ros_context):
    """``spin(nodes, until, timeout)`` on ONE executor (nodes added on first use)."""
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor(context=ros_context)
    added = set()

    def _spin(nodes, until, timeout=30.0):
        for n in nodes:
            if id(n) not in added:
                ex.add_node(n)
                added.add(id(n))
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.01)
            if until():
                return True
        return False

    yield _spin
    ex.shutdown()


@pytest.fixture
def graph(ros_context):
    host = rclpy.create_node('host', context=ros_context)
    probe = rclpy.create_node('probe', context=ros_context)
    plant = Plant(probe, Rotation.from_euler('ZYX', [30, 0, 0], degrees=True).as_quat())
    switched = []
    server = SlewActionServer(host, plant.set_target,
                              switch_controller=lambda n: (switched.append(n) or True, 'ok'),
                              known_controllers=KNOWN, default_tolerance_deg=0.05,
                              rate_tolerance_deg_s=0.01, hold_s=0.5)
    client = ActionClient(probe, Slew, 'adcs/slew')
    yield host, probe, plant, server, client, switched
    client.destroy()
    host.destroy_node()
    probe.destroy_node()


def _send(spin, nodes, client, goal, feedback=None):
    assert spin(nodes, client.server_is_ready)
    fut = client.send_goal_async(goal, feedback_callback=feedback)
    assert spin(nodes, fut.done)
    return fut.result()


def test_bad_goals_are_rejected(graph, spin):
    host, probe, plant, server, client, _ = graph
    nodes = [host, probe]
    for goal in (make_goal([0, 0, 0, 1.2], 'orbit'), make_goal([math.nan, 0, 0, 1], 'orbit'),
                 make_goal([0, 0, 0, 1], 'orbit', controller='pid')):
        assert not _send(spin, nodes, client, goal).accepted
    assert plant.targets == []                  # nothing was commanded


def test_goal_reaches_target_with_result_numbers(graph, spin):
    host, probe, plant, server, client, switched = graph
    nodes = [host, probe]
    fbs = []
    q_goal = goal_quaternion(0.0, 0.0, 0.0)
    handle = _send(spin, nodes, client, make_goal(q_goal, 'inertial', 'fuzzy'),
                   lambda m: fbs.append(m.feedback))
    assert handle.accepted
    res = handle.get_result_async()
    assert spin(nodes, res.done, timeout=60.0)
    out = res.result()
    assert out.status == GoalStatus.STATUS_SUCCEEDED and out.result.success
    assert plant.targets[0][1] == 'eci'
    np.testing.assert_allclose(plant.targets[0][0], q_goal)
    assert switched == ['fuzzy']
    assert out.result.final_error_deg < 0.05
    # Independent: the angle decays by 0.9 per 0.1 s tick from 30 deg; the 5 % band (1.5 deg)
    # is entered after ceil(log(0.05)/log(0.9)) = 29 ticks.
    assert out.result.settling_time_s == pytest.approx(2.8, abs=0.15)
    # Energy: sum |M_i| = 0.75 N m over the elapsed time (zero-order hold).
    assert out.result.energy_nms == pytest.approx(0.75 * out.result.elapsed_s, abs=0.2)
    assert fbs and fbs[0].angle_to_go_deg > fbs[-1].angle_to_go_deg


def test_new_goal_preempts_and_cancel_holds(graph, spin):
    host, probe, plant, server, client, _ = graph
    nodes = [host, probe]
    plant.moving = False                        # the plant does not reach anything
    first = _send(spin, nodes, client, make_goal(goal_quaternion(10, 0, 0), 'orbit'))
    assert first.accepted
    spin(nodes, lambda: False, timeout=0.3)
    second = _send(spin, nodes, client, make_goal(goal_quaternion(0, 20, 0), 'orbit'))
    assert second.accepted
    r1 = first.get_result_async()
    assert spin(nodes, r1.done)
    assert r1.result().status == GoalStatus.STATUS_ABORTED
    assert r1.result().result.message == 'preempted'
    np.testing.assert_allclose(plant.targets[-1][0], goal_quaternion(0, 20, 0))
    cancel = second.cancel_goal_async()
    assert spin(nodes, cancel.done)
    r2 = second.get_result_async()
    assert spin(nodes, r2.done)
    assert r2.result().status == GoalStatus.STATUS_CANCELED
    assert 'holding' in r2.result().result.message
    q_hold, frame = plant.targets[-1]
    assert frame == 'orbit'
    assert abs(float(np.dot(q_hold, plant.q))) == pytest.approx(1.0, abs=1e-9)
