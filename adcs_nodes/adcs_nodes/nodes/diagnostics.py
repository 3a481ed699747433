"""``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``) of any ADCS node, and the
``lockstep/status`` and ``lockstep/progress`` of a lockstep node (:class:`StatusTopics`).

``/diagnostics`` is what ``rqt_robot_monitor``, Foxglove and ``diagnostic_aggregator`` read:
one ``DiagnosticStatus`` (name = node name, hardware id ``adcs``) once per ``period_s`` of sim
time, published from the frame path (deterministic in lockstep, so recorded and compared) and
only while someone reads the topic (:meth:`Diagnostics.wanted`). Values (strings), in order:
the node's ``timing_diagnostics()``, its attributes among :data:`ATTRIBUTES`, its
``diagnostic_values()`` (the manager's active controller, ``fallback``, ...). Level ``WARN``
when a counter of :data:`COUNTERS` grew since the last status or a ``fallback`` is active,
``ERROR`` when the node sets ``diagnostic_error``, else ``OK``.
"""
from __future__ import annotations

import time
from typing import Any, Dict, List, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from adcs_msgs.msg import LockstepStatus
from adcs_nodes.core.run_status import StatusPacer
from adcs_nodes.nodes import cdr, runtime
from adcs_nodes.nodes.adapter import QOS_DATA

TOPIC = '/diagnostics'
HARDWARE_ID = 'adcs'

#: Node attributes reported when present (and not already in ``timing_diagnostics()``).
ATTRIBUTES = ('frames', 'missed_frames', 'last_missed_input', 'update_count', 'rejected_count',
              'last_rejection', 'resets', 'rejected_commands', 'dropouts')
#: Values that count problems: their growth over a period makes the level WARN.
COUNTERS = ('missed_frames', 'rejected_samples', 'rejected_count', 'resets',
            'rejected_commands', 'dropouts', 'security_events')
NS_PER_S = 1_000_000_000


def _text(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.9g}'
    if isinstance(value, (list, tuple)):
        return ', '.join(_text(v) for v in value)
    return str(value)


