"""Base class of every lockstep node: the rclpy adapter over the pure timing pieces.

Decided without rclpy (each tested so): the timing mode and the frame schedule
(:mod:`adcs_nodes.core.frame_schedule` over ``FrameSync``), live and external sample timing
(:mod:`adcs_nodes.core.sample_timing`), the start handshake (:mod:`adcs_nodes.core.handshake`),
counts, summary and status pacing (:mod:`adcs_nodes.core.run_status`). Their rclpy glue:
:class:`~adcs_nodes.nodes.frame_timing.FrameTiming`, :class:`~adcs_nodes.nodes.handshake.
Handshake`, :class:`~adcs_nodes.nodes.diagnostics.StatusTopics`. DESIGN section 6 has the
timing model; stamps become elapsed integer nanoseconds at the edge (:meth:`elapsed_ns`).
"""
from __future__ import annotations

import copy
from typing import Any, Callable, Dict, List, Optional, Tuple

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions

from adcs_nodes.components.base import DEFAULT_EPOCH, epoch_to_ns, parse_epoch  # noqa: F401
from adcs_nodes.core.frame_schedule import LIVE, LOCKSTEP, FrameSchedule, timing_mode  # noqa
from adcs_nodes.core.handshake import first_line
from adcs_nodes.core.lockstep import MAX_LAG_FRAMES, NS_PER_S, seconds_to_ns  # noqa: F401
from adcs_nodes.core.run_status import (  # noqa: F401 (MONITOR_*: re-exported)
    MONITOR_NODE, MONITOR_STATUS_OF, MONITOR_STATUS_WALL_S, SampleCounts, run_summary,
    timing_values)
from adcs_nodes.core.sample_timing import REASONS, ExternalInputs
from adcs_nodes.nodes import cdr
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes.adapter import QOS_LATCHED, QOS_READY  # noqa: F401 (re-exported)
from adcs_nodes.msgs.fields import stamp_ns, to_stamp
from adcs_nodes.nodes.diagnostics import StatusTopics
from adcs_nodes.nodes.frame_timing import (  # noqa: F401 (re-exported)
    QOS_DATA, SENSOR_PREFIXES, SUMMARY_PREFIX, FrameTiming)
from adcs_nodes.nodes.handshake import Handshake

#: Parameters only the launcher (or a lockstep test) gives: any of them means lockstep.
LAUNCH_PARAMS = ('expected_matches', 'duration_s', 'frame_period_s')
#: Why a sample is rejected: the timing reasons, and ``undecodable`` (raw CDR bytes that do
#: not decode, from a stranger on the domain: ``nodes/cdr.py``).
REJECT_REASONS = REASONS + ('undecodable',)
#: Node options: what the params file or ``-p`` gives is declared at once (an unknown name is
#: refused with a did-you-mean), and nothing undeclared can be set at run time.
NODE_OPTIONS = {'allow_undeclared_parameters': False,
                'automatically_declare_parameters_from_overrides': True}


