"""When a lockstep node fires its frames: the rclpy glue of the pure timing pieces.

* lockstep: :class:`~adcs_nodes.core.frame_schedule.FrameSchedule` over
  :class:`~adcs_nodes.core.lockstep.FrameSync`, fed by ``/clock`` ticks and the input stamps,
  with a wall-clock watchdog for missed frames;
* sample timing (an external driver's inputs): :class:`~adcs_nodes.core.sample_timing.
  ExternalInputs`;
* live: :class:`~adcs_nodes.core.sample_timing.LiveSamples`, a timer on the ROS clock.

The node's own hooks: ``input_arrived(name)`` on every message, ``apply_parameters()`` at
each frame boundary, ``on_frame(t_ns, msgs, missing)`` the frame, ``last_usable_ns(name)``
for starvation; its ``counts`` get what was used, rejected and superseded.
"""
from __future__ import annotations

import json
import time
from typing import Any, Callable, Dict, List, Tuple

from rclpy.qos import qos_profile_sensor_data
from rosgraph_msgs.msg import Clock

from adcs_nodes.core.frame_schedule import FrameSchedule
from adcs_nodes.core.lockstep import (NS_PER_S, REVIVE_HOLD_FRAMES, FrameSync, InputKind,
                                      input_kind, seconds_to_ns)
from adcs_nodes.core.sample_timing import ExternalInputs, LiveSamples
from adcs_nodes.nodes import publisher_guard
from adcs_nodes.nodes.adapter import QOS_DATA, node_log
from adcs_nodes.msgs.fields import stamp_ns

#: Topic prefixes subscribed best-effort (SensorDataQoS) in live mode and sample timing.
SENSOR_PREFIXES = ('sensors/', '/sensors/')
#: The line a flight-software node logs at its last frame, followed by its summary as JSON.
SUMMARY_PREFIX = 'run summary '


