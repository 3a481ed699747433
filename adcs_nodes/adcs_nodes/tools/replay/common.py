"""What both replays share: the recorded inputs read from a bag as raw CDR samples, message
classes, restamping, and the errors."""
from __future__ import annotations

import importlib
import struct
from dataclasses import dataclass
from typing import Dict, Iterable, List, Sequence, Tuple

from adcs_nodes.bag import list_topics, stamped_messages

SENSOR_PREFIX = '/sensors/'
STATIC_TOPICS = ('/tf_static',)
NS_PER_S = 1_000_000_000


class ReplayError(ValueError):
    """Bad bag, topic selection or options (exit code 2)."""


class LockstepStall(RuntimeError):
    """A lockstep node never became ready or stopped making progress (exit code 1)."""


@dataclass
class Sample:
    """One message to publish: topic, stamp [ns] (0 for a static one), raw CDR bytes."""

    topic: str
    stamp_ns: int
    data: bytes


def topic_name(name: str) -> str:
    return '/' + name.lstrip('/')


def bag_topics(bag: str) -> Dict[str, str]:
    """``{topic: message type}`` of the bag (ReplayError for a missing or unreadable bag)."""
    try:
        return list_topics(bag)
    except (OSError, ValueError) as exc:
        raise ReplayError(str(exc)) from None


def read_samples(bag: str, topics: Iterable[str], decode: Sequence[str] = (),
                 header_only: bool = False
                 ) -> Tuple[List[Sample], List[Sample], List[Tuple[str, int, object]]]:
    """``(timed samples in stamp order, static ones, decoded (topic, stamp, message))`` of
    ``topics``; ReplayError for a topic without a stamp or an unreadable bag."""
    timed: List[Sample] = []
    static: List[Sample] = []
    decoded: List[Tuple[str, int, object]] = []
    try:
        messages = stamped_messages(bag, topics, STATIC_TOPICS, decode, header_only)
        for topic, stamp, raw, msg in messages:
            if msg is not None:
                decoded.append((topic, stamp, msg))
            else:
                (static if topic in STATIC_TOPICS else timed).append(Sample(topic, stamp, raw))
    except (OSError, ValueError) as exc:
        raise ReplayError(f'{bag}: {exc}: only stamped inputs are replayed'
                          if ' has no ' in str(exc) else str(exc)) from None
    timed.sort(key=lambda s: s.stamp_ns)
    return timed, static, decoded


def message_class(msgtype: str):
    pkg, kind, name = msgtype.split('/')
    try:
        return getattr(importlib.import_module(f'{pkg}.{kind}'), name)
    except (ImportError, AttributeError) as exc:
        raise ReplayError(f'type {msgtype} is not installed here ({exc})') from None


def restamp(raw: bytes, stamp_ns: int) -> bytes:
    """``raw`` CDR with its leading ``builtin_interfaces/Time`` set to ``stamp_ns``."""
    fmt = '<iI' if raw[1] & 0x01 else '>iI'
    out = bytearray(raw)
    struct.pack_into(fmt, out, 4, stamp_ns // NS_PER_S, stamp_ns % NS_PER_S)
    return bytes(out)


def latched_qos():
    """``/tf_static`` as tf2's static listener takes it: depth 100, transient local."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
