"""``adcs replay BAG``: publish recorded sensor topics as a driver would, without ``sim_node``.

The flight software (estimator, controllers, manager) then runs in live mode against the
replayed samples exactly as against real drivers (``docs/topics.md``, "Plug in a real sensor").

What is published
-----------------
* the sensor topics of the bag (``/sensors/*``; or ``--topics``), each message at the wall time
  its ``header.stamp`` comes due (``--rate F``: F sim seconds per wall second), with its
  original stamp (plus ``--time-offset``), best-effort like most drivers (``SensorDataQoS``);
* ``/tf_static`` (the sensor mounts), latched, once at the start;
* ``/clock`` (every 10 ms of wall time, the replayed time), unless ``--now``: nodes started
  with ``use_sim_time:=true`` take their time from it, as with ``ros2 bag play --clock``.

Time
----
``--time-offset S`` adds S seconds to every stamp and to ``/clock`` (stamps off the
simulator's frame grid). ``--now`` shifts the stamps so that the first sample is stamped with
the wall clock at the start and publishes no ``/clock`` (a driver with wall-clock stamps;
needs ``--rate 1``). In both cases the flight software's onboard orbit model must be told the
same shift: the replay prints the ``epoch`` to give it (the bag's scenario epoch + offset).

Lockstep (``--lockstep``): the recorded estimates again, bit for bit
-------------------------------------------------------------------
``adcs replay BAG --lockstep [--nodes estimator]`` feeds flight-software nodes started alone in
``timing_mode: lockstep`` with exactly what they received in the recorded run, so they compute
exactly what they published then (``tests/integration/test_replay_lockstep.py``):

* the inputs each node awaited in the run (the ``sub:`` entries of its handshake in the graph
  of the bag's ``scenario.yaml``: ``/clock``, ``/tf_static`` mounts, sensor topics, the
  actuator command an estimator takes from the previous frame, ...), reliable with depth 100
  (``/tf_static`` latched), their recorded bytes with their original stamps;
* frame by frame: every message stamped up to a recorded ``/clock`` tick, then that tick;
* paced by the nodes: it waits for their ``lockstep/ready``, and never runs more than
  ``MAX_LAG_FRAMES`` frames ahead of what each node reports read (``lockstep/progress``) or
  processed (``lockstep/status``), so no queue overflows and nothing waits a fixed time. It
  ends when each node has processed the last frame it processed in the recording (or sent its
  final progress).

The nodes must run with the parameters the launcher gave them:
``adcs replay BAG --lockstep --write-params FILE`` writes them (from the bag's scenario and
duration, ``timing_mode: lockstep``, the handshake reduced to the replayed inputs) and exits;
start each node with ``--ros-args -r __node:=NAME --params-file FILE``.

Messages are published as the recorded CDR bytes (only the 8 stamp bytes are rewritten when a
stamp changes), so nothing is lost or rounded. Exit codes: 0 done, 1 a lockstep node not ready
or stalled (``--wait``, ``--stall-timeout``), 2 bad input (bag, topics, options, a bag without
the topics the nodes need), 130 interrupted.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib
import os
import struct
import sys
import time
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from typing import Callable, Dict, List, Optional, Sequence

from adcs_nodes.bag import cdr_stamp_ns, open_bag

SENSOR_PREFIX = '/sensors/'
STATIC_TOPICS = ('/tf_static',)
CLOCK_TICK_S = 0.01
#: After every replayed topic has a subscriber [s]: the subscriber's side matches our writer
#: on its own schedule, and a best-effort sample sent before it did is dropped (seen in CI:
#: the first of 3 magnetometer samples never reached a live estimator). ASSUMPTION: 1 s
#: covers that lag on one machine, also under load.
MATCH_SETTLE_S = 1.0
NS_PER_S = 1_000_000_000


class ReplayError(ValueError):
    """Bad bag, topic selection or options (exit code 2)."""


class LockstepStall(RuntimeError):
    """A lockstep node never became ready or stopped making progress (exit code 1)."""


@dataclass
class Sample:
    """One message to publish: topic, stamp [ns] (already shifted), raw CDR bytes."""

    topic: str
    stamp_ns: int
    data: bytes


def _message_class(msgtype: str):
    pkg, kind, name = msgtype.split('/')
    try:
        return getattr(importlib.import_module(f'{pkg}.{kind}'), name)
    except (ImportError, AttributeError) as exc:
        raise ReplayError(f'type {msgtype} is not installed here ({exc})') from None


def _restamp(raw: bytes, stamp_ns: int) -> bytes:
    """``raw`` CDR with its leading ``builtin_interfaces/Time`` set to ``stamp_ns``."""
    fmt = '<iI' if raw[1] & 0x01 else '>iI'
    out = bytearray(raw)
    struct.pack_into(fmt, out, 4, stamp_ns // NS_PER_S, stamp_ns % NS_PER_S)
    return bytes(out)


def _bag_epoch(bag: str) -> Optional[datetime]:
    """The scenario epoch of a bag recorded by ``adcs run`` (its ``scenario.yaml``), or None."""
    path = os.path.join(bag, 'scenario.yaml')
    if not os.path.isfile(path):
        return None
    import yaml
    try:
        with open(path, encoding='utf-8') as fh:
            text = str((yaml.safe_load(fh) or {}).get('epoch', ''))
        dt = datetime.fromisoformat(text.replace('Z', '+00:00'))
    except (OSError, ValueError, AttributeError, yaml.YAMLError):
        return None
    return (dt if dt.tzinfo else dt.replace(tzinfo=timezone.utc)).astimezone(timezone.utc)


def load_samples(bag: str, topics: Optional[Sequence[str]] = None
                 ) -> tuple[Dict[str, str], List[Sample], List[Sample]]:
    """Read the bag: ``(types, timed samples in stamp order, static samples)``.

    Raises
    ------
    ReplayError
        Missing or unreadable bag; a requested topic not in the bag; no sensor topic; a timed
        topic without ``header.stamp``.
    """
    from adcs_nodes.bag import stamp_kind
    try:
        with open_bag(bag) as reader:
            available = {c.topic: c.msgtype for c in reader.connections}
            wanted = list(topics) if topics else sorted(
                t for t in available if t.startswith(SENSOR_PREFIX))
            wanted = ['/' + t.lstrip('/') for t in wanted]
            missing = [t for t in wanted if t not in available]
            if missing:
                raise ReplayError(f'{bag}: no topic {", ".join(missing)} (it has: '
                                  f'{", ".join(sorted(available))})')
            if not wanted:
                raise ReplayError(f'{bag}: no sensor topics (/sensors/*) to replay; '
                                  'choose some with --topics')
            store = reader.typestore if hasattr(reader, 'typestore') else None
            statics = [t for t in STATIC_TOPICS if t in available and t not in wanted]
            for topic in wanted:
                kind = stamp_kind(store, available[topic]) if store is not None else 'header'
                if kind != 'header':
                    raise ReplayError(f'{topic} [{available[topic]}] has no header.stamp: '
                                      'only stamped sensor messages are replayed')
            conns = [c for c in reader.connections if c.topic in set(wanted) | set(statics)]
            timed: List[Sample] = []
            static: List[Sample] = []
            for conn, _, raw in reader.messages(connections=conns):
                raw = bytes(raw)
                if conn.topic in statics:
                    static.append(Sample(conn.topic, 0, raw))
                    continue
                stamp = cdr_stamp_ns(raw)
                if stamp is None:
                    raise ReplayError(f'{bag}: unreadable message on {conn.topic}')
                timed.append(Sample(conn.topic, stamp, raw))
    except FileNotFoundError as exc:
        raise ReplayError(str(exc)) from None
    except ReplayError:
        raise
    except ValueError as exc:
        raise ReplayError(str(exc)) from None
    timed.sort(key=lambda s: s.stamp_ns)          # stable: recording order within a stamp
    types = {t: available[t] for t in wanted + statics}
    return types, timed, static


def replay(bag: str, topics: Optional[Sequence[str]] = None, rate: float = 1.0,
           time_offset_s: float = 0.0, now: bool = False, clock: Optional[bool] = None,
           wait_s: float = 0.0, start_s: float = 0.0, duration_s: Optional[float] = None,
           log=print) -> int:
    """Publish the bag's sensor topics (see the module docstring). Returns the number of
    timed messages published.

    Parameters
    ----------
    rate : float
        Sim seconds per wall second (> 0).
    time_offset_s : float
        Added to every stamp and to ``/clock`` [s].
    now : bool
        Shift stamps to the wall clock (overrides ``time_offset_s``; needs ``rate == 1``).
    clock : bool, optional
        Publish ``/clock`` (default: unless ``now``).
    wait_s : float
        Wait up to this long for a subscriber on every replayed topic before starting.
    start_s, duration_s : float
        Replay only stamps in ``[first + start_s, first + start_s + duration_s]``.
    """
    import math
    if not (rate > 0 and math.isfinite(rate)):
        raise ReplayError(f'--rate must be a positive number, got {rate}')
    if now and rate != 1.0:
        raise ReplayError('--now stamps with the wall clock: it needs --rate 1')
    if not math.isfinite(time_offset_s):
        raise ReplayError('--time-offset must be finite')
    if wait_s < 0 or start_s < 0 or (duration_s is not None and not duration_s > 0):
        raise ReplayError('--wait and --start must be >= 0 and --duration > 0')
    types, timed, static = load_samples(bag, topics)
    if not timed:
        raise ReplayError(f'{bag}: the selected topics hold no messages')
    first = timed[0].stamp_ns + int(round(start_s * NS_PER_S))
    last = timed[-1].stamp_ns if duration_s is None else \
        first + int(round(duration_s * NS_PER_S))
    timed = [s for s in timed if first <= s.stamp_ns <= last]
    clock = (not now) if clock is None else clock
    offset_ns = 0 if now else int(round(time_offset_s * NS_PER_S))   # --now: set at the start

    import rclpy
    from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                           qos_profile_sensor_data)
    from rosgraph_msgs.msg import Clock

    from adcs_nodes.nodes.convert import to_stamp

    # depth 100 as tf2's static listener: one latched message per sensor node must all reach
    # a late reader (depth 1 would keep only the last mount)
    latched = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('adcs_replay', context=context)
    try:
        pubs = {t: node.create_publisher(
            _message_class(m), t, latched if t in STATIC_TOPICS else qos_profile_sensor_data)
            for t, m in types.items()}
        clock_pub = node.create_publisher(Clock, '/clock', 10) if clock else None
        epoch = _bag_epoch(bag)
        names = [t for t in types if t not in STATIC_TOPICS]
        if static:
            names += [t for t in types if t in STATIC_TOPICS]
        log(f'[replay] {bag}: {len(timed)} messages on {", ".join(names)}, '
            f'{(last - first) / NS_PER_S:g} s at {rate:g}x, '
            f'{"wall-clock stamps" if now else f"stamp offset {offset_ns / NS_PER_S:+g} s"}'
            f'{", /clock" if clock else ""}')
        if epoch is not None and offset_ns:
            shifted = epoch + timedelta(microseconds=offset_ns / 1000)
            log(f'[replay] onboard models: give the flight software '
                f'epoch:={shifted.isoformat().replace("+00:00", "Z")} (scenario epoch + offset)')
        deadline = time.monotonic() + wait_s
        everyone = list(pubs.values()) + ([clock_pub] if clock_pub else [])
        if wait_s:
            while not all(p.get_subscription_count() for p in everyone):
                if time.monotonic() > deadline:
                    break
                time.sleep(0.02)
            else:
                time.sleep(MATCH_SETTLE_S)      # the readers match our writers too
        for s in static:
            pubs[s.topic].publish(s.data)
        t0_wall = time.monotonic()
        if now:      # the first sample is stamped now, after the wait for subscribers
            offset_ns = time.time_ns() - first
            log(f'[replay] wall-clock stamps: offset {offset_ns / NS_PER_S:+.9f} s')
        i, sent = 0, 0
        while i < len(timed):
            sim_ns = first + int((time.monotonic() - t0_wall) * rate * NS_PER_S)
            if clock_pub is not None:
                clock_pub.publish(Clock(clock=to_stamp(min(sim_ns, last) + offset_ns)))
            while i < len(timed) and timed[i].stamp_ns <= sim_ns:
                s = timed[i]
                data = _restamp(s.data, s.stamp_ns + offset_ns) if offset_ns else s.data
                pubs[s.topic].publish(data)
                i += 1
                sent += 1
            if i < len(timed):
                wait = (timed[i].stamp_ns - sim_ns) / (rate * NS_PER_S)
                time.sleep(max(0.0, min(CLOCK_TICK_S, wait)))
        if clock_pub is not None:
            clock_pub.publish(Clock(clock=to_stamp(last + offset_ns)))
        time.sleep(0.2)                     # let reliable /tf_static and the last clock go out
        log(f'[replay] done: {sent} messages in {time.monotonic() - t0_wall:.1f} s')
        return sent
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


# ---------------------------------------------------------------------- lockstep replay
@dataclass
class LockstepPlan:
    """What a lockstep replay publishes and when it is done (see :func:`lockstep_plan`).

    Attributes
    ----------
    types : dict
        Replayed topic -> message type (``/clock`` and ``/tf_static`` included).
    subscribers : dict
        Replayed topic -> how many of the followed nodes subscribe to it.
    clocks : list of Sample
        The recorded ``/clock`` ticks, in stamp order: one frame each.
    timed : list of Sample
        The other stamped inputs, in stamp order (recording order within a stamp).
    static : list of Sample
        ``/tf_static`` messages (sensor mounts), published latched at the start.
    frame_ns : int
        Base frame [ns] (the smallest step between two recorded ``/clock`` ticks).
    last_done : dict
        Node -> stamp [ns] of the last frame it processed in the recording (its last
        ``lockstep/status`` in the bag; the last ``/clock`` tick when the bag has none).
    params : dict
        Node -> parameters for a lockstep run alone (empty without a scenario).
    """

    types: Dict[str, str]
    subscribers: Dict[str, int]
    clocks: List[Sample]
    timed: List[Sample]
    static: List[Sample]
    frame_ns: int
    last_done: Dict[str, int]
    params: Dict[str, Dict]


def _topic(name: str) -> str:
    return '/' + name.lstrip('/')


def _graph_nodes(bag: str, nodes: Sequence[str]):
    """Node specs of ``nodes`` in the graph of the bag's ``scenario.yaml`` and run duration."""
    folder = bag if os.path.isdir(bag) else os.path.dirname(os.path.abspath(bag))
    path = os.path.join(folder, 'scenario.yaml')
    if not os.path.isfile(path):
        if not os.path.exists(bag):
            raise ReplayError(f'{bag}: not found')
        raise ReplayError(f'{bag}: no scenario.yaml beside the bag (adcs run --record writes '
                          'it): --lockstep needs it for the nodes\' inputs and parameters')
    from adcs_nodes.graph import build_graph
    from adcs_nodes.scenario import load_scenario
    try:
        sc = load_scenario(path)
        specs = {n.name: n for n in build_graph(sc, float(sc['duration_s']), record=True)}
    except ValueError as exc:
        raise ReplayError(f'{path}: {exc}') from None
    unknown = [n for n in nodes if n not in specs]
    if 'dynamics' in nodes:
        raise ReplayError('dynamics is the clock master: it paces a run, a replay cannot '
                          'pace it')
    if unknown:
        raise ReplayError(f'no node {", ".join(unknown)} in the graph of {path} (it has: '
                          f'{", ".join(sorted(specs))})')
    return [specs[n] for n in nodes]


