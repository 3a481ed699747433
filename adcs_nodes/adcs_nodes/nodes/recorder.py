"""Recorder node: every topic (or a list), raw CDR, into a rosbag2 MCAP bag via ``rosbags``.

``ros2 bag`` is no PyPI wheel, so this node is the project's recorder: ``raw=True``
subscriptions, the bytes written unchanged into a rosbag2 directory (``docs/topics.md``).

Parameters: :data:`PARAMS` (all read-only). ``topics`` entries may carry their type,
``topic=pkg/msg/Name``; empty records every topic found on the graph (re-scanned every
``discovery_period_s``). ``expected_matches`` (``sub:<topic>=<n>``) is the lockstep start
handshake: when every recording subscription has its publishers, the node publishes its name
once on the latched ``lockstep/ready``.

``recorder/status`` (``adcs_msgs/LockstepStatus``): ``frames`` = messages written,
``header.stamp`` = latest ``/clock``, ``missed_frames`` = messages the middleware reported
lost, ``last_missed_input`` = topic of the last loss (or ``write failed: ...``), ``wall_time``
= wall seconds since the first message; every ``status_period_s`` and every
:data:`STATUS_EVERY_CLOCKS` ``/clock`` messages (the clock master's flow control).

QoS: a topic is subscribed once it has a publisher: reliable (best effort if any publisher
is), KEEP_LAST 1000, transient local when every publisher is (latched topics); the publishers'
QoS are stored as ``offered_qos_profiles``.

Log times (``docs/topics.md``, "Bags"): a message's own stamp, else the latest ``/clock``
(held, at most :data:`MAX_HELD`, until the first one), else without a ``/clock`` publisher
its receive time.

Crash safety: the pending chunk is closed and flushed every ``flush_sim_s`` of log time or
``flush_period_s`` of wall time (:func:`adcs_nodes.bag.flush_writer`), so a killed recorder
loses at most that much; the tools read the unfinished file (:func:`adcs_nodes.bag.recover_mcap`).
A write error (disk full) stops the recording, not the process: logged, reported in
``recorder/status``, exit :data:`EXIT_WRITE_FAILED`.
"""
from __future__ import annotations

import errno
import fnmatch
import importlib
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Set

from adcs_msgs.msg import LockstepStatus
from builtin_interfaces.msg import Time
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import String

from adcs_nodes.core import handshake
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.adapter import QOS_READY
from adcs_nodes.registry import Param
from adcs_nodes.bag import (BAG_VERSION, cdr_stamp_ns, ensure_type, flush_writer,
                            make_typestore, stamp_offset)
from adcs_nodes.distro import close_writer

DEFAULT_EXCLUDE = ['/rosout', '/parameter_events']
QUEUE_DEPTH = 1000
STATUS_TOPIC = 'recorder/status'
READY_TOPIC = 'lockstep/ready'
HANDSHAKE_PERIOD_S = 0.02
#: ``recorder/status`` is also published every this many ``/clock`` messages written (as the
#: lockstep nodes report progress every 10 frames), so the clock master's flow control sees
#: the recorder's progress in frames, not only every ``status_period_s`` of wall time.
STATUS_EVERY_CLOCKS = 10
CLOCK_TYPE = 'rosgraph_msgs/msg/Clock'
#: Exit code of a recorder stopped by a write error (disk full); the launcher names it.
EXIT_WRITE_FAILED = 3
#: Prefix of ``recorder/status.last_missed_input`` after a write error.
WRITE_FAILED_PREFIX = 'write failed: '
DISK_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
#: Unstamped messages held until the first ``/clock`` of a simulation; more are logged at
#: their receive time.
MAX_HELD = 10_000

