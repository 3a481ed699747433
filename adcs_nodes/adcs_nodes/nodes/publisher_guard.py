"""Publisher identity of lockstep inputs: only the launched node's publisher is used.

A consumer given ``expected_publishers`` (``"<topic>=<node name>"`` per guarded input) locks
each guarded topic at the end of the start handshake to the named node's publisher GID(s) and
then drops a message of another publisher (``foreign_publisher``), a stamp already received
(``duplicate_stamp``) or older than the last :data:`HISTORY` (``old_stamp``), or one before
the lock (``before_handshake``); a later publisher is reported once (``second_publisher``),
except the expected node's own new one once none of the locked ones is left (a lifecycle
cleanup and configure: a relock). Events are logged (throttled), counted on ``/diagnostics``
and published on :data:`EVENTS_TOPIC`. In-process deliveries carry no message info: only
their stamps are checked. What it does not prevent: ``docs/security.md``.
:class:`PublisherGuard` is the pure bookkeeping; :class:`NodeGuard` the rclpy glue.
"""
from __future__ import annotations

import collections
import inspect
import time
from typing import Any, Deque, Dict, Iterable, List, Optional, Set, Tuple

#: Why a message (or a publisher) was refused; keys of :attr:`PublisherGuard.counts`.
REASONS = ('foreign_publisher', 'duplicate_stamp', 'old_stamp', 'before_handshake',
           'second_publisher')
#: Stamps remembered per guarded topic for the duplicate check.
HISTORY = 4096
#: Events published on the events topic per wall second at most (the rest are counted).
MAX_EVENTS_PER_S = 100
EVENTS_TOPIC = 'adcs/security_events'
PARAM = 'expected_publishers'      # (its spec: ``nodes.params.COMMON``)


def parse_expected(entries: Iterable[str]) -> Dict[str, str]:
    """``["<topic>=<node>", ...]`` -> ``{topic: node}`` (empty entries skipped); ``ValueError``
    for an entry without ``=``, an empty topic or node, or a topic given twice."""
    out: Dict[str, str] = {}
    for entry in entries:
        entry = str(entry).strip()
        if not entry:
            continue
        topic, sep, node = entry.rpartition('=')
        topic, node = topic.strip(), node.strip()
        if not sep or not topic or not node:
            raise ValueError(f'bad {PARAM} entry {entry[:100]!r} (want "<topic>=<node name>")')
        if topic in out:
            raise ValueError(f'{PARAM}: topic {topic!r} given twice')
        out[topic] = node
    return out


def gid_hex(gid: Optional[bytes]) -> str:
    """Readable GID (hex), ``'-'`` for none."""
    return '-' if gid is None else bytes(gid).hex()


class PublisherGuard:
    """Which publisher may feed each guarded topic (``expected``: ``{resolved topic: node
    name}``), and which stamps it has sent (``history`` remembered per topic, >= 1)."""

    def __init__(self, expected: Dict[str, str], history: int = HISTORY) -> None:
        if int(history) < 1:
            raise ValueError('history must be >= 1')
        self.expected = dict(expected)
        self.history = int(history)
        self.allowed: Dict[str, Set[bytes]] = {}
        self.known: Dict[str, Set[bytes]] = {t: set() for t in self.expected}
        self._stamps: Dict[str, Set[int]] = {t: set() for t in self.expected}
        self._order: Dict[str, Deque[int]] = {t: collections.deque() for t in self.expected}
        self.counts: Dict[str, int] = {r: 0 for r in REASONS}
        self.by_topic: Dict[Tuple[str, str], int] = collections.Counter()
        self.last_event = ''
        self.relocks, self.last_relock = 0, ''

    @property
    def topics(self) -> List[str]:
        """The guarded topics."""
        return list(self.expected)

    @property
    def locked(self) -> bool:
        """True once every guarded topic is locked."""
        return all(t in self.allowed for t in self.expected)

    @property
    def total(self) -> int:
        """Events of every reason so far."""
        return sum(self.counts.values())

    def lock(self, topic: str, gids: Iterable[bytes]) -> None:
        """Accept ``topic`` only from the publishers ``gids`` from now on (``KeyError``: not
        guarded; ``ValueError``: no gids, the expected node has no publisher there)."""
        if topic not in self.expected:
            raise KeyError(topic)
        allowed = {bytes(g) for g in gids}
        if not allowed:
            raise ValueError(f'{topic}: no publisher of {self.expected[topic]} to lock to')
        self.allowed[topic] = allowed
        self.known[topic] |= allowed

    def relock(self, topic: str, mine: Iterable[bytes], present: Iterable[bytes]) -> bool:
        """Lock ``topic`` to the expected node's publishers ``mine`` now when none of the
        locked ones is ``present`` any more (the node re-created its publisher); True if so."""
        mine = {bytes(g) for g in mine}
        if topic not in self.allowed or not mine or mine <= self.allowed[topic] or \
                self.allowed[topic] & {bytes(g) for g in present}:
            return False
        self.allowed[topic] = mine
        self.known[topic] |= mine
        self.relocks += 1
        return True

    def new_publishers(self, topic: str, gids: Iterable[bytes]) -> List[bytes]:
        """Publishers of a locked ``topic`` seen for the first time (each reported once)."""
        if topic not in self.allowed:
            return []
        new = [bytes(g) for g in gids if bytes(g) not in self.known[topic]]
        self.known[topic].update(new)
        return new

    def check(self, topic: str, gid: Optional[bytes], stamp_ns: int) -> Optional[str]:
        """Decide on one message: ``None`` to accept it, else the reason it is refused.

        ``gid`` None: delivered in process (no message info), only the stamp is checked.
        A refused message does not count as received (its stamp is not remembered).
        """
        if topic not in self.expected:
            return None
        if topic not in self.allowed:
            return 'before_handshake'
        if gid is not None and bytes(gid) not in self.allowed[topic]:
            return 'foreign_publisher'
        stamps, order = self._stamps[topic], self._order[topic]
        stamp_ns = int(stamp_ns)
        if stamp_ns in stamps:
            return 'duplicate_stamp'
        if len(order) >= self.history and stamp_ns < order[0]:
            return 'old_stamp'
        stamps.add(stamp_ns)
        order.append(stamp_ns)
        if len(order) > self.history:
            stamps.discard(order.popleft())
        return None

    def count(self, topic: str, reason: str, text: str) -> int:
        """Count one event; returns the number of events of this topic and reason so far."""
        if reason not in self.counts:
            raise KeyError(reason)
        self.counts[reason] += 1
        self.by_topic[(topic, reason)] += 1
        self.last_event = text
        return self.by_topic[(topic, reason)]

    def diagnostic_values(self) -> Dict[str, str]:
        """Counters for ``/diagnostics``."""
        out = {'security_events': str(self.total)}
        out.update({f'security_{r}': str(n) for r, n in self.counts.items()})
        out['last_security_event'] = self.last_event
        out.update(relocks=str(self.relocks), last_relock=self.last_relock)
        return out