def _lockstep_params(spec) -> Dict:
    """The launcher's parameters of ``spec`` for a lockstep run alone: ``timing_mode:
    lockstep`` and a handshake that waits only for its inputs (which the replay publishes).

    Left out: ``expected_publishers`` (the replay, not the graph's producer, publishes the
    inputs) and ``autostart`` (a managed node started alone configures and activates itself).
    """
    params = dict(spec.params, timing_mode='lockstep')
    for key in ('expected_publishers', 'autostart'):
        params.pop(key, None)
    subs = [e for e in params.pop('expected_matches', []) if e.startswith('sub:')]
    if subs:        # (an empty list has no type in a ROS parameter file)
        params['expected_matches'] = subs
    return params


def _awaited_topics(params: Dict) -> List[str]:
    """Input topics of a node's handshake (``sub:<topic>=<n>``)."""
    return [_topic(e[4:].rsplit('=', 1)[0]) for e in params.get('expected_matches', [])
            if e.startswith('sub:')]


def lockstep_plan(bag: str, nodes: Sequence[str] = ('estimator',),
                  topics: Optional[Sequence[str]] = None) -> LockstepPlan:
    """Read what a lockstep replay for ``nodes`` needs from ``bag``.

    The inputs are those each node awaited in the recorded run (the ``sub:`` entries of its
    handshake in the graph of the bag's scenario), or ``--topics`` plus ``/clock`` and
    ``/tf_static``.

    Raises
    ------
    ReplayError
        Missing or unreadable bag or scenario, a node not in the graph, a needed topic not in
        the bag, no ``/clock`` ticks, an input without a time stamp.
    """
    if not nodes:
        raise ReplayError('--nodes: name at least one node to follow')
    specs = _graph_nodes(bag, nodes)
    params = {s.name: _lockstep_params(s) for s in specs}
    needed: Dict[str, List[str]] = {}
    for name, par in params.items():
        for t in (_awaited_topics(par) if not topics else
                  [_topic(t) for t in topics] + ['/clock']):
            needed.setdefault(t, []).append(name)
    try:
        with open_bag(bag) as reader:
            available = {c.topic: c.msgtype for c in reader.connections}
            if topics and '/tf_static' in available:
                needed.setdefault('/tf_static', list(nodes))
            needed.setdefault('/clock', [])           # the frames, even for a node without it
            missing = [t for t in needed if t not in available]
            if missing:
                raise ReplayError(
                    f'{bag}: no topic ' + ', '.join(
                        f'{t} (needed by {", ".join(needed[t] or ["the frames"])})'
                        for t in missing)
                    + f' (it has: {", ".join(sorted(available))})')
            store = reader.typestore if hasattr(reader, 'typestore') else None
            from adcs_nodes.bag import stamp_kind
            for t in needed:
                if t in STATIC_TOPICS or store is None:
                    continue
                if stamp_kind(store, available[t]) is None:
                    raise ReplayError(f'{t} [{available[t]}] has no time stamp: only stamped '
                                      'inputs are replayed frame by frame')
            wanted = set(needed) | {'/lockstep/status'}
            conns = [c for c in reader.connections if c.topic in wanted]
            clocks: List[Sample] = []
            timed: List[Sample] = []
            static: List[Sample] = []
            last_done: Dict[str, int] = {}
            for conn, _, raw in reader.messages(connections=conns):
                raw = bytes(raw)
                if conn.topic == '/lockstep/status' and conn.topic not in needed:
                    msg = reader.deserialize(raw, conn.msgtype)
                    if msg.node in params:
                        last_done[msg.node] = max(last_done.get(msg.node, 0),
                                                  cdr_stamp_ns(raw) or 0)
                    continue
                if conn.topic in STATIC_TOPICS:
                    static.append(Sample(conn.topic, 0, raw))
                    continue
                stamp = cdr_stamp_ns(raw)
                if stamp is None:
                    raise ReplayError(f'{bag}: unreadable message on {conn.topic}')
                (clocks if conn.topic == '/clock' else timed).append(
                    Sample(conn.topic, stamp, raw))
    except FileNotFoundError as exc:
        raise ReplayError(str(exc)) from None
    except ReplayError:
        raise
    except (ValueError, KeyError, AttributeError) as exc:
        raise ReplayError(f'{bag}: {exc}') from None
    if not clocks:
        raise ReplayError(f'{bag}: no /clock ticks: nothing to pace the frames by')
    clocks.sort(key=lambda s: s.stamp_ns)
    timed.sort(key=lambda s: s.stamp_ns)          # stable: recording order within a stamp
    steps = [b.stamp_ns - a.stamp_ns for a, b in zip(clocks, clocks[1:])
             if b.stamp_ns > a.stamp_ns]
    frame_ns = min(steps) if steps else NS_PER_S
    for name in params:
        last_done.setdefault(name, clocks[-1].stamp_ns)
    return LockstepPlan(types={t: available[t] for t in needed},
                        subscribers={t: len(n) for t, n in needed.items()},
                        clocks=clocks, timed=timed, static=static, frame_ns=frame_ns,
                        last_done=last_done, params=params)