#: The recorder's parameters (module docstring). All read-only: the bag, its topics and its
#: flush periods are set when the recording starts.
PARAMS = (
    Param('output', 'str', '', '-', "bag directory to create ('': adcs_bag_<UTC time>; an "
          'existing path is refused)', read_only=True),
    Param('topics', 'str[]', [], '-', 'topics to record, optionally topic=pkg/msg/Name '
          '(empty: every topic)', read_only=True),
    Param('exclude', 'str[]', list(DEFAULT_EXCLUDE), '-', 'topics (or fnmatch patterns) never '
          'recorded', read_only=True),
    Param('discovery_period_s', 'float', 0.5, 's', 'wall-clock period of the graph scan',
          positive=True, max=3600.0, read_only=True),
    Param('status_period_s', 'float', 0.5, 's', 'wall-clock period of recorder/status',
          positive=True, max=3600.0, read_only=True),
    Param('flush_sim_s', 'float', 2.0, 's', 'write the pending chunk once it spans this log '
          '(simulated) time', positive=True, max=1e6, read_only=True),
    Param('flush_period_s', 'float', 0.5, 's', 'write the pending chunk at least this often '
          '(wall clock)', positive=True, max=3600.0, read_only=True),
    Param('fsync_period_s', 'float', 2.0, 's', 'fsync the bag file this often (wall clock)',
          positive=True, max=3600.0, read_only=True),
    Param('expected_matches', 'str[]', [], '-', 'start handshake: "sub:<topic>=<n>" publishers '
          'matched to our subscription (lockstep/ready when all hold)', read_only=True),
)


class OutputExistsError(FileExistsError, ValueError):
    """The bag output path exists already (a configuration error: choose another ``output``)."""


def default_output() -> str:
    """Default bag directory name ``adcs_bag_YYYY_MM_DD-HH_MM_SS`` (UTC)."""
    return 'adcs_bag_' + datetime.now(timezone.utc).strftime('%Y_%m_%d-%H_%M_%S')


def import_message_class(msgtype: str):
    """Python class of the ROS interface ``pkg/msg/Name`` (no ``rosidl_runtime_py`` needed):
    ``ValueError`` for a malformed name, ``ImportError``/``AttributeError`` if not installed."""
    parts = msgtype.split('/')
    if len(parts) != 3:
        raise ValueError(f'message type must look like pkg/msg/Name, got {msgtype!r}')
    pkg, iface, name = parts
    return getattr(importlib.import_module(f'{pkg}.{iface}'), name)


def _qos_time(duration) -> QosTime:
    return QosTime(*divmod(int(duration.nanoseconds), 1_000_000_000))


def _to_bag_qos(profile: QoSProfile) -> Qos:
    """rosbags ``Qos`` of an rclpy ``QoSProfile`` (enum members are matched by name)."""
    def conv(enum_cls, policy):
        return enum_cls.__members__.get(policy.name, enum_cls.UNKNOWN)

    return Qos(
        history=conv(QosHistory, profile.history),
        depth=int(profile.depth),
        reliability=conv(QosReliability, profile.reliability),
        durability=conv(QosDurability, profile.durability),
        deadline=_qos_time(profile.deadline),
        lifespan=_qos_time(profile.lifespan),
        liveliness=conv(QosLiveliness, profile.liveliness),
        liveliness_lease_duration=_qos_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
    )


def subscription_qos(publisher_profiles: Sequence[QoSProfile]) -> QoSProfile:
    """QoS the recorder uses for a topic with these publishers (see the module docstring)."""
    best_effort = any(p.reliability == ReliabilityPolicy.BEST_EFFORT
                      for p in publisher_profiles)
    latched = bool(publisher_profiles) and all(
        p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publisher_profiles)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=QUEUE_DEPTH,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


@dataclass
class _Topic:
    """Book-keeping of one recorded topic."""

    name: str
    msgtype: str
    connection: object
    subscription: object
    stamp_offset: Optional[int]
    count: int = 0
    lost: int = 0


