"""Bag to CSV: one file per topic, one row per message, flattened fields, first column ``t``.

Columns
-------
* ``t`` [s]: ``header.stamp`` in seconds (epoch of the stamp, i.e. the scenario's UTC date in
  simulation) when the message has a header (``rosgraph_msgs/Clock``: its ``clock``), else the
  bag's log time. ``header.stamp`` itself is not repeated; ``header.frame_id`` is kept.
* every other field with a dotted name: ``r_eci.x``, ``q_eci_orbit.w``; fixed arrays
  ``covariance[0]`` ... ``covariance[35]``; variable arrays ``momentum[0]`` ... up to the longest
  array seen on the topic (shorter rows leave the extra cells empty).
* booleans are written ``1`` / ``0``; floats with ``repr`` (exact round trip).

File names: the topic without its leading ``/``, every ``/`` replaced by ``__``:
``/sim/state`` -> ``sim__state.csv``. Rows are in recording order (per topic, arrival order).
Since ``t`` comes from header stamps, the CSV of a deterministic simulation is identical
between runs (log times are not exported).
"""
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
    """Ordered union of the column names of all rows, new names placed after their predecessor.

    Keeps ``momentum[3]`` right after ``momentum[2]`` even when the first rows are shorter.
    """

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
    """Write one CSV per topic of ``bag_path`` into ``out_dir`` (created if needed).

    Parameters
    ----------
    bag_path : path-like
        rosbag2 bag directory or ``.mcap`` file.
    out_dir : path-like
        Output directory; existing CSV files of the same names are replaced.
    topics : sequence of str, optional
        Only these topics; all when ``None``.

    Returns
    -------
    list of pathlib.Path
        The written files, sorted by topic name. Topics without messages get a file with the
        header row ``t`` only.

    Raises
    ------
    FileNotFoundError
        If the bag does not exist.
    ValueError
        If it is not a readable bag, or a CSV file cannot be written (disk full).
    """
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
