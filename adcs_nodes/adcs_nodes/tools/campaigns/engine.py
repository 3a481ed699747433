"""Which engine a campaign runs on: ``graph``, ``plain`` or ``auto`` (the default).

``auto`` is ``plain`` (the FrameLoop, :mod:`sim_node.engine`: every scenario's components
without ROS, the graph's series to the last bit) unless a sensor is external (a driver
publishes it), else ``graph``. An explicit ``--engine`` wins. A campaign that already
exists in ``--out`` resumes on the engine recorded in its ``campaign.json`` (the engine is part
of the campaign identity, :data:`~adcs_nodes.tools.campaigns.config.IDENTITY_KEYS`).
"""
from __future__ import annotations

import json
import os
from typing import Any, Dict, Optional, Tuple

from adcs_nodes.tools.campaigns.config import ENGINES


def plain_engine_problem(sc: Dict[str, Any]) -> Optional[str]:
    """Why the plain engine (:class:`sim_node.engine.FrameLoop`) cannot run the validated
    scenario ``sc``; None when it can (every scenario without an external sensor)."""
    external = sorted(k for k, cfg in (sc.get('sensors') or {}).items() if cfg.get('external'))
    if external:
        return f'external sensors ({", ".join(external)}) need their drivers: a graph'
    return None


def recorded_engine(out: str) -> Optional[str]:
    """The engine in ``out/campaign.json`` (a campaign to resume), or None (no campaign).

    A ``campaign.json`` without an engine is from before the engines: ``'graph'``.
    """
    path = os.path.join(out, 'campaign.json')
    if not os.path.isfile(path):
        return None
    try:
        with open(path, encoding='utf-8') as fh:
            data = json.load(fh)
    except (OSError, ValueError):
        return None   # unreadable: the identity check reports it
    engine = data.get('engine', 'graph') if isinstance(data, dict) else None
    return engine if engine in ENGINES else None


def resolve_engine(requested: Optional[str], sc: Dict[str, Any],
                   out: str) -> Tuple[str, str]:
    """The engine of a campaign and why: ``(engine, reason)``.

    Parameters
    ----------
    requested : str or None
        ``--engine``: ``'graph'``, ``'plain'``, or ``'auto'`` / None (the default).
    sc : dict
        The validated base scenario.
    out : str
        Campaign directory (an existing campaign there keeps its engine under ``auto``).
    """
    if requested in ENGINES:
        return requested, '--engine'
    if requested not in (None, 'auto'):
        raise ValueError(f'--engine must be auto, {" or ".join(ENGINES)}, got {requested!r}')
    old = recorded_engine(out)
    if old is not None:
        return old, 'auto: the engine of the campaign being resumed'
    problem = plain_engine_problem(sc)
    if problem is None:
        return 'plain', 'auto: the plain engine runs this scenario'
    return 'graph', f'auto: {problem}'