class NodeGuard:
    """rclpy glue of :class:`PublisherGuard` for one :class:`LockstepNode` (see module doc).

    Built by :func:`for_node`; hooks: a start-handshake ready check, :meth:`lock` when the
    handshake completes, :meth:`wrap` for input callbacks, a 1 s graph check.
    """

    def __init__(self, node: Any, expected: Dict[str, str]) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        from adcs_nodes.nodes.adapter import QOS_DATA
        self.node = node
        self.core = PublisherGuard({node.resolve_topic_name(t): n
                                    for t, n in expected.items()})
        self._array = DiagnosticArray
        self.pub = node.publisher(DiagnosticArray, EVENTS_TOPIC, QOS_DATA)
        self._window = (0.0, 0)        # (wall second, events published in it)
        self.suppressed = 0
        node.add_ready_check(self.missing)
        self._graph_timer = None
        self._relock_after: Dict[str, float] = {}

    # ------------------------------------------------------------------ handshake
    def _publishers(self, topic: str) -> Tuple[List[bytes], List[Tuple[str, bytes]]]:
        """(GIDs of the expected node's publishers, [(node, gid)] of the others) now."""
        want = self.core.expected[topic]
        mine, others = [], []
        for info in self.node.get_publishers_info_by_topic(topic):
            full = info.node_namespace.rstrip('/') + '/' + info.node_name
            gid = bytes(info.endpoint_gid)
            if info.node_name == want or full == want:
                mine.append(gid)
            else:
                others.append((full, gid))
        return mine, others

    def missing(self) -> List[str]:
        """Ready check: guarded topics with no publisher of the expected node yet."""
        if self.core.locked:
            return []
        return [f'{t} (no publisher of {n} yet: {PARAM})'
                for t, n in self.core.expected.items() if not self._publishers(t)[0]]

    def lock(self) -> None:
        """Lock every guarded topic to its expected node's publisher(s) (handshake done)."""
        for topic, name in self.core.expected.items():
            mine, others = self._publishers(topic)
            self.core.lock(topic, mine)
            self.node.get_logger().info(
                f'{topic}: accepted only from {name} (publisher {", ".join(map(gid_hex, mine))})')
            for full, gid in others:
                self.core.known[topic].add(gid)
                self.event(topic, 'second_publisher', gid, None,
                           f'{topic}: another publisher at the handshake, {full} '
                           f'({gid_hex(gid)}): not trusted')
        self._graph_timer = self.node.create_timer(1.0, self.check_graph)

    def relock(self, topic: str) -> bool:
        """Lock ``topic`` to its expected node's new publisher if that node re-created it
        (:meth:`PublisherGuard.relock`); logged, and said on ``/diagnostics``."""
        now = time.monotonic()
        if now < self._relock_after.get(topic, 0.0):
            return False                      # (a stranger's flood: the graph asked 10/s)
        mine, others = self._publishers(topic)
        if not self.core.relock(topic, mine, mine + [g for _, g in others]):
            self._relock_after[topic] = now + 0.1
            return False
        self.core.last_relock = (
            f'{topic}: {self.core.expected[topic]} re-created its publisher (a lifecycle '
            f'cleanup and configure?) at t={self.node.sim_t_ns / 1e9:g} s; its old one is '
            f'gone: accepted from now on ({", ".join(map(gid_hex, mine))})')
        self.node.get_logger().info(self.core.last_relock)
        return True

    def check_graph(self) -> None:
        """Report a publisher that joined a guarded topic after the lock (once each), or
        lock to it when it is the expected node's own new one (:meth:`relock`)."""
        for topic in self.core.topics:
            if self.node.count_publishers(topic) <= len(self.core.known[topic]):
                continue
            if self.relock(topic):
                continue
            infos = {bytes(i.endpoint_gid): i for i in
                     self.node.get_publishers_info_by_topic(topic)}
            for gid in self.core.new_publishers(topic, infos):
                i = infos[gid]
                self.event(topic, 'second_publisher', gid, None,
                           f'{topic}: a second publisher joined, {i.node_namespace.rstrip("/")}'
                           f'/{i.node_name} ({gid_hex(gid)}): its messages are dropped')

    # ------------------------------------------------------------------ messages
    def wrap(self, topic_of, callback):
        """A two-argument subscription callback (rclpy passes the message info) that calls
        ``callback(msg)`` only for an accepted message. ``topic_of``: the resolved topic, or
        a callable giving it (evaluated per message)."""
        core = self.core

        def guarded(msg: Any, info: Any) -> None:
            if isinstance(msg, tuple):      # EventsExecutor: the (msg, info) pair, see below
                msg, info = msg
            topic = topic_of() if callable(topic_of) else topic_of
            gid = None
            if info is not None:
                gid = (info.get('publisher_gid') or {}).get('data')
            stamp = self.node.elapsed_ns(
                msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            reason = core.check(topic, gid, stamp)
            if reason == 'foreign_publisher' and self.relock(topic):
                reason = core.check(topic, gid, stamp)     # the expected node's new one
            if reason is None:
                callback(msg)
                return
            self.event(topic, reason, gid, stamp,
                       f'{topic}: message stamped t={stamp / 1e9:.9g} s dropped ({reason}, '
                       f'publisher {gid_hex(gid)}, expected {core.expected[topic]})')
        return WithInfo(guarded)

    def event(self, topic: str, reason: str, gid: Optional[bytes], stamp_ns: Optional[int],
              text: str) -> None:
        """Log (throttled), count and publish one event."""
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
        n = self.core.count(topic, reason, text)
        self.node.get_logger().warning(
            f'security: {text} [{reason} on this topic: {n}, all events: {self.core.total}]',
            throttle_duration_sec=5.0)
        now = time.monotonic()
        second, sent = self._window
        if now - second >= 1.0:
            second, sent = now, 0
        if sent >= MAX_EVENTS_PER_S:
            self.suppressed += 1
            self._window = (second, sent)
            return
        self._window = (second, sent + 1)
        st = DiagnosticStatus(level=DiagnosticStatus.WARN, name=self.node.get_name(),
                              hardware_id='adcs', message=text)
        allowed = sorted(self.core.allowed.get(topic, ()))
        st.values = [KeyValue(key=k, value=str(v)) for k, v in (
            ('topic', topic), ('reason', reason), ('publisher_gid', gid_hex(gid)),
            ('expected_node', self.core.expected.get(topic, '')),
            ('expected_gids', ', '.join(map(gid_hex, allowed))),
            ('message_stamp_s', '-' if stamp_ns is None else f'{stamp_ns / 1e9:.9f}'),
            ('count', n), ('suppressed', self.suppressed))]
        self.suppressed = 0
        msg = self._array()
        msg.header.stamp = self.node.stamp(self.node.sim_t_ns)
        msg.status = [st]
        self.pub.publish(msg)


class WithInfo:
    """A subscription callback that gets the message info from any executor: rclpy's
    ``SingleThreadedExecutor`` calls ``cb(msg, info)``, the ``EventsExecutor`` of rclpy 9.1
    ``cb((msg, info))`` (a plain two-argument function fails there)."""

    __signature__ = inspect.Signature([
        inspect.Parameter('msg', inspect.Parameter.POSITIONAL_ONLY),
        inspect.Parameter('info', inspect.Parameter.POSITIONAL_ONLY)])

    def __init__(self, fn) -> None:
        self.fn = fn

    def __call__(self, msg: Any, info: Any = None) -> None:
        self.fn(msg, info)


def for_node(node: Any) -> Optional[NodeGuard]:
    """The node's :class:`NodeGuard` (built on the first call from its ``expected_publishers``
    parameter), or None when the parameter is empty (unguarded)."""
    if hasattr(node, '_publisher_guard'):
        return node._publisher_guard
    expected = parse_expected(node.param(PARAM, ['']) or [])
    node._publisher_guard = NodeGuard(node, expected) if expected else None
    return node._publisher_guard
