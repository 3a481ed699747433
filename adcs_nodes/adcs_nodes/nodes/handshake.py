"""The start handshake of a lockstep node: the rclpy glue of :mod:`adcs_nodes.core.handshake`.

Every 20 ms (0.1 s after the first second) the node checks its expectations
(``expected_matches`` against the matched counts of its endpoints), then its own ready checks
(sensor mounts, the lifecycle state, the publisher guard) and the publishers of its external
drivers' topics; when all hold it locks its guarded inputs, arms its frame schedule, publishes
its name on ``lockstep/ready`` (latched) and calls ``on_ready``. A wait longer than 10 s says
what is missing, with what discovery knows (the launcher's self-healing reads that line).

While it waits for an external driver, the node publishes ``/clock`` at the epoch minus 1 ns
once a second: a driver on sim time (``ros2 topic pub -s``, ``use_sim_time``) that waits for a
clock before it publishes can then start, instead of both waiting for the other until the wait
ends (60 s). Lockstep nodes ignore a time before frame 0.
"""
from __future__ import annotations

import time
from typing import Any, Callable, List, Optional

from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from adcs_nodes.core import handshake
from adcs_nodes.nodes.adapter import node_log


class Handshake:
    """The start handshake of ``node`` (a :class:`~adcs_nodes.nodes.lockstep_node.
    LockstepNode`) with the ``expected_matches`` entries ``raw`` (ValueError for a bad one)."""

    def __init__(self, node: Any, raw: List[str], qos: Any) -> None:
        self.node = node
        self.expected = handshake.parse_expectations(raw, node.resolve_topic_name)
        self.checks: List[Callable[[], List[str]]] = []
        self.driver_wait = handshake.DriverWait()
        self.pub = node.create_publisher(String, 'lockstep/ready', qos)
        self.on_ready: Optional[Callable[[], None]] = None
        self.timer = None
        self.clock_pub, self.clock_at = None, 0.0

    def unmatched(self, graph_view: bool = False, quick: bool = False) -> List[str]:
        """What is not matched yet, as readable strings (``graph_view``: with what discovery
        knows of each topic; ``quick``: only the expectations while one is unmet, the ready
        checks, which query the graph, after)."""
        node = self.node

        def matched(kind: str, topic: str) -> Optional[int]:
            ent = (node._pubs if kind == 'pub' else node._subs).get(topic)
            return None if ent is None else (ent.get_subscription_count() if kind == 'pub'
                                             else ent.get_publisher_count())
        known = (lambda kind, topic: node.count_subscribers(topic) if kind == 'pub'
                 else node.count_publishers(topic)) if graph_view else None
        unmet = handshake.unmet(self.expected, matched, node.get_name(), known)
        if quick and unmet:
            return unmet
        return [m for check in self.checks for m in check()] + unmet

    def external_unmatched(self) -> List[str]:
        """Topics of sample-timing inputs with no publisher matched yet, for at most
        :data:`handshake.EXTERNAL_WAIT_S` (not in :meth:`unmatched`: the launcher never
        restarts a node for a driver that is not there)."""
        node = self.node
        missing = sorted(node._topics_of[n] for n in node.external
                         if node._subs[node._topics_of[n]].get_publisher_count() < 1)
        now = time.monotonic()
        waiting, line = self.driver_wait.check(missing, now)
        if line is not None:
            node_log(node)(*line)
        if waiting and now >= self.clock_at:           # a clock a sim-time driver starts on
            self.clock_at = now + 1.0
            self.clock_pub = self.clock_pub or node.create_publisher(Clock, '/clock', 10)
            self.clock_pub.publish(Clock(clock=node.stamp(-1)))
        elif not waiting and self.clock_pub is not None:
            node.destroy_publisher(self.clock_pub)
            self.clock_pub = None
        return missing if waiting else []

    def start(self, on_ready: Optional[Callable[[], None]] = None) -> None:
        """Check every 20 ms until ready, every 0.1 s after the first second (a node that waits
        for slower ones to start costs less CPU)."""
        self.on_ready, self.t0, self.warned = on_ready, time.monotonic(), 0.0
        self.timer = self.node.create_timer(0.02, self._check)

    def _check(self) -> None:
        node = self.node
        waited = time.monotonic() - self.t0
        if waited > 1.0 and self.timer.timer_period_ns < 100_000_000:
            self.timer.cancel()
            node.destroy_timer(self.timer)
            self.timer = node.create_timer(0.1, self._check)
        if self.unmatched(quick=True):
            if waited - self.warned > handshake.ENDPOINT_WAIT_LOG_S:
                self.warned = waited
                node.get_logger().warning(f'still waiting for endpoints after {waited:.0f} s: '
                                          + ', '.join(self.unmatched(graph_view=True)))
            return
        if self.external_unmatched():
            return
        self.timer.cancel()
        node.destroy_timer(self.timer)
        if getattr(node, '_publisher_guard', None) is not None:
            node._publisher_guard.lock()      # guarded inputs: the launched producers only
        node.handshake_done()
        self.pub.publish(String(data=node.get_name()))
        if self.on_ready is not None:
            self.on_ready()