class Diagnostics:
    """``/diagnostics`` of one ``node`` (see module docstring; its ``publisher`` method when it
    has one), every ``period_s`` > 0 of sim time."""

    def __init__(self, node: Any, period_s: float = 1.0) -> None:
        if not period_s > 0:
            raise ValueError(f'diagnostics period must be positive, got {period_s}')
        self.node = node
        self.period_ns = int(round(period_s * NS_PER_S))
        make = getattr(node, 'publisher', None)
        self.pub = (make(DiagnosticArray, TOPIC, QOS_DATA) if make is not None
                    else node.create_publisher(DiagnosticArray, TOPIC, QOS_DATA))
        self._next_ns = -1
        self._last: Dict[str, int] = {}
        # the rcl call, without rclpy's `with handle` guard (0.09 us against 0.47 us; called
        # by every node every sim second; a destroyed publisher raises RCLError either way)
        self._subscription_count = self.pub.handle.get_subscription_count

    def frame(self, t_ns: int) -> bool:
        """Called once per processed frame (elapsed sim time ``t_ns``); publishes when a
        period boundary is reached and someone reads the topic. Returns True when a status
        was published. The first frame logs the process CPU so far (:func:`runtime.start_cost`)."""
        if t_ns < self._next_ns:
            return False
        if self._next_ns < 0:
            self.node.get_logger().info(runtime.start_cost(t_ns))
        self._next_ns = (t_ns // self.period_ns + 1) * self.period_ns
        if not self.wanted():
            return False
        self.publish(t_ns)
        return True

    def wanted(self) -> bool:
        """True when a subscription is matched to ``/diagnostics`` (else nothing is built)."""
        return self._subscription_count() > 0

    def values(self) -> List[Tuple[str, Any]]:
        """``(key, value)`` pairs (see module docstring for the order)."""
        out: Dict[str, Any] = {}
        for method in ('timing_diagnostics', None, 'diagnostic_values'):
            if method is None:
                out.update({name: getattr(self.node, name) for name in ATTRIBUTES
                            if name not in out and hasattr(self.node, name)})
                continue
            fn = getattr(self.node, method, None)
            if callable(fn):
                out.update(fn())
        return list(out.items())

    def status(self) -> DiagnosticStatus:
        """The node's ``DiagnosticStatus`` now (level and message from what changed)."""
        problems = []
        values = self.values()
        given = dict(values)
        for name in COUNTERS:
            try:
                value = int(given[name])
            except (KeyError, TypeError, ValueError):
                continue
            grown = value - self._last.get(name, 0)
            self._last[name] = value
            if grown > 0:
                problems.append(f'{grown} {name.replace("_", " ")}')
        fallback = str(given.get('fallback', '') or '')
        if fallback:
            problems.append(f'fallback: {fallback}')
        error = str(getattr(self.node, 'diagnostic_error', '') or '')
        st = DiagnosticStatus()
        st.name = self.node.get_name()
        st.hardware_id = HARDWARE_ID
        if error:
            st.level, st.message = DiagnosticStatus.ERROR, error
        elif problems:
            st.level, st.message = DiagnosticStatus.WARN, '; '.join(problems)
        else:
            st.level, st.message = DiagnosticStatus.OK, 'OK'
        st.values = [KeyValue(key=str(k), value=_text(v)) for k, v in values]
        return st

    def publish(self, t_ns: int) -> None:
        """Publish the status stamped with elapsed sim time ``t_ns``."""
        msg = DiagnosticArray()
        msg.header.stamp = self.node.stamp(t_ns)
        msg.status = [self.status()]
        self.pub.publish(msg)


class StatusTopics:
    """``lockstep/status`` (frames, missed frames, wall time: for the launcher and a user) and
    ``lockstep/progress`` (the clock master's flow control) of a lockstep node, and its
    ``/diagnostics`` (:attr:`diagnostics`); when each is due is
    :class:`~adcs_nodes.core.run_status.StatusPacer`'s decision (also once a wall second while
    the node is stalled). Nothing after the final status or :meth:`stop` (``node_killed``).
    """

    def __init__(self, node: Any, status_period_ns: int) -> None:
        self.node, self.wall0 = node, time.monotonic()
        self.pacer = StatusPacer(node.get_name(), node.frame_ns, status_period_ns, self.wall0)
        self.stopped = False
        self.pub = cdr.raw_publisher(
            node.create_publisher(LockstepStatus, 'lockstep/status', QOS_DATA))
        self.progress_pub = cdr.raw_publisher(
            node.create_publisher(LockstepStatus, 'lockstep/progress', QOS_DATA))
        self.diagnostics = Diagnostics(node)     # once per sim second (frame_done)
        node.create_timer(1.0, self._watchdog)

    def _msg(self, t_ns: int, final: bool) -> LockstepStatus:
        n = self.node
        msg = LockstepStatus(node=n.get_name(), frames=int(n.frames),
                             missed_frames=int(n.missed_frames), final=bool(final))
        msg.header.stamp = n.stamp(t_ns)
        return msg

    def stop(self) -> None:
        """Publish nothing more (a crashed process)."""
        self.stopped = self.pacer.final_sent = True

    def progress(self, seen_ns: int, final: bool = False) -> None:
        """``lockstep/progress`` for sim time ``seen_ns`` when due."""
        if not self.stopped and self.pacer.progress_due(seen_ns, final):
            self.progress_pub.publish(self._msg(seen_ns, final))

    def frame_done(self, t_ns: int, final: bool = False) -> None:
        """After frame ``t_ns``: ``/diagnostics`` and ``lockstep/status`` when due."""
        self.diagnostics.frame(t_ns)
        if self.pacer.status_due(t_ns, final, self.node.missed_frames,
                                 self.pub.get_subscription_count, time.monotonic()):
            self.publish(final)

    def _watchdog(self) -> None:
        if self.pacer.stalled(time.monotonic()):
            self.publish()

    def wanted(self) -> bool:
        """Whether a status now would reach a reader (:meth:`StatusPacer.wanted`)."""
        return self.pacer.wanted(
            self.pub.get_subscription_count(), lambda: [
                i.node_name for i in self.node.get_subscriptions_info_by_topic(
                    self.pub.topic_name)], self.node.missed_frames, time.monotonic())

    def publish(self, final: bool = False) -> None:
        """``lockstep/status`` stamped with the sim time of the node's last frame."""
        if self.pacer.final_sent:
            return
        self.pacer.final_sent = bool(final)
        self.pacer.last_wall = time.monotonic()
        if not self.wanted():
            return
        msg = self._msg(self.node.sim_t_ns, final)
        msg.last_missed_input = self.node.last_missed_input
        msg.wall_time = time.monotonic() - self.wall0
        self.pub.publish(msg)
