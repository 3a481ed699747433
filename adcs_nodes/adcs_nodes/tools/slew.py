"""Client of the ``adcs/slew`` action (``adcs slew --to ROLL PITCH YAW [--frame ...]``).

:func:`slew` joins a running graph (as ``adcs switch`` does), sends the goal, prints feedback
and returns the result line; Ctrl-C cancels the goal (the spacecraft then holds its attitude).
:func:`run_goal` does the exchange on a given node and executor (tests, other tools).
"""
from __future__ import annotations

import math
import time
from typing import Callable, Optional, Sequence

import numpy as np

from adcs_nodes.core import attitude
from adcs_nodes.tools.live import SERVER_WAIT_S

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


def run_goal(node, executor, goal, server_wait_s: float = SERVER_WAIT_S,
             on_feedback: Optional[Callable] = None, deadline_s: float = math.inf):
    """Send ``goal`` to ``adcs/slew`` and wait for the result.

    Returns
    -------
    (status, result)
        ``status``: ``'rejected'``, ``'succeeded'``, ``'aborted'``, ``'canceled'`` or
        ``'timeout'`` (no result within ``deadline_s`` of wall time); ``result``: the
        ``Slew.Result`` or None. On KeyboardInterrupt the goal is canceled first.

    Raises
    ------
    RuntimeError
        When no action server appears within ``server_wait_s``.
    """
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from adcs_msgs.action import Slew
    client = ActionClient(node, Slew, 'adcs/slew')
    try:
        if not client.wait_for_server(timeout_sec=server_wait_s):
            raise RuntimeError(f'no adcs/slew action server within {server_wait_s:g} s')
        fb = (lambda m: on_feedback(m.feedback)) if on_feedback else None
        send = client.send_goal_async(goal, feedback_callback=fb)
        executor.spin_until_future_complete(send, timeout_sec=server_wait_s)
        handle = send.result()
        if handle is None or not handle.accepted:
            return 'rejected', None
        result = handle.get_result_async()
        end = time.monotonic() + deadline_s
        try:
            while not result.done() and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
        except KeyboardInterrupt:
            cancel = handle.cancel_goal_async()
            executor.spin_until_future_complete(cancel, timeout_sec=5.0)
            executor.spin_until_future_complete(result, timeout_sec=5.0)
        if not result.done():
            return 'timeout', None
        names = {GoalStatus.STATUS_SUCCEEDED: 'succeeded', GoalStatus.STATUS_ABORTED: 'aborted',
                 GoalStatus.STATUS_CANCELED: 'canceled'}
        res = result.result()
        return names.get(res.status, str(res.status)), res.result
    finally:
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
    """``adcs slew --to ROLL PITCH YAW [--frame inertial|orbit] [--controller NAME]``.

    Slews a running graph (launcher ``pid`` when several) to the 3-2-1 attitude (deg) in
    ``frame``; prints feedback about once a second unless ``quiet``; returns the result line.

    Raises
    ------
    adcs_nodes.tools.live.LiveError
        Bad goal (the reason, before anything is sent), no run, no server, rejected, not
        succeeded.
    """
    from adcs_nodes import registry
    from adcs_nodes.nodes.slew_action import check_goal
    from adcs_nodes.tools.live import LiveError, _Session, pick_run
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
