"""Driver-like replay: the recorded sensor topics at the wall time their stamps come due."""
from __future__ import annotations

import math
import time
from datetime import datetime, timedelta, timezone
from typing import Dict, List, Optional, Sequence, Tuple

from adcs_nodes.tools.replay.common import (NS_PER_S, SENSOR_PREFIX, STATIC_TOPICS,
                                            ReplayError, Sample, bag_topics, latched_qos,
                                            message_class, read_samples, restamp, topic_name)

CLOCK_TICK_S = 0.01
#: After every replayed topic has a subscriber [s], for its side to match (ASSUMPTION).
MATCH_SETTLE_S = 1.0


def load_samples(bag: str, topics: Optional[Sequence[str]] = None
                 ) -> Tuple[Dict[str, str], List[Sample], List[Sample]]:
    """``(types, timed samples in stamp order, static samples)`` of the bag; ReplayError."""
    available = bag_topics(bag)
    wanted = [topic_name(t) for t in topics] if topics else sorted(
        t for t in available if t.startswith(SENSOR_PREFIX))
    missing = [t for t in wanted if t not in available]
    if missing:
        raise ReplayError(f'{bag}: no topic {", ".join(missing)} (it has: '
                          f'{", ".join(sorted(available))})')
    if not wanted:
        raise ReplayError(f'{bag}: no sensor topics (/sensors/*) to replay; choose some with '
                          '--topics')
    statics = [t for t in STATIC_TOPICS if t in available and t not in wanted]
    timed, static, _ = read_samples(bag, wanted + statics, header_only=True)
    return {t: available[t] for t in wanted + statics}, timed, static


def bag_epoch(bag: str) -> Optional[datetime]:
    """The scenario epoch of a bag recorded by ``adcs run`` (its ``scenario.yaml``), or None."""
    from adcs_nodes.tools.bagfile import BagError, bag_scenario
    try:
        sc = bag_scenario(bag) or {}
        dt = datetime.fromisoformat(str(sc.get('epoch', '')).replace('Z', '+00:00'))
    except BagError as exc:
        raise ReplayError(str(exc)) from None
    except ValueError:
        return None
    return (dt if dt.tzinfo else dt.replace(tzinfo=timezone.utc)).astimezone(timezone.utc)


def _check(rate: float, time_offset_s: float, now: bool, wait_s: float, start_s: float,
           duration_s: Optional[float]) -> None:
    if not (rate > 0 and math.isfinite(rate)):
        raise ReplayError(f'--rate must be a positive number, got {rate}')
    if now and rate != 1.0:
        raise ReplayError('--now stamps with the wall clock: it needs --rate 1')
    if not math.isfinite(time_offset_s):
        raise ReplayError('--time-offset must be finite')
    if not (wait_s >= 0 and start_s >= 0) or (duration_s is not None and not duration_s > 0):
        raise ReplayError('--wait and --start must be >= 0 and --duration > 0')


def replay(bag: str, topics: Optional[Sequence[str]] = None, rate: float = 1.0,
           time_offset_s: float = 0.0, now: bool = False, clock: Optional[bool] = None,
           wait_s: float = 0.0, start_s: float = 0.0, duration_s: Optional[float] = None,
           log=print) -> int:
    """Publish the bag's sensor topics as ``adcs replay`` says; the timed messages sent."""
    _check(rate, time_offset_s, now, wait_s, start_s, duration_s)
    epoch = bag_epoch(bag)
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
    from rclpy.qos import qos_profile_sensor_data
    from rosgraph_msgs.msg import Clock

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('adcs_replay', context=context)
    try:
        pubs = {t: node.create_publisher(
            message_class(m), t, latched_qos() if t in STATIC_TOPICS else
            qos_profile_sensor_data) for t, m in types.items()}
        clock_pub = node.create_publisher(Clock, '/clock', 10) if clock else None
        log(f'[replay] {bag}: {len(timed)} messages on {", ".join(types)}, '
            f'{(last - first) / NS_PER_S:g} s at {rate:g}x, '
            f'{"wall-clock stamps" if now else f"stamp offset {offset_ns / NS_PER_S:+g} s"}'
            f'{", /clock" if clock else ""}')
        if epoch is not None and offset_ns:
            shifted = epoch + timedelta(microseconds=offset_ns / 1000)
            log(f'[replay] onboard models: give the flight software '
                f'epoch:={shifted.isoformat().replace("+00:00", "Z")} (scenario epoch + offset)')
        _wait_for_readers(list(pubs.values()) + ([clock_pub] if clock_pub else []), wait_s)
        for s in static:
            pubs[s.topic].publish(s.data)
        if now:      # the first sample is stamped now, after the wait for subscribers
            offset_ns = time.time_ns() - first
            log(f'[replay] wall-clock stamps: offset {offset_ns / NS_PER_S:+.9f} s')
        t0_wall = time.monotonic()
        sent = _publish_paced(timed, pubs, clock_pub, first, last, rate, offset_ns)
        log(f'[replay] done: {sent} messages in {time.monotonic() - t0_wall:.1f} s')
        return sent
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def _wait_for_readers(pubs: list, wait_s: float) -> None:
    """Up to ``wait_s`` for a subscriber on every publisher, then :data:`MATCH_SETTLE_S`."""
    if not wait_s:
        return
    deadline = time.monotonic() + wait_s
    while not all(p.get_subscription_count() for p in pubs):
        if time.monotonic() > deadline:
            return
        time.sleep(0.02)
    time.sleep(MATCH_SETTLE_S)      # the readers match our writers too


def _publish_paced(timed: List[Sample], pubs: dict, clock_pub, first: int, last: int,
                   rate: float, offset_ns: int) -> int:
    """Each sample when its stamp comes due at ``rate``, ``/clock`` every tick."""
    from rosgraph_msgs.msg import Clock

    from adcs_nodes.msgs.fields import to_stamp
    t0_wall = time.monotonic()
    i = 0
    while i < len(timed):
        sim_ns = first + int((time.monotonic() - t0_wall) * rate * NS_PER_S)
        if clock_pub is not None:
            clock_pub.publish(Clock(clock=to_stamp(min(sim_ns, last) + offset_ns)))
        while i < len(timed) and timed[i].stamp_ns <= sim_ns:
            s = timed[i]
            pubs[s.topic].publish(restamp(s.data, s.stamp_ns + offset_ns) if offset_ns
                                  else s.data)
            i += 1
        if i < len(timed):
            wait = (timed[i].stamp_ns - sim_ns) / (rate * NS_PER_S)
            time.sleep(max(0.0, min(CLOCK_TICK_S, wait)))
    if clock_pub is not None:
        clock_pub.publish(Clock(clock=to_stamp(last + offset_ns)))
    time.sleep(0.2)                     # let reliable /tf_static and the last clock go out
    return i