class FrameTiming:
    """The frame timing of ``node``'s ``inputs`` (see
    :meth:`~adcs_nodes.nodes.lockstep_node.LockstepNode.lockstep_inputs`); sets the node's
    ``sync``, ``external``, ``schedule`` (lockstep) and ``_topics_of``."""

    def __init__(self, node: Any, inputs: Dict[str, Tuple], period_s: float,
                 on_frame: Callable[[int, Dict[str, Any], List[str]], None]) -> None:
        self.node, self.on_frame = node, on_frame
        self.period_ns = node._own_period_ns = seconds_to_ns(period_s)
        live, frame_ns = node.live, node.frame_ns
        if self.period_ns <= 0 or (not live and self.period_ns % frame_ns):
            raise ValueError(f'period_s: {period_s} s is not a positive multiple of the frame '
                             f'{frame_ns / NS_PER_S:g} s')
        specs, ext_periods = {}, {}
        for name, spec in inputs.items():
            if len(spec) not in (3, 4):
                raise ValueError(f'input {name}: want (msg_type, topic, period_s[, kind])')
            msg_type, topic, p_s = spec[:3]
            kind = input_kind(spec[3] if len(spec) == 4 else InputKind.FRAME)
            p_ns = seconds_to_ns(p_s) if p_s else 0
            if not live and p_ns % frame_ns:
                raise ValueError(f'input {name}: period {p_s} s is not a multiple of the frame')
            external = not live and name in node._external_inputs
            if external:                   # sample timing: never awaited
                ext_periods[name] = p_ns
            specs[name] = (0, InputKind.LATEST) if kind is InputKind.LATEST or external or \
                not p_ns else (p_ns, kind)
            cb = self.live_cb(name) if live else (
                self.external_cb(name) if external else self.input_cb(name))
            best_effort = (live or external) and topic.startswith(SENSOR_PREFIXES)
            sub = node.subscription(msg_type, topic, cb, qos_profile_sensor_data if best_effort
                                    else QOS_DATA)
            node._topics_of[name] = sub.topic_name
        self.topics = node._topics_of
        self.sync = node.sync = FrameSync(specs, dead_after=node.dead_after,
                                          revive_hold_ns=REVIVE_HOLD_FRAMES * frame_ns)
        future_ns, age_ns = seconds_to_ns(node.max_future_s), seconds_to_ns(node.max_sample_age_s)
        # a driver stamps with the world's /clock, which may lead this node's view by up to
        # the clock master's lag window (REVIVE_HOLD_FRAMES frames): not "from the future"
        self.external = node.external = ExternalInputs(
            ext_periods, self.topics, self.period_ns, node.dead_after, node.epoch_ns,
            future_ns + REVIVE_HOLD_FRAMES * frame_ns, age_ns, node.counts)
        self.frame_inputs = [n for n in specs if n not in self.external]
        if live:
            self.live_samples = LiveSamples(
                specs, [n for n, (p, k) in specs.items() if k is InputKind.FRAME],
                node.epoch_ns, future_ns, age_ns, node.live_latency_ns, node.counts)
            node.create_timer(self.period_ns / NS_PER_S, self.live_tick)
            return
        self.schedule = node.schedule = FrameSchedule(
            self.sync, self.period_ns, node.timeout_s,
            not node.real_time or node.SIMULATED_WORLD, node.rejoin, frame_ns)
        # /clock says that time has reached t even when no input is due then; never awaited
        node.subscription(Clock, '/clock', self.on_clock_tick)
        node.create_timer(min(0.05, node.timeout_s / 4.0), self.watchdog)

    # ------------------------------------------------------------------ lockstep
    def see(self, t: int) -> None:
        """Sim time ``t`` reached (a rejoin's first frame is logged)."""
        self.schedule.see(t)
        if self.schedule.rejoined_at is not None:
            self.node.get_logger().info(
                f'joined the run at t={self.schedule.seen_ns / NS_PER_S:g} s: first frame t='
                f'{self.schedule.rejoined_at / NS_PER_S:g} s (its inputs all come after)')
            self.schedule.rejoined_at = None

    def detached(self) -> bool:
        """True once a lifecycle cleanup undid the configure that made this timing: a delivery
        or a timer call the executor had already taken is dropped."""
        return self.node.__dict__.get('timing') is not self

    def on_clock_tick(self, msg: Clock) -> None:
        if self.detached():
            return
        self.see(self.node.elapsed_ns(stamp_ns(msg.clock)))
        self.try_fire()
        # an input stamped ahead of the clock may have moved the seen time past a mark
        self.node.report_progress(self.schedule.seen_ns)

    def input_cb(self, name: str) -> Callable[[Any], None]:
        node = self.node

        def cb(msg: Any) -> None:
            if self.detached():
                return
            node.input_arrived(name)
            t = node.elapsed_ns(stamp_ns(msg.header.stamp))
            if self.sync.add(name, t, msg):
                node.get_logger().info(
                    f'{self.topics[name]} publishes again (stamped t={t / NS_PER_S:g} s, '
                    f'before frame t={self.schedule.next_ns / NS_PER_S:g} s): used and '
                    f'awaited again after {REVIVE_HOLD_FRAMES} frames (t > '
                    f'{(t + self.sync.revive_hold_ns) / NS_PER_S:g} s)')
            self.see(t)
            self.try_fire()
        # expected_publishers given: only the launched producer's messages reach cb
        guard = publisher_guard.for_node(node)
        return cb if guard is None else guard.wrap(lambda: self.topics[name], cb)

    def external_cb(self, name: str) -> Callable[[Any], None]:
        """A sample in sample timing: queued by stamp for its frame, or rejected."""
        node = self.node

        def cb(msg: Any) -> None:
            if self.detached():
                return
            node.input_arrived(name)
            s = stamp_ns(msg.header.stamp)
            why = self.external.offer(name, s, self.schedule.seen_ns, msg)
            if why is not None:
                node._reject_sample(name, *why)
                return
            self.sync.add(name, s - node.epoch_ns, msg)
        return cb

    def try_fire(self) -> None:
        while (t := self.schedule.next_ready(time.monotonic())) is not None:
            self.fire(t, [])

    def watchdog(self) -> None:
        """A frame waited ``timeout_s``: a missed frame, fired without its missing inputs."""
        if self.detached():
            return
        out = self.schedule.timed_out(time.monotonic())
        if out is None:
            return
        t, names, dead = out
        topics = [self.topics[n] for n in names]
        self.node.count_missed(topics, t, 'going on without it (' + ', '.join(
            f'{self.topics[n]}: ' + ('none (a previous-frame input)'
                                     if self.sync.kind(n) is InputKind.PREVIOUS
                                     else 'its latest earlier sample, if any')
            for n in names) + ')')
        for n in dead:
            self.node.get_logger().error(
                f'{self.topics[n]} missed {self.node.dead_after} frames in a row: its producer '
                'is treated as dead and no longer awaited until it publishes again')
        self.fire(t, topics)
        self.try_fire()

    def fire(self, t: int, missing: List[str]) -> None:
        node = self.node
        if node.stops_at(t):
            return
        self.frame(t, self.schedule.take(t), missing)
        last = node.is_last_frame(t, self.period_ns)
        if last and not node.SIMULATED_WORLD:
            node.get_logger().info(SUMMARY_PREFIX + json.dumps(node.run_summary(),
                                                               sort_keys=True))
        node.frame_done(t, final=last)
        if last:
            node.report_progress(max(t, self.schedule.seen_ns), final=True)

    def frame(self, t: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """One frame: the node's step, then what was used (and starvation)."""
        node = self.node
        node.frames += 1
        node.sim_t_ns = t
        node.apply_parameters()
        self.on_frame(t, msgs, missing)
        stamps = {n: stamp_ns(m.header.stamp) for n, m in msgs.items() if m is not None}
        if not node.live:
            for n in self.frame_inputs:
                if n in stamps:
                    node.counts.use(n, stamps[n])
        if self.external:
            self.external.after_frame(t, {n: s for n, s in stamps.items() if n in self.external})
            for level, text in self.external.check_starved(t, node.last_usable_ns):
                node_log(node)(level, text)

    # ------------------------------------------------------------------ live
    def live_cb(self, name: str) -> Callable[[Any], None]:
        node = self.node

        def cb(msg: Any) -> None:
            if self.detached():
                return
            node.input_arrived(name)
            why = self.live_samples.offer(name, stamp_ns(msg.header.stamp),
                                          node.get_clock().now().nanoseconds, msg)
            if why is not None:
                node._reject_sample(name, *why)
        return cb

    def live_tick(self) -> None:
        """Live mode: one frame with the newest samples (:class:`LiveSamples`)."""
        if self.detached():
            return
        node = self.node
        now = node.get_clock().now().nanoseconds
        t, late = self.live_samples.choose(now)
        for n in late:
            node._reject_sample(n, 'late', 'arrived after a later frame was processed')
        if t is None or node.stops_at(t):
            return
        self.frame(t, self.live_samples.take(t, now), [])
        node.frame_done(t)