class LockstepNode(node_params.SpecParameters, Node):
    """rclpy node with the project's parameter, handshake, timing and status conventions.
    Its common parameters (``nodes.params.COMMON``) are read-only at run time, ``use_sim_time``
    too (it would change the clock under a running node)."""

    #: True for the simulator's own nodes: they run in lockstep only.
    SIMULATED_WORLD = False

    def __init__(self, name: str, **kwargs: Any) -> None:
        Node.__init__(self, name, **NODE_OPTIONS, **kwargs)
        self.setup_lockstep()

    def setup_lockstep(self, rejoin: bool = False) -> None:
        """Read the common parameters and create the lockstep endpoints (status, progress,
        ready, ``/diagnostics``); ValueError for a bad value. ``rejoin``: the node joins a
        run already going (its first frame follows the world's time, not 0)."""
        self.done, self.exit_code, self.rejoin = False, 0, rejoin
        self.epoch = parse_epoch(self.param('epoch', DEFAULT_EPOCH))
        self.epoch_ns = epoch_to_ns(self.epoch)
        self.frame_ns = seconds_to_ns(self.param('frame_period_s', 1.0))
        self.timeout_s = float(self.param('timeout_s', 5.0)) * self.param('timeout_factor', 1.0)
        self.seed = int(self.param('seed', 0))
        self.real_time = bool(self.param('real_time', False))
        self.dead_after = self.param('dead_after_frames', 3)
        self._expected_raw = list(self.param('expected_matches', ['']) or [])
        given = getattr(self, '_parameter_overrides', {})      # params file, -p, overrides
        self.timing_mode = timing_mode(
            self.get_name(), str(self.param('timing_mode', '') or ''), self.SIMULATED_WORLD,
            any(given[n].value not in (None, '', [''], [], 0, 0.0)
                for n in LAUNCH_PARAMS if n in given), self.real_time)
        self._external_inputs = [n for n in self.param('external_inputs', []) if n]
        self.max_sample_age_s = float(self.param('max_sample_age_s', 5.0))
        self.max_future_s = float(self.param('max_future_s', 0.5))
        # ASSUMPTION: 50 ms covers a driver's publish-to-receive latency on one machine
        self.live_latency_ns = seconds_to_ns(self.param('live_latency_s', 0.05))
        killed_at = float(self.param('killed_at_s', -1.0))   # a node_killed fault
        self.killed_at_ns = seconds_to_ns(killed_at) if killed_at >= 0 else None
        self.counts = SampleCounts(REJECT_REASONS)
        self.frames, self.missed_frames, self.last_missed_input = 0, 0, ''
        self.sim_t_ns = 0            # elapsed sim time of the last frame this node processed
        self.duration_ns = seconds_to_ns(self.param('duration_s', 0.0))
        self._pubs: Dict[str, Any] = {}
        self._subs: Dict[str, Any] = {}
        self._ready_sent = False
        self.handshake = Handshake(self, self._expected_raw, QOS_READY)
        self.status = StatusTopics(self, seconds_to_ns(self.param('status_period_s', 1.0)))
        self.diagnostics = self.status.diagnostics
        self._topics_of: Dict[str, str] = {}
        self.schedule: Optional[FrameSchedule] = None
        self.external = ExternalInputs({}, {}, 1, 1, 0, 0, 0, self.counts)
        self.killed = False
        self.add_on_set_parameters_callback(self._refuse_clock_switch)

    def _refuse_clock_switch(self, parameters) -> SetParametersResult:
        """``use_sim_time`` is read at start-up: switched at run time it would move the
        node's clock under its filter and timers."""
        for p in parameters:
            if p.name == 'use_sim_time' and self.has_parameter(p.name) \
                    and p.value != self.get_parameter(p.name).value:
                return SetParametersResult(successful=False, reason=(
                    f'use_sim_time is read at start-up ({self.get_name()} runs on '
                    f'{"/clock" if self.get_parameter(p.name).value else "the wall clock"}); '
                    'restart the node with -p use_sim_time:=... to change it'))
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ parameters
    def param(self, name: str, default: Any, doc: str = '') -> Any:
        """Value of parameter ``name``, declared from its spec (:data:`params.COMMON`, else
        typed from ``default`` and described by ``doc`` or the class's ``PARAM_DOCS``)."""
        self._asked = getattr(self, '_asked', set())
        self._asked.add(name)
        spec = node_params.COMMON.get(name)
        doc = doc or getattr(self, 'PARAM_DOCS', {}).get(name, '')
        if spec is None:    # (a plugin's parameter: typed from its default)
            spec = node_params.infer(name, default, doc or name.replace('_', ' '))
        if name in getattr(self, '_adcs_specs', {}):       # (a second read)
            value = self._parameters[name].value
        else:
            value = node_params.declare(self, spec)
        if value is None:                                  # (an optional one not given)
            return default
        return list(value) if spec.type.endswith('[]') else value

    def section(self, prefix: str, spec: Any) -> Dict[str, Any]:
        """Parameters ``prefix.*`` as the validated values of section ``spec`` (for model
        factories; :func:`adcs_nodes.nodes.params.declare_section`)."""
        return node_params.declare_section(self, prefix, spec)

    def apply_parameters(self) -> None:
        """At a frame boundary: apply run-time parameter changes (managed nodes)."""

    # ------------------------------------------------------------------ endpoints
    def publisher(self, msg_type, topic: str, qos: QoSProfile = QOS_DATA):
        """A raw-CDR publisher (``nodes/cdr.py``), QoS overridable, known to the handshake."""
        pub = self.create_publisher(
            msg_type, topic, copy.copy(qos),   # rclpy applies overrides to the profile in place
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self._pubs[pub.topic_name] = pub
        return cdr.raw_publisher(pub)

    def subscription(self, msg_type, topic: str, callback, qos: QoSProfile = QOS_DATA):
        """A subscription (QoS overridable) known to the handshake; raw CDR for a type the
        codec covers (``callback`` gets the decoded message; undecodable bytes are rejected
        and counted)."""
        codec = cdr.raw_codec(msg_type)
        if codec is not None:
            callback = cdr.decoding(callback, codec, lambda exc: self._reject_sample(
                topic, 'undecodable', f'a message that does not decode was dropped ({exc})'))
        sub = self.create_subscription(
            msg_type, topic, callback, copy.copy(qos),
            qos_overriding_options=QoSOverridingOptions.with_default_policies(),
            raw=codec is not None)
        self._subs[sub.topic_name] = sub
        return sub

    @property
    def live(self) -> bool:
        """True in live mode."""
        return self.timing_mode == LIVE

    # ------------------------------------------------------------------ inputs
    def lockstep_inputs(self, inputs: Dict[str, Tuple], period_s: float,
                        on_frame: Callable[[int, Dict[str, Any], List[str]], None]) -> None:
        """Fire ``on_frame(t_ns, msgs, missing)`` at t = 0, P, 2P, ... (P = ``period_s``)
        when the inputs due then have arrived (lockstep), or every P of the ROS clock (live).

        ``inputs``: ``{name: (msg_type, topic, period_s[, kind])}``: the producer's period (0:
        never awaited) and ``kind`` (``frame``, ``previous`` or ``latest``); messages need
        ``header.stamp``. ``msgs``: ``{name: msg or None}``; ``missing``: the due inputs that
        timed out. In ``real_time`` flight software fires with the latest values at once.
        """
        self.timing = FrameTiming(self, inputs, period_s, on_frame)

    def input_arrived(self, name: str) -> None:
        """Hook called on every message of an input before it is stored."""

    def external_samples(self, t_ns: int) -> List[Tuple[int, str, Any]]:
        """The samples in sample timing frame ``t_ns`` takes, in stamp order, each once:
        ``(elapsed stamp, input name, message)``."""
        return self.external.take(t_ns)

    def last_usable_ns(self, name: str) -> Optional[int]:
        """Elapsed stamp of the last usable sample of an input in sample timing (one that
        passed the timing checks; a consumer that checks more overrides it), or None."""
        return self.external.last_usable(name)

    def fresh(self, name: str, msg: Any, t_ns: int) -> bool:
        """True when ``msg``, the value of input ``name`` in frame ``t_ns``, is a new sample:
        stamped ``t_ns`` (lockstep), newer than the last used (sample timing) or than the
        frame before's (live)."""
        if msg is None:
            return False
        s = stamp_ns(msg.header.stamp)
        if name in self.external:
            return self.external.fresh(name, s)
        if not self.live:
            return self.elapsed_ns(s) == int(t_ns)
        return self.timing.live_samples.fresh(name, s)

    def _reject_sample(self, name: str, reason: str, text: str) -> None:
        self.get_logger().warning(
            self.counts.reject(reason, self._topics_of.get(name, name), text),
            throttle_duration_sec=5.0)

    def stops_at(self, t: int) -> bool:
        """True from the frame of this node's ``node_killed`` fault on (nothing more is
        published, as a crashed process; in a graph run the launcher kills it)."""
        if self.killed_at_ns is None or t < self.killed_at_ns:
            return False
        if self.schedule is not None:
            self.schedule.stop()
        if not self.killed:
            self.killed = True
            self.status.stop()
            self.get_logger().error(
                f'killed by the scenario (a node_killed fault) at t={t / NS_PER_S:g} s: this '
                'node publishes nothing more')
        return True

    # ------------------------------------------------------------------ summary, diagnostics
    def used_counts(self) -> Dict[str, int]:
        """Samples used per input name (a node whose component knows better overrides it)."""
        return dict(self.counts.used)

    def run_summary(self) -> Dict[str, Any]:
        """What this node did with its inputs, by topic (:func:`run_status.run_summary`)."""
        return run_summary(self.frames, self.missed_frames, self.counts, self.used_counts(),
                           self._topics_of, self.external.starved,
                           dict(getattr(self, 'rejected_by', {}) or {}),
                           getattr(self, 'resets', None))

    def timing_diagnostics(self) -> Dict[str, str]:
        """Timing health for ``/diagnostics`` (:func:`run_status.timing_values`)."""
        sync = getattr(self, 'sync', None)
        out = timing_values(self.timing_mode, self.frames, self.missed_frames,
                            self.last_missed_input,
                            [self._topics_of.get(n, n) for n in sync.dead()] if sync else [],
                            self.counts, self.external.starved, self._topics_of)
        guard = getattr(self, '_publisher_guard', None)
        if guard is not None:                 # publisher identity (publisher_guard)
            out.update(guard.core.diagnostic_values())
        return out

    # ------------------------------------------------------------------ handshake
    def add_ready_check(self, check: Callable[[], List[str]]) -> None:
        """Also wait, before ready, until ``check()`` (what is still missing) is empty."""
        self.handshake.checks.append(check)

    def unmatched(self, graph_view: bool = False) -> List[str]:
        """What the start handshake still waits for (:meth:`Handshake.unmatched`)."""
        return self.handshake.unmatched(graph_view)

    def start_handshake(self, on_ready: Optional[Callable[[], None]] = None) -> None:
        """Say what the node waits for and publishes (its first line), then ``lockstep/ready``
        once matched, then call ``on_ready`` (:class:`Handshake`)."""
        timing = getattr(self, 'timing', None)
        self.get_logger().info(first_line(
            self.timing_mode, sorted(set(self._topics_of.values())),
            sorted(t for t in self._pubs if t not in ('/diagnostics', '/adcs/security_events')),
            not self.handshake.expected, 0.0 if timing is None else timing.period_ns / NS_PER_S,
            bool(self.get_parameter('use_sim_time').value), self.SIMULATED_WORLD))
        self.handshake.start(on_ready)

    def handshake_done(self) -> None:
        """Ready: the frame schedule is armed (a rejoin takes its first frame now)."""
        self._ready_sent = True
        if self.schedule is not None:
            self.schedule.arm()
            self.timing.see(self.schedule.seen_ns)   # (a rejoin: the first frame, logged)
            self.report_progress(self.schedule.seen_ns)   # (a rejoin: the master hears it)

    # ------------------------------------------------------------------ time and status
    def elapsed_ns(self, stamp_ns: int) -> int:
        """Elapsed sim time of an absolute stamp."""
        return int(stamp_ns) - self.epoch_ns

    def stamp(self, elapsed_ns: int):
        """Absolute ``builtin_interfaces/Time`` of an elapsed sim time."""
        return to_stamp(self.epoch_ns + int(elapsed_ns))

    def count_missed(self, inputs: List[str], t_ns: int,
                     applied: str = 'going on without it') -> None:
        """Record a frame whose inputs ``inputs`` timed out, and log what is applied."""
        self.missed_frames += 1
        self.last_missed_input = ','.join(inputs)
        self.get_logger().warning(
            f'frame t={t_ns / NS_PER_S:.3f} s: no {self.last_missed_input} within '
            f'{self.timeout_s:g} s wall; {applied} (missed frames: {self.missed_frames})')

    def report_progress(self, seen_ns: int, final: bool = False) -> None:
        """``lockstep/progress``: every message stamped up to ``seen_ns`` is read; ``final``:
        the node's last frame is done (:class:`StatusTopics`)."""
        self.status.progress(seen_ns, final)

    def is_last_frame(self, t_ns: int, period_ns: int) -> bool:
        """True when frame ``t_ns`` is this node's last one of a run of ``duration_s``."""
        return self.duration_ns > 0 and t_ns + period_ns > self.duration_ns

    def frame_done(self, t_ns: int, final: bool = False) -> None:
        """After frame ``t_ns``: ``/diagnostics``, and ``lockstep/status`` when due."""
        self.sim_t_ns = t_ns
        self.status.frame_done(t_ns, final)

    def publish_status(self, final: bool = False) -> None:
        """``lockstep/status`` now (nothing more after the ``final`` one)."""
        self.status.publish(final)
