"""A run's stamped messages, ``Topics`` = ``{topic: {header stamp [ns]: message}}``, from a bag
or from FrameLoop frames (through the topics' converters): the same fields either way."""
from __future__ import annotations

import os
from typing import Any, Dict, Iterable, Optional, Sequence

import numpy as np

Topics = Dict[str, Dict[int, Any]]


def from_bag(bag: str, topics: Sequence[str]) -> Topics:
    """The messages of ``topics`` in ``bag`` by header stamp; FileNotFoundError, ValueError."""
    from adcs_nodes.tools.analyse.bag_series import cached
    names = tuple(t.lstrip('/') for t in topics)
    return cached('topics', bag, names, lambda: _from_bag(bag, names))


def _from_bag(bag: str, names: Sequence[str]) -> Topics:
    from adcs_nodes.bag import header_stamp_ns, read_messages
    out: Topics = {t: {} for t in names}
    for topic, _, msg in read_messages(bag, ['/' + t for t in names]):
        stamp = header_stamp_ns(msg)
        if stamp is not None:
            out[topic.lstrip('/')][stamp] = msg
    return out


def save_figure(fig: Any, out_dir: str, name: str, dpi: int) -> str:
    """``fig`` laid out and written to ``out_dir/name`` (PNG); its path."""
    os.makedirs(out_dir, exist_ok=True)
    fig.tight_layout()
    path = os.path.join(out_dir, name)
    fig.savefig(path, dpi=dpi)
    return path


def from_frames(frames: Iterable[Any], topics: Sequence[str], epoch_ns: int) -> Topics:
    """The messages of ``topics`` in FrameLoop frames of a run with epoch ``epoch_ns``."""
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
    """``sc`` when loaded, else a bag's scenario validated without its plugins."""
    from adcs_nodes.scenario import apply_overrides
    return sc if '_path' in sc else apply_overrides({**sc, 'plugins': []}, {})


def run_topics(sc: Dict[str, Any], topics: Sequence[str], duration_s: Optional[float] = None,
               overrides: Any = None, ideal: bool = False) -> Topics:
    """The stamped messages of ``topics`` of a FrameLoop run of ``sc`` with ``overrides``."""
    from adcs_nodes.scenario import apply_overrides
    from sim_node.engine import FrameLoop
    if overrides:
        sc = apply_overrides(sc, overrides)
    loop = FrameLoop.from_scenario(sc, duration_s, ideal_estimate=ideal)
    return from_frames(loop.run(), topics, loop.epoch_ns)