class RecorderNode(node_params.SpecParameters, Node):
    """Record topics raw into a rosbag2 MCAP bag (module docstring). ``**kwargs`` go to
    :class:`rclpy.node.Node`. Raises :class:`OutputExistsError` (a ``ValueError``: the runtime
    reports a configuration error) if ``output`` exists."""

    def __init__(self, node_name: str = 'recorder', **kwargs) -> None:
        # given names declared at once (unknown ones refused with a did-you-mean)
        kwargs.setdefault('automatically_declare_parameters_from_overrides', True)
        super().__init__(node_name, **kwargs)
        self._writer: Optional[Writer] = None
        try:
            self._configure()
        except Exception:
            if self._writer is not None:  # opened before the failure: leave a valid bag
                self._writer.close()
                self._writer = None
            super().destroy_node()
            raise

    def _configure(self) -> None:
        """Read the parameters, open the bag, create the timers and the status publisher."""
        p = node_params.declare_all(self, PARAMS)
        node_params.refuse_unknown(self)
        node_params.install_validator(self)

        output = p['output'] or default_output()
        self.output = Path(output)
        if self.output.exists():
            raise OutputExistsError(f"output {self.output} exists already, not overwriting "
                                    "(choose another 'output')")
        entries = [str(t) for t in p['topics'] if str(t)]
        self._declared_types: Dict[str, str] = {}
        wanted = set()
        for entry in entries:
            topic, _, msgtype = entry.partition('=')
            topic = self._resolve(topic.strip())
            wanted.add(topic)
            if msgtype.strip():
                self._declared_types[topic] = msgtype.strip()
        self._wanted: Optional[Set[str]] = wanted or None
        self._exclude = [self._resolve(t) for t in p['exclude']]
        self._expected = handshake.parse_expectations(p['expected_matches'], self._resolve)
        self._fsync_s = p['fsync_period_s']
        self._flush_sim_ns = int(p['flush_sim_s'] * 1e9)
        self._chunk_t0_ns: Optional[int] = None   # log time of the first pending message
        self._last_fsync = time.monotonic()
        self.write_error = ''
        self.exit_code = 0
        self.done = False

        self._store = make_typestore()
        self._writer = Writer(self.output, version=BAG_VERSION,
                              storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except OSError as exc:
            raise ValueError(f'cannot create the bag {self.output}: {exc.strerror or exc}') \
                from None
        self._writer.set_custom_data('recorder', 'adcs_nodes.nodes.recorder')

        self._topics: Dict[str, _Topic] = {}
        self._skipped: Set[str] = set()
        self.messages_written = 0
        self.messages_lost = 0
        self._last_lost_topic = ''
        self._latest_clock_ns, self._clock_seen = 0, False
        self._held: List[tuple] = []   # (topic, raw, receive time) before the first /clock
        self._clocks_written = 0
        self._clock_in_graph = False
        self._first_write_wall: Optional[float] = None

        self._status_pub = self.create_publisher(LockstepStatus, STATUS_TOPIC, 10)
        self._status_topic = self._status_pub.topic_name
        self._ready_pub = self.create_publisher(String, READY_TOPIC, QOS_READY)
        self.ready = False
        records_clock = not self._excluded('/clock') and (
            self._wanted is None or '/clock' in self._wanted)
        if not records_clock:
            # /clock recorded: its raw callback gives the latest clock, and a second
            # subscription would be an extra DDS match in the lockstep start handshake
            self.create_subscription(ClockMsg, '/clock', self._on_clock, QoSProfile(
                depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._last_discovery, self._t_start = 0.0, time.monotonic()
        self._discovery_timer, self._status_timer, self._handshake_timer, self._flush_timer = (
            self.create_timer(period, callback, clock=steady) for period, callback in (
                (p['discovery_period_s'], self.discover),
                (p['status_period_s'], self.publish_status),
                (HANDSHAKE_PERIOD_S, self._check_ready), (p['flush_period_s'], self.flush)))
        what = 'every topic' if self._wanted is None else ', '.join(sorted(self._wanted))
        self.get_logger().info(f'recording {what} into {self.output} '
                               f'(excluding {", ".join(self._exclude) or "nothing"})')
        self.discover()

    # ------------------------------------------------------------------ properties
    @property
    def counts(self) -> Dict[str, int]:
        """Messages written per topic."""
        return {name: rec.count for name, rec in self._topics.items()}

    @property
    def topics(self) -> List[str]:
        """Topics being recorded, in the order they were added."""
        return list(self._topics)

    @property
    def is_open(self) -> bool:
        """Whether the bag is still open for writing."""
        return self._writer is not None

    # ------------------------------------------------------------------ discovery
    def _resolve(self, topic: str) -> str:
        try:
            return self.resolve_topic_name(topic)
        except Exception:  # noqa: BLE001 - older rclpy without it, or an invalid name
            return topic if topic.startswith('/') else '/' + topic

    def _excluded(self, topic: str) -> bool:
        if topic == getattr(self, '_status_topic', None):
            return True
        return any(topic == pat or fnmatch.fnmatchcase(topic, pat) for pat in self._exclude)

    def discover(self) -> None:
        """Scan the graph once and subscribe to every new topic that has a publisher."""
        if self._writer is None:
            return
        self._last_discovery = time.monotonic()
        for topic, types in self.get_topic_names_and_types():
            if topic == '/clock' and not self._clock_in_graph:
                self._clock_in_graph = bool(self.get_publishers_info_by_topic(topic))
            if topic in self._topics or topic in self._skipped or self._excluded(topic):
                continue
            if self._wanted is not None and topic not in self._wanted:
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # the publishers' QoS decide ours: wait for one
            self._add_topic(topic, types, publishers)

    def _skip(self, topic: str, why: str) -> None:
        self._skipped.add(topic)
        self.get_logger().warning(f'not recording {topic}: {why}')

    def _add_topic(self, topic: str, types: Sequence[str], publishers) -> None:
        declared = self._declared_types.get(topic)
        msgtype = declared if declared in types else types[0]
        if len(types) > 1:
            self.get_logger().warning(f'{topic} has several types {list(types)}; '
                                      f'recording {msgtype}')
        if declared and declared != msgtype:
            self.get_logger().warning(f'{topic}: declared type {declared} but the graph has '
                                      f'{msgtype}; recording {msgtype}')
        try:
            msg_class = import_message_class(msgtype)
        except (ImportError, AttributeError, ValueError) as exc:
            self._skip(topic, f'cannot import {msgtype} ({exc})')
            return
        if not ensure_type(self._store, msgtype):
            self._skip(topic, f'no .msg definition found for {msgtype}')
            return
        profiles = [info.qos_profile for info in publishers]
        qos = subscription_qos(profiles)
        connection = self._writer.add_connection(
            topic, msgtype, typestore=self._store,
            offered_qos_profiles=[_to_bag_qos(p) for p in profiles])
        rec = _Topic(topic, msgtype, connection, None, stamp_offset(self._store, msgtype))
        events = SubscriptionEventCallbacks(
            message_lost=lambda info, r=rec: self._on_lost(r, info))
        rec.subscription = self.create_subscription(
            msg_class, topic, lambda raw, r=rec: self._on_message(r, raw), qos,
            event_callbacks=events, raw=True)
        self._topics[topic] = rec
        self.get_logger().info(
            f'recording {topic} [{msgtype}] ({qos.reliability.name.lower()}, '
            f'{qos.durability.name.lower()}, {len(publishers)} publisher(s))')

    # ------------------------------------------------------------------ handshake
    def unmatched(self) -> List[str]:
        """Start-handshake expectations not met yet (:func:`handshake.unmet`): ``sub``: the
        recording subscription of the topic has that many matched publishers; ``pub``: the
        recorder's publisher (``recorder/status``) that many matched subscriptions."""
        def matched(kind: str, topic: str) -> int:
            if kind == 'sub':
                rec = self._topics.get(topic)
                return rec.subscription.get_publisher_count() if rec is not None else 0
            return self._status_pub.get_subscription_count() if topic == self._status_topic \
                else 0
        return handshake.unmet(self._expected, matched, self.get_name())

    def _check_ready(self) -> None:
        """Handshake timer: publish our name on ``lockstep/ready`` once every match holds."""
        missing = self.unmatched()
        if missing and self._handshake_timer.timer_period_ns < 100_000_000 and \
                time.monotonic() - self._t_start > 1.0:     # slower after a second
            self._handshake_timer.cancel()
            self.destroy_timer(self._handshake_timer)
            self._handshake_timer = self.create_timer(0.1, self._check_ready, clock=Clock(
                clock_type=ClockType.STEADY_TIME))
        if missing:
            # scan faster than discovery_period_s while topics we wait for are not subscribed
            if time.monotonic() - self._last_discovery > 0.1 and any(
                    kind == 'sub' and topic not in self._topics
                    for kind, topic, _ in self._expected):
                self.discover()
            return
        self._handshake_timer.cancel()
        self.ready = True
        self._ready_pub.publish(String(data=self.get_name()))
        self.get_logger().info(f'ready: {len(self._expected)} expected match(es) hold')
        self.get_logger().info(runtime.start_cost(0))

    # ------------------------------------------------------------------ callbacks
    def _log_time_ns(self, rec: _Topic, raw: bytes) -> Optional[int]:
        """Log time of a message (module docstring); ``None``: hold it until the first /clock."""
        if rec.stamp_offset is not None:
            stamp = cdr_stamp_ns(raw, rec.stamp_offset)
            if stamp is not None and (stamp > 0 or rec.msgtype == CLOCK_TYPE):
                return stamp
        if self._clock_seen:
            return self._latest_clock_ns
        if not self._clock_in_graph:   # discovery may not have seen it yet
            self._clock_in_graph = self.count_publishers('/clock') > 0
        return None if self._clock_in_graph else time.time_ns()

    def _on_message(self, rec: _Topic, raw: bytes) -> None:
        if self._writer is None:
            return
        clock_tick = False
        if rec.msgtype == CLOCK_TYPE:
            stamp = cdr_stamp_ns(raw)
            if stamp is not None:
                self._latest_clock_ns = max(self._latest_clock_ns, stamp)
                self._clock_seen = clock_tick = True
        t_ns = self._log_time_ns(rec, raw)
        if t_ns is None and len(self._held) < MAX_HELD:
            self._held.append((rec, raw, time.time_ns()))
            return
        self._write(rec, raw, time.time_ns() if t_ns is None else t_ns)
        if clock_tick:
            self._clock_ticked()

    def _write(self, rec: _Topic, raw: bytes, t_ns: int) -> None:
        if self._writer is None:
            return
        try:
            self._writer.write(rec.connection, t_ns, raw)
        except OSError as exc:
            self._write_failed(exc)
            return
        if self._chunk_t0_ns is None:
            self._chunk_t0_ns = t_ns
        rec.count += 1
        self.messages_written += 1
        if self._first_write_wall is None:
            self._first_write_wall = time.monotonic()
        if abs(t_ns - self._chunk_t0_ns) >= self._flush_sim_ns:
            self.flush()

    def _clock_ticked(self) -> None:
        """A /clock arrived: write the held messages at it; progress for the flow control."""
        held, self._held = self._held, []
        for rec, raw, _ in held:
            self._write(rec, raw, self._latest_clock_ns)
        self._clocks_written += 1
        if self._clocks_written % STATUS_EVERY_CLOCKS == 0:
            self.publish_status()

    def flush(self, fsync: Optional[bool] = None) -> None:
        """Write the pending chunk and flush it to the kernel (module docstring, 'Crash safety').

        ``fsync``: also force the file to the disk; default: when ``fsync_period_s`` has
        passed since the last one. Also called by the wall-clock timer.
        """
        if self._writer is None:
            return
        now = time.monotonic()
        if fsync is None:
            fsync = now - self._last_fsync >= self._fsync_s
        try:
            flush_writer(self._writer, fsync=fsync)
        except OSError as exc:
            self._write_failed(exc)
            return
        self._chunk_t0_ns = None
        if fsync:
            self._last_fsync = now

    def _write_failed(self, exc: OSError) -> None:
        """A write error (disk full): stop recording, keep what is on disk, tell and exit."""
        writer, self._writer = self._writer, None
        full = exc.errno in DISK_FULL_ERRNOS
        what = 'disk full' if full else 'write error'
        self.write_error = f'{what}: {exc.strerror or exc}'
        try:
            writer.abort()   # no summary: the disk cannot take it; the records stay readable
        except Exception:  # noqa: BLE001 - the file may refuse even its close
            pass
        self.get_logger().error(
            f'{self.write_error} while writing {self.output}: recording stopped. The bag keeps '
            f'the messages written before (about {self.messages_written}); adcs export / adcs '
            'report read the unfinished file' + ('; free some space' if full else ''))
        self.exit_code = EXIT_WRITE_FAILED
        self.done = True
        for timer in (self._discovery_timer, self._handshake_timer, self._flush_timer):
            timer.cancel()
        self.publish_status()

    def _on_lost(self, rec: _Topic, info) -> None:
        lost = int(getattr(info, 'total_count_change', 1) or 1)
        rec.lost += lost
        self.messages_lost += lost
        self._last_lost_topic = rec.name
        self.get_logger().warning(f'{lost} message(s) lost on {rec.name}')

    def _on_clock(self, msg: ClockMsg) -> None:
        stamp = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        self._latest_clock_ns = max(self._latest_clock_ns, stamp)
        self._clock_seen = True
        self._clock_ticked()

    def publish_status(self) -> None:
        """Publish ``recorder/status`` now (also called by the wall-clock timer)."""
        msg = LockstepStatus()
        sec, nanosec = divmod(self._latest_clock_ns, 1_000_000_000)
        msg.header.stamp = Time(sec=int(sec), nanosec=int(nanosec))
        msg.node = self.get_name()
        msg.frames = self.messages_written
        msg.missed_frames = min(self.messages_lost, 2**32 - 1)
        msg.last_missed_input = (WRITE_FAILED_PREFIX + self.write_error if self.write_error
                                 else self._last_lost_topic)
        if self._first_write_wall is not None:
            msg.wall_time = time.monotonic() - self._first_write_wall
        self._status_pub.publish(msg)

    # ------------------------------------------------------------------ shutdown
    def close(self) -> None:
        """Stop recording and finalise the bag (MCAP summary + ``metadata.yaml``). Idempotent."""
        writer, self._writer = getattr(self, '_writer', None), None
        if writer is None:
            return
        self._discovery_timer.cancel()
        self._handshake_timer.cancel()
        self._flush_timer.cancel()
        for rec in self._topics.values():
            self.destroy_subscription(rec.subscription)
        self._writer, held, self._held = writer, self._held, []
        for rec, raw, received_ns in held:      # no /clock came: at their receive time
            self._write(rec, raw, received_ns)
        writer, self._writer = self._writer, None
        if writer is None:                      # a write error above
            return
        try:
            close_writer(writer)      # metadata carries the real ROS distro, not 'rosbags'
        except OSError as exc:
            self._writer = writer
            self._write_failed(exc)
            return
        except Exception as exc:  # noqa: BLE001 - report, the node is going down anyway
            self.get_logger().error(f'closing {self.output} failed: {exc}')
            raise
        self.publish_status()
        self.get_logger().info(f'bag {self.output} closed: {self.messages_written} messages '
                               f'on {len(self._topics)} topics')

    def destroy_node(self) -> None:
        """Close the bag (if still open) before destroying the node."""
        self.close()
        super().destroy_node()


def main(args=None) -> int:
    """Entry point ``ros2 run adcs_nodes recorder``."""
    return runtime.run(RecorderNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
