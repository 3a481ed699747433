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

Messages are published as the recorded CDR bytes (only the 8 stamp bytes are rewritten when a
stamp changes), so nothing is lost or rounded. Exit codes: 0 done, 2 bad input (bag, topics,
options), 130 interrupted.
"""
from __future__ import annotations

import argparse
import importlib
import os
import struct
import sys
import time
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from typing import Dict, List, Optional, Sequence

from adcs_nodes.tools.bag import cdr_stamp_ns, open_bag

SENSOR_PREFIX = '/sensors/'
STATIC_TOPICS = ('/tf_static',)
CLOCK_TICK_S = 0.01
NS_PER_S = 1_000_000_000


class ReplayError(ValueError):
    """Bad bag, topic selection or options (exit code 2)."""


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
    from adcs_nodes.tools.bag import stamp_kind
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

    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
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
        while wait_s and time.monotonic() < deadline and \
                not all(p.get_subscription_count() for p in everyone):
            time.sleep(0.02)
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


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Arguments of ``adcs replay``."""
    p.add_argument('bag', help='rosbag2 bag directory (or .mcap file) recorded by adcs run')
    p.add_argument('--topics', nargs='+', metavar='TOPIC',
                   help='topics to replay (default: every /sensors/* topic of the bag)')
    p.add_argument('--rate', type=float, default=1.0, metavar='F',
                   help='sim seconds per wall second (default 1)')
    p.add_argument('--time-offset', type=float, default=0.0, metavar='S',
                   help='add S seconds to every stamp and to /clock (default 0)')
    p.add_argument('--now', action='store_true',
                   help='stamp with the wall clock (first sample = now), no /clock; --rate 1')
    p.add_argument('--no-clock', action='store_true', help='do not publish /clock')
    p.add_argument('--wait', type=float, default=0.0, metavar='S',
                   help='wait up to S seconds for a subscriber on every topic first')
    p.add_argument('--start', type=float, default=0.0, metavar='S',
                   help='skip the first S seconds of the recording')
    p.add_argument('--duration', type=float, metavar='S', help='replay only S seconds')


def run_from_args(args: argparse.Namespace) -> int:
    """``adcs replay`` entry point: exit code."""
    try:
        replay(args.bag, args.topics, rate=args.rate, time_offset_s=args.time_offset,
               now=args.now, clock=False if args.no_clock else None, wait_s=args.wait,
               start_s=args.start, duration_s=args.duration)
    except ReplayError as exc:
        print(f'adcs replay: {exc}', file=sys.stderr)
        return 2
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
