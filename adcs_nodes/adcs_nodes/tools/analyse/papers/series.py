"""A run's stamped messages by topic, ``Topics`` = ``{topic: {header stamp [ns]: message}}``
(FrameLoop names: ``sim/state``, ...), from a bag or from FrameLoop frames (samples made
messages by their topics' converters): the same field names either way, so the paper modules
read both alike."""
from __future__ import annotations

import os
from typing import Any, Dict, Iterable, Optional, Sequence

import numpy as np

Topics = Dict[str, Dict[int, Any]]

#: One bag read, kept for the next reader of the same bag (the report reads the paper's topics
#: for its table and again for its figures): ``(path, mtime, topics) -> Topics``.
_LAST: Dict[tuple, Topics] = {}


def _stamp(msg: Any) -> Optional[int]:
    from adcs_nodes.bag import header_stamp_ns
    return header_stamp_ns(msg)


def from_bag(bag: str, topics: Sequence[str]) -> Topics:
    """The messages of ``topics`` in ``bag`` (any engine's) by header stamp;
    FileNotFoundError or ValueError for no bag or an unreadable one."""
    from adcs_nodes.bag import read_messages
    names = tuple(t.lstrip('/') for t in topics)
    try:
        mtime = max(os.stat(os.path.join(bag, f)).st_mtime_ns for f in os.listdir(bag)) \
            if os.path.isdir(bag) else os.stat(bag).st_mtime_ns
    except OSError:
        mtime = None
    key = (os.path.abspath(bag), mtime, names)
    if mtime is not None and key in _LAST:
        return _LAST[key]
    out: Topics = {t: {} for t in names}
    for topic, _, msg in read_messages(bag, ['/' + t for t in names]):
        stamp = _stamp(msg)
        if stamp is not None:
            out[topic.lstrip('/')][stamp] = msg
    _LAST.clear()
    if mtime is not None:
        _LAST[key] = out
    return out


def from_frames(frames: Iterable[Any], topics: Sequence[str], epoch_ns: int) -> Topics:
    """The messages of ``topics`` in FrameLoop frames (:class:`sim_node.engine.Frame`) of a
    run with epoch ``epoch_ns`` (the samples' converters, :func:`adcs_nodes.inputs.converter`)."""
    from adcs_nodes.inputs import converter
    out: Topics = {t.lstrip('/'): {} for t in topics}
    to_msg = {t: converter(t).to_msg for t in out}
    for frame in frames:
        for topic, x in frame.outputs:
            got = out.get(topic)
            if got is not None:
                got[epoch_ns + x.t_ns] = to_msg[topic](x, epoch_ns)
    return out


def epoch_ns(sc: Dict[str, Any]) -> int:
    """The scenario's epoch (sim time 0) [ns since 1970]."""
    from adcs_nodes.components.base import epoch_to_ns, parse_epoch
    return epoch_to_ns(parse_epoch(str(sc['epoch'])))


def orbit_period_s(sc: Dict[str, Any]) -> Optional[float]:
    """Period of the scenario's circular orbit (Kepler) [s]; None for another orbit type."""
    import math

    from adcs_nodes.core.orbit import MU_EARTH, R_EARTH
    if (sc.get('orbit') or {}).get('type', 'circular') != 'circular':
        return None
    a = R_EARTH + 1e3 * float(sc['orbit']['altitude_km'])
    return 2.0 * math.pi * math.sqrt(a ** 3 / MU_EARTH)


def quat(q: Any) -> np.ndarray:
    """``geometry_msgs/Quaternion`` -> ``[x, y, z, w]``."""
    return np.array([q.x, q.y, q.z, q.w], dtype=float)


def vec(v: Any) -> np.ndarray:
    """``geometry_msgs/Vector3`` -> ``[x, y, z]``."""
    return np.array([v.x, v.y, v.z], dtype=float)


def sorted_items(topic: Dict[int, Any]) -> list:
    """``[(stamp, message)]`` in stamp order."""
    return sorted(topic.items(), key=lambda kv: kv[0])


def scenario_dict(sc: Dict[str, Any]) -> Dict[str, Any]:
    """A validated scenario: ``sc`` itself when it was loaded (it has ``_path``), else the
    effective scenario of a bag (``scenario.yaml``) validated again, without its plugins (a
    bag is data)."""
    from adcs_nodes.scenario import apply_overrides
    return sc if '_path' in sc else apply_overrides({**sc, 'plugins': []}, {})


def run_topics(sc: Dict[str, Any], topics: Sequence[str], duration_s: Optional[float] = None,
               overrides: Any = None, ideal: bool = False) -> Topics:
    """The stamped messages of ``topics`` of a FrameLoop run of the validated scenario ``sc``
    with ``overrides``; ScenarioError or EngineError (ValueErrors) for a bad override or a
    scenario the plain engine cannot run."""
    from adcs_nodes.scenario import apply_overrides
    from sim_node.engine import FrameLoop
    if overrides:
        sc = apply_overrides(sc, overrides)
    loop = FrameLoop.from_scenario(sc, duration_s, ideal_estimate=ideal)
    return from_frames(loop.run(), topics, loop.epoch_ns)
