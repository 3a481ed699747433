"""Which engine a campaign runs on (``--engine``): ``auto`` is ``plain`` unless a sensor is
external, else ``graph``; a campaign resumed in ``--out`` keeps its recorded engine."""
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
    """The engine in ``out/campaign.json`` (none recorded: ``'graph'``), or None (no
    campaign)."""
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
    """``(engine, reason)`` of a campaign: ``requested`` (``--engine``: ``'graph'``,
    ``'plain'``, ``'auto'`` or None) for the validated base scenario ``sc`` in ``out``."""
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
