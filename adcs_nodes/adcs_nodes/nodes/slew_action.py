"""Action server ``adcs/slew`` (``adcs_msgs/action/Slew``): slew to an attitude and hold it.

A reusable class, :class:`SlewActionServer`, hosted by any node (the guidance node, or the
small :class:`SlewActionNode` here). The host passes a callback that sets the guidance target;
the server never commands actuators itself: the active controller (e.g. ``fuzzy``, paper 003)
does the slew toward the target that guidance publishes.

Behaviour
---------
* **Goal check** (:func:`check_goal`, public so that ``adcs slew`` gives the same reason up
  front): a quaternion not finite or not unit (1e-3), a frame not ``orbit``/``eci``, an
  unknown controller, a bad tolerance or timeout, or no way to switch: rejected, logged.
* **Accepted**: the server sets the target (``set_target(q_xyzw, frame)``), switches the
  controller if one is named (``switch_controller(name) -> (ok, message)``), and follows the
  attitude estimate ``adcs/attitude_estimate`` (``AttitudeState``): feedback per estimate with
  the angle to go, the rate relative to the target frame, the elapsed sim time.
* **Done** when the angle to go is below ``tolerance_deg`` and the rate below
  ``rate_tolerance_deg_s`` for ``hold_s`` of sim time: succeeded. The result carries the
  settling time (paper 003 definition: first time after which the angle stays within 5 % of the
  initial angle, up to the end), the energy ``int sum_i |M_i| dt`` of the commanded torque from
  ``adcs/actuator_command`` (``torque_body`` plus the wheel motor torques, zero-order hold) and
  the final error.
* **New goal** while one runs: the running goal is aborted with ``message = 'preempted'``; the
  new target replaces it.
* **Cancel**: the target becomes the current attitude estimate (hold where it is), the goal
  ends as canceled with ``message = 'canceled: holding attitude'``.
* **Timeout** (sim time): aborted, ``message = 'timeout ...'``; the target stays.
* Estimate lost (no message): the goal simply waits (the timeout is in sim time, so a stopped
  simulation does not abort it).
"""
from __future__ import annotations

import math
import threading
from typing import Callable, Iterable, Optional, Tuple

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future

from adcs_msgs.action import Slew
from adcs_msgs.msg import ActuatorCommand, AttitudeState, AttitudeTarget
from adcs_nodes.core import attitude
from adcs_nodes.msgs.fields import quat, stamp_ns, to_quat, to_vec3, vec3
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.adapter import QOS_DATA, QOS_LATCHED

ACTION_NAME = 'adcs/slew'
FRAMES = ('orbit', 'eci')
#: Accepted deviation of the goal quaternion's norm from 1.
UNIT_TOLERANCE = 1e-3

SetTarget = Callable[[np.ndarray, str], None]
SwitchController = Callable[[str], Tuple[bool, str]]


