"""Client of the ``adcs/slew`` action: :func:`slew` (``adcs slew``), :func:`run_goal`."""
from __future__ import annotations

import math
import time
from typing import Callable, Optional, Sequence

import numpy as np

from adcs_nodes.core import attitude
from adcs_nodes.tools.run.live import SERVER_WAIT_S

#: CLI frame names -> goal frame names.
FRAME_NAMES = {'inertial': 'eci', 'eci': 'eci', 'orbit': 'orbit'}


def goal_quaternion(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """``q_frame_body`` (scalar last) of 3-2-1 angles [deg]: yaw about z, pitch, roll."""
    return attitude.from_euler_321(math.radians(roll_deg), math.radians(pitch_deg),
                                   math.radians(yaw_deg))


def make_goal(q_xyzw: Sequence[float], frame: str, controller: str = '',
              tolerance_deg: float = 0.0, timeout_s: float = 0.0):
    """A ``Slew.Goal``; ``frame`` in ``inertial``, ``eci``, ``orbit``."""
    from adcs_msgs.action import Slew
    from geometry_msgs.msg import Quaternion
    goal = Slew.Goal()
    x, y, z, w = (float(v) for v in q_xyzw)
    goal.q_target = Quaternion(x=x, y=y, z=z, w=w)
    goal.frame = FRAME_NAMES.get(frame, frame)
    goal.controller = controller
    goal.tolerance_deg = float(tolerance_deg)
    goal.timeout_s = float(timeout_s)
    return goal


#: Wall seconds to wait for an answer before the request is sent again (docs/reliability.md,
#: "Dropped answers").
ANSWER_S = 3.0
#: Wall seconds between result requests while the goal runs and its status says nothing.
RESULT_RESEND_S = 30.0
_TERMINAL = (4, 5, 6)   # GoalStatus SUCCEEDED, CANCELED, ABORTED


class _GoalExchange:
    """One ``adcs/slew`` goal, robust to dropped answers: resent with the same goal id, its
    status topic telling an accepted or finished goal whose answer was lost."""

    def __init__(self, node, client, goal, answer_s: float, on_feedback) -> None:
        import uuid as _uuid

        from action_msgs.msg import GoalStatusArray
        from rclpy.qos import qos_profile_action_status_default
        from unique_identifier_msgs.msg import UUID
        self.client, self.goal, self.answer_s = client, goal, answer_s
        self.uuid = UUID(uuid=list(_uuid.uuid4().bytes))
        self.fb = (lambda m: on_feedback(m.feedback)) if on_feedback else None
        self.status = None                 # last GoalStatus of our goal id (None: unseen)
        self.status_at = 0.0
        self.sends = 0
        self._sub = node.create_subscription(GoalStatusArray, 'adcs/slew/_action/status',
                                             self._on_status, qos_profile_action_status_default)
        self._node = node

    def _on_status(self, msg) -> None:
        for st in msg.status_list:
            if bytes(st.goal_info.goal_id.uuid) == bytes(self.uuid.uuid):
                if st.status != self.status:
                    self.status, self.status_at = st.status, time.monotonic()

    def destroy(self) -> None:
        self._node.destroy_subscription(self._sub)

    def handle(self):
        """A goal handle for our id (the server accepted it; its answer may have been lost)."""
        from rclpy.action.client import ClientGoalHandle
        response = self.client._action_type.Impl.SendGoalService.Response()
        response.accepted = True
        return ClientGoalHandle(self.client, self.uuid, response)

    def send(self, executor, deadline: float):
        """Send the goal until answered: ``(handle, None)``, ``(None, result future)`` (a
        resend refused: the result decides) or ``(None, None)`` (refused, or no answer)."""
        futures, next_send = [], 0.0
        while time.monotonic() < deadline:
            now = time.monotonic()
            if now >= next_send:
                futures.append(self.client.send_goal_async(self.goal, feedback_callback=self.fb,
                                                           goal_uuid=self.uuid))
                self.sends += 1
                next_send = now + self.answer_s
            executor.spin_once(timeout_sec=0.05)
            answers = [f.result() for f in futures if f.done() and f.result() is not None]
            accepted = [h for h in answers if h.accepted]
            if accepted:
                return accepted[0], None
            if self.status is not None:       # the server has our goal: its answer was lost
                return self.handle(), None
            if answers:
                if len(futures) == 1:
                    return None, None         # refused at the first request
                # a refusal of a resend: a duplicate of an accepted goal, or a real refusal
                return None, self.handle().get_result_async()
        return None, None

    def result(self, executor, handle, first, end: float):
        """The first done result future by ``end`` (monotonic), or None; requests resent
        after ``answer_s`` once finished, else every :data:`RESULT_RESEND_S`."""
        futures = [first if first is not None else handle.get_result_async()]
        sent = time.monotonic()
        while time.monotonic() < end:
            done = [f for f in futures if f.done()]
            if done:
                return done[0]
            executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            finished = self.status in _TERMINAL and now - self.status_at > self.answer_s
            if now - sent > (self.answer_s if finished else RESULT_RESEND_S):
                futures.append(handle.get_result_async())
                sent = now
        return None


def run_goal(node, executor, goal, server_wait_s: float = SERVER_WAIT_S,
             on_feedback: Optional[Callable] = None, deadline_s: float = math.inf,
             answer_s: float = ANSWER_S):
    """Send ``goal`` to ``adcs/slew``: ``(status, Slew.Result or None)``; dropped answers
    resent (:class:`_GoalExchange`), Ctrl-C cancels. RuntimeError: no server."""
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from adcs_msgs.action import Slew
    client = ActionClient(node, Slew, 'adcs/slew')
    exchange = None
    try:
        if not client.wait_for_server(timeout_sec=server_wait_s):
            raise RuntimeError(f'no adcs/slew action server within {server_wait_s:g} s')
        exchange = _GoalExchange(node, client, goal, answer_s, on_feedback)
        handle, first = exchange.send(executor, time.monotonic() + server_wait_s)
        if handle is None and first is None:
            return 'rejected', None
        end = time.monotonic() + deadline_s
        result = None
        try:
            if handle is None:      # refusal of a resend: the result request decides
                while not first.done() and time.monotonic() < end:
                    executor.spin_once(timeout_sec=0.05)
                    if exchange.status is not None:
                        break        # the server has the goal
                if first.done() and first.result().status == GoalStatus.STATUS_UNKNOWN:
                    return 'rejected', None
                handle = exchange.handle()
            result = exchange.result(executor, handle, first, end)
        except KeyboardInterrupt:
            for _ in range(2):      # a lost cancel answer: asked once more
                cancel = handle.cancel_goal_async() if handle is not None else None
                if cancel is None:
                    break
                executor.spin_until_future_complete(cancel, timeout_sec=answer_s)
                if cancel.done():
                    break
            result = exchange.result(executor, handle or exchange.handle(), None,
                                     time.monotonic() + 5.0)
        if result is None or not result.done():
            return 'timeout', None
        names = {GoalStatus.STATUS_SUCCEEDED: 'succeeded', GoalStatus.STATUS_ABORTED: 'aborted',
                 GoalStatus.STATUS_CANCELED: 'canceled'}
        res = result.result()
        return names.get(res.status, str(res.status)), res.result
    finally:
        if exchange is not None:
            exchange.destroy()
        client.destroy()


def format_result(status: str, result) -> str:
    """One line: status, message, settling time, energy, final error."""
    if result is None:
        return status
    settle = 'n/a' if result.settling_time_s < 0 else f'{result.settling_time_s:.2f} s'
    return (f'{status}: {result.message}; settling {settle}, energy '
            f'{result.energy_nms:.2f} N m s, final error {result.final_error_deg:.3f} deg, '
            f'{result.elapsed_s:.1f} s')


def slew(roll_deg: float, pitch_deg: float, yaw_deg: float, frame: str = 'inertial',
         controller: str = '', tolerance_deg: float = 0.0, timeout_s: float = 0.0,
         pid: Optional[int] = None, quiet: bool = False) -> str:
    """``adcs slew`` to the 3-2-1 attitude [deg] in ``frame``; the result line, LiveError."""
    from adcs_nodes import registry
    from adcs_nodes.nodes.slew_action import check_goal
    from adcs_nodes.tools.run.live import LiveError, _Session, pick_run
    if frame not in FRAME_NAMES:
        raise LiveError(f'unknown frame {frame!r}; use inertial or orbit')
    q = goal_quaternion(roll_deg, pitch_deg, yaw_deg)
    reason = check_goal(q, FRAME_NAMES[frame], controller, registry.names('controller'),
                        tolerance_deg, timeout_s)
    if reason:
        raise LiveError(reason)
    session = _Session(pick_run(pid), deadline=False)
    last = [0.0]

    def show(fb) -> None:
        now = time.monotonic()
        if not quiet and now - last[0] >= 1.0:
            last[0] = now
            print(f'  t {fb.elapsed_s:7.1f} s  angle to go {fb.angle_to_go_deg:8.3f} deg  '
                  f'rate {fb.rate_deg_s:7.3f} deg/s', flush=True)
    try:
        status, result = run_goal(session.node, session.executor,
                                  make_goal(q, frame, controller, tolerance_deg, timeout_s),
                                  on_feedback=show)
    except RuntimeError as exc:
        raise LiveError(str(exc)) from None
    finally:
        session.close()
    if status == 'rejected':
        raise LiveError('goal rejected by the server (see its log for the reason)')
    line = format_result(status, result)
    if status != 'succeeded':
        raise LiveError(line)
    return line
