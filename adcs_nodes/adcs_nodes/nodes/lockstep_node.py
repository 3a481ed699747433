"""Base class of every lockstep node: parameters, start handshake, timing, status.

Start handshake (no fixed sleeps, DESIGN section 6)
---------------------------------------------------
The launcher knows the whole graph, so it tells each node how many DDS endpoints must be
matched before it is ready: parameter ``expected_matches`` is a list of ``"pub:<topic>=<n>"``
(that many subscriptions matched to our publisher) and ``"sub:<topic>=<n>"`` (that many
publishers matched to our subscription). When all hold, the node publishes its name on the
latched topic ``lockstep/ready``. The clock master (dynamics) starts frame 0 only when every node
in its ``wait_for_nodes`` list said ready. A node started alone (``ros2 run``) has no
expectations and is ready at once.

Time: ``/clock`` carries ``epoch + elapsed``; nodes convert stamps to elapsed integer
nanoseconds at the edge (``elapsed_ns``) so frame arithmetic is exact.
"""
from __future__ import annotations

import time
from datetime import datetime, timezone
from typing import Any, Callable, Dict, List, Optional, Tuple

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from adcs_msgs.msg import LockstepStatus
from adcs_nodes.core.lockstep import NS_PER_S, FrameSync, seconds_to_ns
from adcs_nodes.nodes.convert import stamp_ns, to_stamp
from adcs_nodes.nodes.diagnostics import Diagnostics

#: Reliable, keep-last QoS deep enough that no frame is lost in lockstep.
QOS_DATA = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
#: Latched (transient local) QoS for status-like topics.
QOS_LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
QOS_READY = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                       history=HistoryPolicy.KEEP_LAST,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)

DEFAULT_EPOCH = '2026-01-01T00:00:00Z'
#: A node reports its progress every this many base frames.
PROGRESS_EVERY = 10
#: The clock master waits when a node is more than this many frames behind (the data QoS
#: keeps 100 messages per topic, so nothing a lagging node has not read yet is dropped).
MAX_LAG_FRAMES = 40


def parse_epoch(text: str) -> datetime:
    """ISO-8601 UTC text (``2026-01-01T00:00:00Z``) -> aware ``datetime``; ValueError if bad."""
    try:
        dt = datetime.fromisoformat(str(text).replace('Z', '+00:00'))
    except ValueError as exc:
        raise ValueError(f'epoch {text!r} is not an ISO-8601 date-time') from exc
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=timezone.utc)
    return dt.astimezone(timezone.utc)


def epoch_to_ns(epoch: datetime) -> int:
    """Aware datetime -> integer ns since the Unix epoch (exact to the microsecond)."""
    delta = epoch - datetime(1970, 1, 1, tzinfo=timezone.utc)
    return (delta.days * 86400 + delta.seconds) * NS_PER_S + delta.microseconds * 1000