def check_goal(q_xyzw, frame: str, controller: str, known_controllers: Iterable[str],
               tolerance_deg: float = 0.0, timeout_s: float = 0.0,
               can_switch: bool = True) -> str:
    """Why a slew goal is refused ('' when it is acceptable): ``q_xyzw`` (4,) the target,
    scalar last, body -> ``frame`` ('orbit', 'eci', '' = orbit); ``controller`` to switch to
    ('' none) among ``known_controllers``; ``tolerance_deg`` [deg], ``timeout_s`` [s] (0: the
    server's default); ``can_switch``: whether the host can switch controllers."""
    try:
        q = np.asarray(q_xyzw, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return 'target quaternion is not numeric'
    if q.shape != (4,):
        return f'target quaternion must have 4 components, got {q.size}'
    if not np.all(np.isfinite(q)):
        return 'target quaternion has NaN or infinite components'
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > UNIT_TOLERANCE:
        return f'target quaternion is not unit (norm {n:.6g})'
    if frame not in FRAMES + ('',):
        return f'unknown frame {frame[:40]!r}; use one of {", ".join(FRAMES)}'
    for name, value in (('tolerance_deg', tolerance_deg), ('timeout_s', timeout_s)):
        if not (math.isfinite(value) and value >= 0.0):
            return f'{name} must be finite and >= 0, got {value}'
    if controller:
        known = list(known_controllers)
        if controller not in known:
            return f'unknown controller {controller[:40]!r}; known: {", ".join(known)}'
        if not can_switch:
            return 'this server cannot switch controllers; leave controller empty'
    return ''


class SlewProgress:
    """Bookkeeping of one slew (pure: no ROS; sim seconds) toward ``q_target`` (4,) in the
    goal frame: done when ``angle < tolerance_rad`` and ``rate < rate_tolerance_rad_s`` for
    ``hold_s``; ``band``: the settling band, a fraction of the initial angle (paper 003: 5 %)."""

    def __init__(self, q_target, tolerance_rad: float, rate_tolerance_rad_s: float,
                 hold_s: float, band: float = 0.05) -> None:
        self.q_target = attitude.normalize(q_target)
        self.tol = tolerance_rad
        self.rate_tol = rate_tolerance_rad_s
        self.hold_s = hold_s
        self.band = band
        self.t0: Optional[float] = None
        self.angle0 = float('nan')
        self.angle = float('nan')
        self.rate = float('nan')
        self.t = float('nan')
        self.last_outside: Optional[float] = None   # last time outside the settling band
        self.inside_since: Optional[float] = None   # start of the current in-tolerance run
        self.energy = 0.0
        self._torque_t: Optional[float] = None
        self._torque_sum = 0.0

    def update(self, t: float, q_frame_body, omega_rel_body) -> None:
        """New estimate at ``t``: attitude in the goal frame, rate relative to it [rad/s]."""
        self.t = t
        self.angle = attitude.angle_between(q_frame_body, self.q_target)
        self.rate = float(np.linalg.norm(omega_rel_body))
        if self.t0 is None:
            self.t0, self.angle0 = t, self.angle
        if self.angle > self.band * self.angle0:
            self.last_outside = t
        ok = self.angle < self.tol and self.rate < self.rate_tol
        if not ok:
            self.inside_since = None
        elif self.inside_since is None:
            self.inside_since = t

    def add_torque(self, t: float, sum_abs_torque: float) -> None:
        """Commanded ``sum_i |M_i|`` [N m] from ``t`` on (zero-order hold)."""
        if self._torque_t is not None and self.t0 is not None and t > self._torque_t:
            start = max(self._torque_t, self.t0)
            if t > start:
                self.energy += self._torque_sum * (t - start)
        self._torque_t, self._torque_sum = t, sum_abs_torque

    @property
    def elapsed(self) -> float:
        return 0.0 if self.t0 is None else self.t - self.t0

    def done(self) -> bool:
        return self.inside_since is not None and self.t - self.inside_since >= self.hold_s

    def settling_time(self) -> float:
        """Sim time from the start until the angle stayed within the band (-1: never)."""
        if self.t0 is None or self.angle > self.band * self.angle0:
            return -1.0
        if self.last_outside is None:
            return 0.0
        return self.last_outside - self.t0


def _state_in_frame(msg: AttitudeState, frame: str):
    """``(q_frame_body, omega_body_frame_body)`` of an estimate, or None if not usable."""
    if frame == 'eci':
        q, w = quat(msg.q_eci_body), vec3(msg.omega_body_eci_body)
    else:
        q, w = quat(msg.q_orbit_body), vec3(msg.omega_body_orbit_body)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(w))) or np.linalg.norm(q) < 1e-6:
        return None
    return attitude.normalize(q), w