def write_params(bag: str, nodes: Sequence[str], path: str, log=print) -> None:
    """Write the parameter file of ``nodes`` for a lockstep replay of ``bag`` (see the module
    docstring)."""
    from adcs_nodes.graph import params_file_text
    specs = [dataclasses.replace(s, params=_lockstep_params(s))
             for s in _graph_nodes(bag, nodes)]
    try:
        with open(path, 'w', encoding='utf-8') as fh:
            fh.write(params_file_text(specs))
    except OSError as exc:
        raise ReplayError(f'--write-params {path}: {exc}') from None
    for s in specs:
        log(f'[replay] {s.name}: ros2_ws/run.sh python -m {s.module} --ros-args '
            f'-r __node:={s.name} --params-file {path}')


def replay_lockstep(bag: str, nodes: Sequence[str] = ('estimator',),
                    topics: Optional[Sequence[str]] = None, wait_s: float = 60.0,
                    stall_s: float = 30.0, log=print) -> int:
    """Feed ``nodes`` (running alone in lockstep) frame by frame from ``bag``; see the module
    docstring. Returns the number of messages published (``/clock`` ticks included).

    Raises
    ------
    ReplayError
        See :func:`lockstep_plan`; bad ``wait_s`` or ``stall_s``.
    LockstepStall
        A node not ready within ``wait_s``, or no progress of a node for ``stall_s`` of wall
        time.
    """
    import math
    if not (wait_s > 0 and stall_s > 0 and math.isfinite(wait_s) and math.isfinite(stall_s)):
        raise ReplayError('--wait and --stall-timeout must be positive')
    plan = lockstep_plan(bag, nodes, topics)

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    from adcs_msgs.msg import LockstepStatus
    from adcs_nodes.nodes.convert import stamp_ns
    from adcs_nodes.nodes.lockstep_node import MAX_LAG_FRAMES, QOS_DATA, QOS_READY

    latched = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    first, last = plan.clocks[0].stamp_ns, plan.clocks[-1].stamp_ns
    ready: set = set()
    final: set = set()
    read = {n: first - plan.frame_ns for n in nodes}     # every message up to it was read
    done = {n: first - plan.frame_ns for n in nodes}     # last frame processed

    def on_ready(msg) -> None:
        if msg.data in read:
            ready.add(msg.data)

    def on_report(processed: bool):
        def cb(msg) -> None:
            if msg.node not in read:
                return
            t = stamp_ns(msg.header.stamp)
            read[msg.node] = max(read[msg.node], t)
            if processed:
                done[msg.node] = max(done[msg.node], t)
            if msg.final:
                final.add(msg.node)
        return cb

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('adcs_replay', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        pubs = {t: node.create_publisher(_message_class(m), t,
                                         latched if t in STATIC_TOPICS else QOS_DATA)
                for t, m in plan.types.items()}
        node.create_subscription(String, 'lockstep/ready', on_ready, QOS_READY)
        reports = [node.create_subscription(LockstepStatus, 'lockstep/progress',
                                            on_report(False), QOS_DATA),
                   node.create_subscription(LockstepStatus, 'lockstep/status',
                                            on_report(True), QOS_DATA)]
        total = len(plan.clocks) + len(plan.timed)
        log(f'[replay] {bag}: lockstep for {", ".join(nodes)}: {len(plan.clocks)} frames '
            f'({(last - first) / NS_PER_S:g} s), {total} messages on '
            f'{", ".join(sorted(plan.types))}')
        for s in plan.static:
            pubs[s.topic].publish(s.data)

        def unmatched() -> List[str]:
            out = [f'{n} not ready' for n in nodes if n not in ready]
            out += [f'{t}: {p.get_subscription_count()}/{plan.subscribers[t]} subscribers'
                    for t, p in pubs.items()
                    if p.get_subscription_count() < plan.subscribers[t]]
            out += [f'{r.topic_name}: {r.get_publisher_count()}/{len(nodes)} publishers'
                    for r in reports if r.get_publisher_count() < len(nodes)]
            return out

        deadline = time.monotonic() + wait_s
        while unmatched():
            if time.monotonic() > deadline:
                raise LockstepStall(
                    f'after {wait_s:g} s: {"; ".join(unmatched())}. Start each node in '
                    'lockstep with the recorded parameters (adcs replay BAG --lockstep '
                    '--write-params FILE prints how), in the same ROS_DOMAIN_ID')
            executor.spin_once(timeout_sec=0.02)
        t0_wall = time.monotonic()
        mark = (min(read.values()), min(done.values()))
        moved = time.monotonic()
        next_log = t0_wall + 2.0

        def wait_while(blocked: Callable[[], bool], what: str) -> None:
            nonlocal mark, moved, next_log
            while blocked():
                executor.spin_once(timeout_sec=0.05)
                now = time.monotonic()
                new = (min(read.values()), min(done.values()))
                if new != mark:
                    mark, moved = new, now
                elif now - moved > stall_s:
                    state = ', '.join(f'{n} read {(read[n] - first) / NS_PER_S:g} s, '
                                      f'processed {(done[n] - first) / NS_PER_S:g} s'
                                      for n in nodes)
                    raise LockstepStall(f'no progress for {stall_s:g} s {what} ({state})')
                if now >= next_log:
                    next_log = now + 2.0
                    show(what)

        def show(what: str = '') -> None:
            log(f'[replay] lockstep: t={(sent_t - first) / NS_PER_S:g} of '
                f'{(last - first) / NS_PER_S:g} s published; ' + ', '.join(
                    f'{n} at {(done[n] - first) / NS_PER_S:g} s' for n in nodes)
                + (f' ({what})' if what else ''))

        lag_ns = MAX_LAG_FRAMES * plan.frame_ns
        i, sent, sent_t = 0, 0, first
        quarters = {len(plan.clocks) * q // 4 for q in (1, 2, 3)}
        for k, tick in enumerate(plan.clocks):
            t = tick.stamp_ns
            wait_while(lambda: t - min(read.values()) > lag_ns,
                       f'waiting to publish t={(t - first) / NS_PER_S:g} s')
            while i < len(plan.timed) and plan.timed[i].stamp_ns <= t:
                pubs[plan.timed[i].topic].publish(plan.timed[i].data)
                i += 1
                sent += 1
            pubs['/clock'].publish(tick.data)
            sent += 1
            sent_t = t
            executor.spin_once(timeout_sec=0.0)
            if time.monotonic() >= next_log or (k + 1) in quarters:   # progress, long bags
                next_log = time.monotonic() + 2.0
                show()
        while i < len(plan.timed):             # inputs stamped after the last tick
            pubs[plan.timed[i].topic].publish(plan.timed[i].data)
            i += 1
            sent += 1
        wait_while(lambda: any(n not in final and done[n] < plan.last_done[n] for n in nodes),
                   'after the last frame')
        log(f'[replay] done: {sent} messages, {len(plan.clocks)} frames in '
            f'{time.monotonic() - t0_wall:.1f} s; ' + ', '.join(
                f'{n} processed ' + ('its last frame' if n in final else
                                     f'up to {(done[n] - first) / NS_PER_S:g} s')
                for n in nodes))
        return sent
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Arguments (and help text) of ``adcs replay``."""
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.description = (
        'Publish the recorded inputs of a bag so flight software runs without sim_node.\n\n'
        'Driver-like (default): the sensor topics, best-effort, with their stamps at the wall\n'
        'time they come due (--rate), /clock beside them (or --now: wall-clock stamps), for\n'
        'nodes in live mode.\n\n'
        'Lockstep (--lockstep): for nodes started alone in timing_mode lockstep with the\n'
        'recorded parameters (--write-params FILE writes them), every input they awaited in\n'
        'the run (/clock, /tf_static, sensors, the previous-frame actuator command), frame by\n'
        'frame, paced by their lockstep/progress: they publish the recorded outputs again,\n'
        'bit for bit.')
    p.epilog = (
        'lockstep example:\n'
        '  adcs run scenarios/paper000_control.yaml --record out/ctl --duration 300\n'
        '  adcs replay out/ctl --lockstep --write-params out/ctl/estimator.yaml\n'
        '  python -m adcs_nodes.nodes.estimator --ros-args -r __node:=estimator \\\n'
        '      --params-file out/ctl/estimator.yaml &\n'
        '  adcs replay out/ctl --lockstep\n'
        'exit codes: 0 done, 1 lockstep node not ready or stalled, 2 bad input, '
        '130 interrupted')
    p.add_argument('bag', help='rosbag2 bag directory (or .mcap file) recorded by adcs run')
    p.add_argument('--topics', nargs='+', metavar='TOPIC',
                   help='topics to replay (default: every /sensors/* topic of the bag; with '
                   '--lockstep: the inputs the nodes awaited in the run)')
    p.add_argument('--rate', type=float, default=1.0, metavar='F',
                   help='sim seconds per wall second (default 1)')
    p.add_argument('--time-offset', type=float, default=0.0, metavar='S',
                   help='add S seconds to every stamp and to /clock (default 0)')
    p.add_argument('--now', action='store_true',
                   help='stamp with the wall clock (first sample = now), no /clock; --rate 1')
    p.add_argument('--no-clock', action='store_true', help='do not publish /clock')
    p.add_argument('--wait', type=float, default=None, metavar='S',
                   help='wait up to S seconds for a subscriber on every topic first, then 1 s '
                   'more for the subscribers to match (default 0; with --lockstep: for the '
                   'nodes to be ready, default 60)')
    p.add_argument('--start', type=float, default=0.0, metavar='S',
                   help='skip the first S seconds of the recording')
    p.add_argument('--duration', type=float, metavar='S', help='replay only S seconds')
    g = p.add_argument_group('lockstep replay')
    g.add_argument('--lockstep', action='store_true',
                   help='replay frame by frame to nodes in timing_mode lockstep (see above)')
    g.add_argument('--nodes', nargs='+', default=['estimator'], metavar='NAME',
                   help='the graph nodes fed and followed (default: estimator)')
    g.add_argument('--write-params', metavar='FILE',
                   help="write the nodes' parameters for a lockstep run alone and exit")
    g.add_argument('--stall-timeout', type=float, default=30.0, metavar='S',
                   help='give up (exit 1) when a node made no progress for S s (default 30)')


def _lockstep_options(args: argparse.Namespace) -> None:
    """Driver-like options make no sense frame by frame: refuse them."""
    bad = [opt for opt, on in (('--rate', args.rate != 1.0),
                               ('--time-offset', args.time_offset != 0.0),
                               ('--now', args.now), ('--no-clock', args.no_clock),
                               ('--start', args.start != 0.0),
                               ('--duration', args.duration is not None)) if on]
    if bad:
        raise ReplayError(f'--lockstep replays every recorded frame with its recorded stamps: '
                          f'{", ".join(bad)} cannot be used with it')


def run_from_args(args: argparse.Namespace) -> int:
    """``adcs replay`` entry point: exit code."""
    lockstep = getattr(args, 'lockstep', False)
    try:
        if getattr(args, 'write_params', None):
            write_params(args.bag, args.nodes, args.write_params)
        elif lockstep:
            _lockstep_options(args)
            replay_lockstep(args.bag, args.nodes, args.topics,
                            wait_s=60.0 if args.wait is None else args.wait,
                            stall_s=args.stall_timeout)
        else:
            replay(args.bag, args.topics, rate=args.rate, time_offset_s=args.time_offset,
                   now=args.now, clock=False if args.no_clock else None,
                   wait_s=args.wait or 0.0, start_s=args.start, duration_s=args.duration)
    except ReplayError as exc:
        print(f'adcs replay: {exc}', file=sys.stderr)
        return 2
    except LockstepStall as exc:
        print(f'adcs replay: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print('adcs replay: interrupted', file=sys.stderr)
        return 130
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    """``python -m adcs_nodes.tools.replay BAG ...``."""
    ap = argparse.ArgumentParser(prog='adcs replay', description=__doc__.split('\n\n')[0])
    add_arguments(ap)
    return run_from_args(ap.parse_args(argv))


if __name__ == '__main__':
    raise SystemExit(main())