class LockstepNode(Node):
    """rclpy node with the project's parameter, handshake and status conventions.

    Parameters common to every node: ``epoch`` (ISO UTC of sim time 0), ``frame_period_s``
    (base frame), ``timeout_s`` (wall-clock wait for a missing input), ``seed``,
    ``expected_matches`` (start handshake), ``real_time`` (latest-value mode).
    """

    def __init__(self, name: str, **kwargs: Any) -> None:
        super().__init__(name, allow_undeclared_parameters=True,
                         automatically_declare_parameters_from_overrides=True, **kwargs)
        self.done = False
        self.exit_code = 0
        self.epoch = parse_epoch(self.param('epoch', DEFAULT_EPOCH))
        self.epoch_ns = epoch_to_ns(self.epoch)
        self.frame_ns = seconds_to_ns(self.param('frame_period_s', 1.0))
        if self.frame_ns <= 0:
            raise ValueError('frame_period_s must be positive')
        self.timeout_s = float(self.param('timeout_s', 5.0))
        if not self.timeout_s > 0:
            raise ValueError('timeout_s must be positive')
        self.seed = int(self.param('seed', 0))
        self.real_time = bool(self.param('real_time', False))
        self.frames = 0
        self.sim_t_ns = 0            # elapsed sim time of the last frame this node processed
        self.missed_frames = 0
        self.last_missed_input = ''
        self._wall0 = time.monotonic()
        self._ready_sent = False
        self._ready_pub = self.create_publisher(String, 'lockstep/ready', QOS_READY)
        self._status_pub = self.create_publisher(LockstepStatus, 'lockstep/status', QOS_DATA)
        # flow control: every PROGRESS_EVERY frames (and at the last frame of the run) a node
        # reports how far it got; the clock master never runs more than MAX_LAG_FRAMES ahead
        self._progress_pub = self.create_publisher(LockstepStatus, 'lockstep/progress',
                                                   QOS_DATA)
        self.duration_ns = seconds_to_ns(self.param('duration_s', 0.0))
        self._progress_mark = -1
        self._pubs: Dict[str, Any] = {}
        self._subs: Dict[str, Any] = {}
        self.diagnostics = Diagnostics(self)     # /diagnostics once per sim second (frames)
        self._on_ready: Optional[Callable[[], None]] = None
        self.create_timer(1.0, self.publish_status)

    # ------------------------------------------------------------------ parameters
    def param(self, name: str, default: Any) -> Any:
        """Value of parameter ``name`` (declared with ``default`` if not given)."""
        if not self.has_parameter(name):
            self.declare_parameter(name, default)
        value = self.get_parameter(name).value
        return default if value is None else value

    def section(self, prefix: str, defaults: Dict[str, Any],
                merge: bool = True) -> Dict[str, Any]:
        """Parameters ``prefix.*`` as a dict (for model factories).

        With ``merge`` the given keys override ``defaults``; without it ``defaults`` are used
        only when no key is given, for sections that select their own variant
        (``orbit.type: tle`` has other keys than the default circular orbit).
        """
        given = {k: p.value for k, p in self.get_parameters_by_prefix(prefix).items()}
        if merge:
            return {**defaults, **given}
        return given if given else dict(defaults)

    # ------------------------------------------------------------------ endpoints
    def publisher(self, msg_type, topic: str, qos: QoSProfile = QOS_DATA):
        """Create a publisher and register it for the start handshake."""
        pub = self.create_publisher(msg_type, topic, qos)
        self._pubs[pub.topic_name] = pub
        return pub

    def subscription(self, msg_type, topic: str, callback, qos: QoSProfile = QOS_DATA):
        """Create a subscription and register it for the start handshake."""
        sub = self.create_subscription(msg_type, topic, callback, qos)
        self._subs[sub.topic_name] = sub
        return sub

    # ------------------------------------------------------------------ frame inputs
    def lockstep_inputs(self, inputs: Dict[str, Tuple[Any, str, float]], period_s: float,
                        on_frame: Callable[[int, Dict[str, Any], List[str]], None]) -> None:
        """Fire ``on_frame`` at t = 0, P, 2P, ... when the inputs due then have arrived.

        Parameters
        ----------
        inputs : dict
            ``{name: (msg_type, topic, period_s)}``; ``period_s`` is the producer's period
            (0: never waited for, always the latest). Messages need ``header.stamp``.
        period_s : float
            This node's own period P (a multiple of ``frame_period_s``).
        on_frame : callable
            ``on_frame(t_ns, msgs, missing)``: elapsed sim time, ``{name: msg or None}`` (the
            message stamped t if present, else the latest before t), and the due inputs that
            timed out (empty in a normal frame).

        Notes
        -----
        Frame t is considered once ``/clock`` or any input stamped >= t has arrived (so a
        node never runs ahead of the simulation). A due input missing ``timeout_s`` of wall
        time after that is counted as a missed frame and the frame fires with the latest
        values. In
        ``real_time`` mode the node never waits: it fires with the latest values as soon as
        time has reached t.
        """
        self._own_period_ns = seconds_to_ns(period_s)
        if self._own_period_ns <= 0 or self._own_period_ns % self.frame_ns:
            raise ValueError(f'period {period_s} s is not a positive multiple of the frame '
                             f'{self.frame_ns / NS_PER_S:g} s')
        periods = {}
        self._topics_of: Dict[str, str] = {}
        for name, (msg_type, topic, p_s) in inputs.items():
            p_ns = seconds_to_ns(p_s) if p_s else 0
            if p_ns % self.frame_ns:
                raise ValueError(f'input {name}: period {p_s} s is not a multiple of the frame')
            periods[name] = p_ns
            sub = self.subscription(msg_type, topic, self._input_cb(name))
            self._topics_of[name] = sub.topic_name
        self.sync = FrameSync(periods)
        self._on_frame = on_frame
        self._next_t = 0
        self._seen_t = -1
        self._wait_since: Optional[float] = None
        # /clock says that time has reached t even when no input is due then (a 2 s
        # estimator between 10 s magnetometer samples); it is never waited for
        self.subscription(Clock, '/clock', self._on_clock_tick)
        self.create_timer(min(0.05, self.timeout_s / 4.0), self._frame_watchdog)

    def _on_clock_tick(self, msg: Clock) -> None:
        t = self.elapsed_ns(stamp_ns(msg.clock))
        if t > self._seen_t:
            self._seen_t = t
            self._try_fire()
            self.report_progress(self._seen_t)

    def input_arrived(self, name: str) -> None:
        """Hook called on every message of a lockstep input before it is stored."""

    def _input_cb(self, name: str) -> Callable[[Any], None]:
        def cb(msg: Any) -> None:
            self.input_arrived(name)
            t = self.elapsed_ns(stamp_ns(msg.header.stamp))
            self.sync.add(name, t, msg)
            if t > self._seen_t:
                self._seen_t = t
            self._try_fire()
        return cb

    def _try_fire(self) -> None:
        while self._seen_t >= self._next_t:
            t = self._next_t
            if not self.real_time and not self.sync.ready(t):
                if self._wait_since is None:
                    self._wait_since = time.monotonic()
                return
            self._fire(t, [])

    def _fire(self, t: int, missing: List[str]) -> None:
        msgs = {name: self.sync.value(name, t) for name in self.sync.names}
        self._wait_since = None
        self._next_t = t + self._own_period_ns
        self.sync.prune(t)
        self.frames += 1
        self.sim_t_ns = t
        self._on_frame(t, msgs, missing)
        self.diagnostics.frame(t)
        if self.is_last_frame(t, self._own_period_ns):
            self.report_progress(max(t, self._seen_t), final=True)

    def _frame_watchdog(self) -> None:
        if self._wait_since is None or time.monotonic() - self._wait_since < self.timeout_s:
            return
        t = self._next_t
        missing = [self._topics_of[n] for n in self.sync.missing(t)]
        self.count_missed(missing, t)
        self._fire(t, missing)
        self._try_fire()

    # ------------------------------------------------------------------ handshake
    def _expectations(self) -> List[tuple]:
        out = []
        for item in self.param('expected_matches', ['']):
            if not item:
                continue
            try:
                kind, rest = item.split(':', 1)
                topic, n = rest.rsplit('=', 1)
                out.append((kind, self.resolve_topic_name(topic), int(n)))
            except ValueError as exc:
                raise ValueError(f'bad expected_matches entry {item!r} '
                                 '(want "pub:<topic>=<n>" or "sub:<topic>=<n>")') from exc
        return out

    def unmatched(self) -> List[str]:
        """Handshake expectations not met yet, as readable strings."""
        missing = []
        for kind, topic, n in self._expectations():
            table = self._pubs if kind == 'pub' else self._subs
            ent = table.get(topic)
            if ent is None:
                missing.append(f'{kind}:{topic} (no such endpoint in {self.get_name()})')
                continue
            have = ent.get_subscription_count() if kind == 'pub' else ent.get_publisher_count()
            if have < n:
                missing.append(f'{kind}:{topic} {have}/{n}')
        return missing

    def start_handshake(self, on_ready: Optional[Callable[[], None]] = None) -> None:
        """Poll matching every 20 ms; when complete publish ready and call ``on_ready``."""
        self._on_ready = on_ready
        self._hs_t0 = time.monotonic()
        self._hs_warned = 0.0
        self._hs_timer = self.create_timer(0.02, self._check_ready)

    def _check_ready(self) -> None:
        missing = self.unmatched()
        if missing:
            waited = time.monotonic() - self._hs_t0
            if waited - self._hs_warned > 10.0:
                self._hs_warned = waited
                self.get_logger().warning(
                    f'still waiting for endpoints after {waited:.0f} s: ' + ', '.join(missing))
            return
        self._hs_timer.cancel()
        self.destroy_timer(self._hs_timer)
        self._ready_sent = True
        self._ready_pub.publish(String(data=self.get_name()))
        if self._on_ready is not None:
            self._on_ready()

    # ------------------------------------------------------------------ time and status
    def elapsed_ns(self, stamp_ns: int) -> int:
        """Elapsed sim time of an absolute stamp."""
        return int(stamp_ns) - self.epoch_ns

    def stamp(self, elapsed_ns: int):
        """Absolute ``builtin_interfaces/Time`` of an elapsed sim time."""
        return to_stamp(self.epoch_ns + int(elapsed_ns))

    def count_missed(self, inputs: List[str], t_ns: int) -> None:
        """Record a frame whose inputs ``inputs`` timed out, and log it."""
        self.missed_frames += 1
        self.last_missed_input = ','.join(inputs)
        self.get_logger().warning(
            f'frame t={t_ns / NS_PER_S:.3f} s: no {self.last_missed_input} within '
            f'{self.timeout_s:g} s wall; going on with the last value '
            f'(missed frames: {self.missed_frames})')

    def report_progress(self, seen_ns: int, final: bool = False) -> None:
        """Publish ``lockstep/progress`` every PROGRESS_EVERY frames of sim time this node
        has received (``seen_ns``: every message stamped up to it is read) and once when it
        has processed its last frame of the run (``final``); the clock master uses it for
        flow control and to end the run only when every node is done."""
        mark = seen_ns // (PROGRESS_EVERY * self.frame_ns)
        if mark == self._progress_mark and not final:
            return
        self._progress_mark = mark
        msg = LockstepStatus()
        msg.header.stamp = self.stamp(seen_ns)
        msg.node = self.get_name()
        msg.frames = int(self.frames)
        msg.missed_frames = int(self.missed_frames)
        msg.final = bool(final)
        self._progress_pub.publish(msg)

    def is_last_frame(self, t_ns: int, period_ns: int) -> bool:
        """True when frame ``t_ns`` is this node's last one of a run of ``duration_s``."""
        return self.duration_ns > 0 and t_ns + period_ns > self.duration_ns

    def publish_status(self, final: bool = False) -> None:
        """Publish ``lockstep/status`` (frames, missed frames, wall time).

        After the ``final`` one, the periodic timer publishes nothing more, so the final
        status stays the latest a listener has.
        """
        if getattr(self, '_final_sent', False):
            return
        self._final_sent = bool(final)
        msg = LockstepStatus()
        msg.header.stamp = self.stamp(self.sim_t_ns)   # sim time of the last frame
        msg.node = self.get_name()
        msg.frames = int(self.frames)
        msg.missed_frames = int(self.missed_frames)
        msg.last_missed_input = self.last_missed_input
        msg.wall_time = time.monotonic() - self._wall0
        self._status_pub.publish(msg)