class SlewActionServer:
    """The ``adcs/slew`` action server, hosted by ``node`` (see the module docstring).

    ``set_target(q_xyzw (4,), frame)`` makes guidance hold that attitude;
    ``switch_controller(name) -> (ok, message)`` (without it, goals naming a controller are
    rejected); ``known_controllers`` default to every registered one; the done criterion and
    timeout defaults are in sim time.
    """

    def __init__(self, node: Node, set_target: SetTarget,
                 switch_controller: Optional[SwitchController] = None,
                 known_controllers: Optional[Iterable[str]] = None,
                 default_tolerance_deg: float = 0.1, rate_tolerance_deg_s: float = 0.01,
                 hold_s: float = 1.0, default_timeout_s: float = 600.0,
                 estimate_topic: str = 'adcs/attitude_estimate',
                 command_topic: str = 'adcs/actuator_command',
                 action_name: str = ACTION_NAME) -> None:
        if known_controllers is None:
            from adcs_nodes import registry
            known_controllers = registry.names('controller')
        self.node = node
        self.set_target = set_target
        self.switch_controller = switch_controller
        self.known = list(known_controllers)
        self.tol_deg = float(default_tolerance_deg)
        self.rate_tol = math.radians(float(rate_tolerance_deg_s))
        self.hold_s = float(hold_s)
        self.timeout_s = float(default_timeout_s)
        self._lock = threading.Lock()
        self._goal = None                 # the active ServerGoalHandle
        self._progress: Optional[SlewProgress] = None
        self._frame = 'orbit'
        self._last_estimate: Optional[AttitudeState] = None
        self._waiters: list = []
        # A LockstepNode host registers the subscriptions for its start-up handshake
        # (``subscription``); a plain Node creates them directly.
        subscribe = getattr(node, 'subscription', None)
        if subscribe is None:
            def subscribe(msg_type, topic, callback):
                return node.create_subscription(msg_type, topic, callback, QOS_DATA)
        subscribe(AttitudeState, estimate_topic, self._on_estimate)
        subscribe(ActuatorCommand, command_topic, self._on_command)
        self.server = ActionServer(node, Slew, action_name, execute_callback=self._execute,
                                   goal_callback=self._on_goal,
                                   handle_accepted_callback=self._on_accepted,
                                   cancel_callback=self._on_cancel)

    # ------------------------------------------------------------------ callbacks
    def _on_goal(self, goal: Slew.Goal) -> GoalResponse:
        q = [goal.q_target.x, goal.q_target.y, goal.q_target.z, goal.q_target.w]
        reason = check_goal(q, goal.frame, goal.controller, self.known, goal.tolerance_deg,
                            goal.timeout_s, self.switch_controller is not None)
        if reason:
            self.node.get_logger().warning(f'slew goal rejected: {reason}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_accepted(self, goal_handle) -> None:
        with self._lock:
            if self._goal is not None and self._goal.is_active:
                self.node.get_logger().info('slew goal preempted by a new goal')
                self._goal.abort()
                self._wake()
            self._goal = goal_handle
        goal_handle.execute()

    def _on_cancel(self, _goal_handle) -> CancelResponse:
        self._wake()              # act without waiting for the next estimate
        return CancelResponse.ACCEPT

    def _wake(self, msg: Optional[AttitudeState] = None) -> None:
        waiters, self._waiters = self._waiters, []
        for fut in waiters:
            if not fut.done():
                fut.set_result(msg)

    def _on_estimate(self, msg: AttitudeState) -> None:
        self._last_estimate = msg
        self._wake(msg)

    def _on_command(self, msg: ActuatorCommand) -> None:
        progress = self._progress
        if progress is None:
            return
        values = [msg.torque_body.x, msg.torque_body.y, msg.torque_body.z] + list(
            msg.wheel_torque)
        total = float(np.sum(np.abs(values)))
        if math.isfinite(total):
            progress.add_torque(stamp_ns(msg.header.stamp) * 1e-9, total)

    # ------------------------------------------------------------------ execution
    async def _next_estimate(self) -> Optional[AttitudeState]:
        """The next estimate (None when woken by a cancel or a preemption)."""
        fut = Future()
        self._waiters.append(fut)
        return await fut

    def _hold_current(self, frame: str) -> bool:
        est = self._last_estimate
        state = None if est is None else _state_in_frame(est, frame)
        if state is None:
            return False
        self.set_target(state[0], frame)
        return True

    def _result(self, progress: SlewProgress, success: bool, message: str) -> Slew.Result:
        res = Slew.Result()
        res.success = success
        res.message = message
        res.settling_time_s = float(progress.settling_time())
        res.energy_nms = float(progress.energy)
        res.final_error_deg = float(math.degrees(progress.angle)) if math.isfinite(
            progress.angle) else -1.0
        res.elapsed_s = float(progress.elapsed)
        return res

    async def _execute(self, goal_handle) -> Slew.Result:
        goal = goal_handle.request
        frame = goal.frame or 'orbit'
        q = attitude.normalize([goal.q_target.x, goal.q_target.y, goal.q_target.z,
                                goal.q_target.w])
        tol = math.radians(goal.tolerance_deg or self.tol_deg)
        timeout = goal.timeout_s or self.timeout_s
        progress = SlewProgress(q, tol, self.rate_tol, self.hold_s)
        self._progress = progress
        self.set_target(q, frame)
        if goal.controller:
            ok, message = self.switch_controller(goal.controller)
            if not ok:
                goal_handle.abort()
                return self._result(progress, False, f'controller switch refused: {message}')
        feedback = Slew.Feedback()
        while True:
            msg = await self._next_estimate()
            if not goal_handle.is_active:                 # aborted by a newer goal
                return self._result(progress, False, 'preempted')
            if goal_handle.is_cancel_requested:
                held = self._hold_current(frame)
                goal_handle.canceled()
                return self._result(progress, False, 'canceled: holding attitude' if held
                                    else 'canceled: no estimate to hold, target unchanged')
            state = None if msg is None else _state_in_frame(msg, frame)
            if state is None:
                continue
            progress.update(stamp_ns(msg.header.stamp) * 1e-9, state[0], state[1])
            feedback.angle_to_go_deg = math.degrees(progress.angle)
            feedback.rate_deg_s = math.degrees(progress.rate)
            feedback.elapsed_s = progress.elapsed
            goal_handle.publish_feedback(feedback)
            if progress.done():
                goal_handle.succeed()
                return self._result(progress, True, 'reached')
            if progress.elapsed > timeout:
                goal_handle.abort()
                return self._result(progress, False, f'timeout after {timeout:g} s (sim time)')


class SlewActionNode(Node):
    """Stand-alone host: serves ``adcs/slew`` and publishes each new target on ``target_topic``
    (``AttitudeTarget``, latched) for a guidance node that does not host the server itself."""

    def __init__(self, name: str = 'slew_action', target_topic: str = 'adcs/slew/target',
                 **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.target_pub = self.create_publisher(AttitudeTarget, target_topic, QOS_LATCHED)
        self.slew = SlewActionServer(self, self.publish_target)

    def publish_target(self, q_xyzw: np.ndarray, frame: str) -> None:
        """Publish a hold target (zero rate) in ``frame``."""
        msg = AttitudeTarget()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = frame
        msg.q_ref_body = to_quat(q_xyzw)
        msg.omega_body_ref_body = to_vec3(np.zeros(3))
        msg.omega_dot_body_ref_body = to_vec3(np.zeros(3))
        msg.profile = 'hold'
        self.target_pub.publish(msg)


def main(args=None) -> int:
    """``ros2 run adcs_nodes slew_action`` (stand-alone host)."""
    return runtime.run(SlewActionNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
