"""Bag to CSV (``adcs export``): a file per topic, a row per message, ``t`` [s] from
``header.stamp`` (else the log time) first, then the flattened fields."""
from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from adcs_nodes.bag import flatten_message, header_stamp_ns, list_topics, read_messages


def topic_file_name(topic: str) -> str:
    """CSV file name of a topic: ``/sim/state`` -> ``sim__state.csv``."""
    name = topic.strip('/').replace('/', '__')
    return f'{name or "root"}.csv'


class _ColumnOrder:
    """Ordered union of the rows' column names, a new name right after its predecessor."""

    def __init__(self) -> None:
        self.names: List[str] = []
        self._known: set = set()

    def add_row(self, keys: Sequence[str]) -> None:
        prev: Optional[str] = None
        for key in keys:
            if key not in self._known:
                pos = self.names.index(prev) + 1 if prev is not None else 0
                self.names.insert(pos, key)
                self._known.add(key)
            prev = key


def _cell(value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, float):
        return repr(value)
    return value


def flatten_row(msg: Any, log_time_ns: int) -> List[tuple]:
    """``[('t', seconds), (name, value), ...]`` of one message (header stamp folded into ``t``)."""
    stamp = header_stamp_ns(msg)
    t_ns = stamp if stamp is not None else log_time_ns
    folded = 'header.stamp.' if hasattr(msg, 'header') else 'clock.'
    row = [('t', t_ns * 1e-9)]
    for key, value in flatten_message(msg):
        if stamp is not None and key.startswith(folded):
            continue  # already in t
        row.append((key, value))
    return row


def export_csv(bag_path: os.PathLike | str, out_dir: os.PathLike | str,
               topics: Optional[Sequence[str]] = None) -> List[Path]:
    """One CSV per topic (all, or ``topics``) of the bag in ``out_dir``; the files."""
    rows: Dict[str, List[Dict[str, Any]]] = {}
    columns: Dict[str, _ColumnOrder] = {}
    messages = read_messages(bag_path, topics)  # raises before out_dir is touched
    for topic, t_ns, msg in messages:
        row = flatten_row(msg, t_ns)
        columns.setdefault(topic, _ColumnOrder()).add_row([k for k, _ in row])
        rows.setdefault(topic, []).append(dict(row))
    for topic in list_topics(bag_path):
        if topics is None or topic in topics:
            rows.setdefault(topic, [])
            columns.setdefault(topic, _ColumnOrder()).add_row(['t'])
    out = Path(out_dir)
    written: List[Path] = []
    path = out
    try:
        out.mkdir(parents=True, exist_ok=True)
        for topic in sorted(rows):
            path = out / topic_file_name(topic)
            names = columns[topic].names
            with path.open('w', newline='', encoding='utf-8') as handle:
                writer = csv.writer(handle)
                writer.writerow(names)
                for row in rows[topic]:
                    writer.writerow([_cell(row[n]) if n in row else '' for n in names])
            written.append(path)
    except OSError as exc:   # disk full, no permission: a message, not a traceback
        raise ValueError(f'cannot write {path}: {exc.strerror or exc} '
                         f'({len(written)} of {len(rows)} CSV files written)') from None
    return written
