"""Bag checks of the tests: per-topic summaries and content digests (determinism, parity)."""
from __future__ import annotations

import hashlib
import os
from typing import Any, Dict, List, Sequence, Tuple

from adcs_nodes.bag import flatten_message, header_stamp_ns, open_bag

#: Types whose content depends on the wall clock (``wall_time``, per-second publication), so
#: two runs of the same deterministic simulation legitimately differ in them.
NONDETERMINISTIC_TYPES = ('adcs_msgs/msg/LockstepStatus',)


def topic_summary(bag_path: os.PathLike | str) -> Dict[str, Tuple[str, int, int, int]]:
    """Per topic: ``(msgtype, count, first_log_ns, last_log_ns)`` (times 0 when empty).

    Counts and times come from reading every record (not deserialised), so they are exact
    even for a bag whose metadata is missing.
    """
    out: Dict[str, List[Any]] = {}
    with open_bag(bag_path) as reader:
        for conn in reader.connections:
            out.setdefault(conn.topic, [conn.msgtype, 0, 0, 0])
        try:
            for conn, t_ns, _ in reader.messages():
                entry = out[conn.topic]
                if entry[1] == 0:
                    entry[2] = entry[3] = t_ns
                entry[1] += 1
                entry[2] = min(entry[2], t_ns)
                entry[3] = max(entry[3], t_ns)
        except Exception as exc:
            raise ValueError(f'{bag_path}: corrupt bag: {exc}') from exc
    return {topic: tuple(entry) for topic, entry in sorted(out.items())}


def content_digest(bag_path: os.PathLike | str,
                   exclude_types: Sequence[str] = NONDETERMINISTIC_TYPES
                   ) -> Dict[str, Tuple[int, str]]:
    """Per topic ``(count, sha256)`` of the message contents, independent of log times.

    Two runs of the same deterministic simulation give equal digests for every topic whose
    type is not in ``exclude_types`` (by default the wall-clock status types of
    :data:`NONDETERMINISTIC_TYPES`). Each message is hashed from its flattened, deserialised
    values (``repr`` of floats is exact; raw CDR padding bytes are unspecified), and the
    per-message hashes are combined in canonical order: sorted by header stamp, then by
    content. Within a single-publisher topic with increasing stamps that is the recording
    order; on topics with several publishers (``lockstep/ready``) the interleaving of
    publishers, which DDS does not fix, does not change the digest.
    """
    excluded = set(exclude_types)
    items: Dict[str, List[Tuple[int, bytes]]] = {}
    with open_bag(bag_path) as reader:
        conns = [c for c in reader.connections if c.msgtype not in excluded]
        for conn in conns:
            items.setdefault(conn.topic, [])
        if conns:
            try:
                for conn, _, raw in reader.messages(connections=conns):
                    msg = reader.deserialize(raw, conn.msgtype)
                    stamp = header_stamp_ns(msg)
                    digest = hashlib.sha256(repr(flatten_message(msg)).encode()).digest()
                    items[conn.topic].append((-1 if stamp is None else stamp, digest))
            except Exception as exc:
                raise ValueError(f'{bag_path}: corrupt bag: {exc}') from exc
    out: Dict[str, Tuple[int, str]] = {}
    for topic in sorted(items):
        total = hashlib.sha256()
        for stamp, digest in sorted(items[topic]):
            total.update(stamp.to_bytes(8, 'little', signed=True) + digest)
        out[topic] = (len(items[topic]), total.hexdigest())
    return out
