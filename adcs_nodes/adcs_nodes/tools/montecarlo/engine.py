"""Which engine a campaign runs on: ``graph``, ``plain`` or ``auto`` (the default).

``auto`` is ``plain`` when the plain loop (:mod:`sim_node.tools.closed_loop`) wires every
node of the scenario's graph (paper 000: environment, dynamics, magnetometer, the
``magnetic_filter`` estimator, the ``magnetic`` / ``bdot`` controllers, guidance and the
controller manager), else ``graph``. An explicit ``--engine`` wins. A campaign that already
exists in ``--out`` resumes on the engine recorded in its ``campaign.json`` (the engine is part
of the campaign identity, :data:`~adcs_nodes.tools.montecarlo.config.IDENTITY_KEYS`).
"""
from __future__ import annotations

import json
import os
from typing import Any, Dict, Optional, Tuple

from adcs_nodes.tools.montecarlo.config import ENGINES

#: Graph nodes the plain loop computes (``*_controller`` nodes are checked one by one).
PLAIN_NODES = frozenset({'environment', 'dynamics', 'magnetometer', 'estimator', 'guidance',
                         'controller_manager'})
#: Estimator algorithms and controllers the plain loop wires (paper 000).
PLAIN_ESTIMATORS = frozenset({'magnetic_filter'})
PLAIN_CONTROLLERS = frozenset({'magnetic', 'bdot'})


def plain_engine_problem(sc: Dict[str, Any]) -> Optional[str]:
    """Why the plain loop cannot run the validated scenario ``sc``; None when it can."""
    from adcs_nodes.tools.graph import build_graph

    nodes = {n.name: n.params for n in build_graph(sc, float(sc['timing']['frame_s']))}
    for name in ('magnetometer', 'estimator', 'controller_manager'):
        if name not in nodes:
            return f'the scenario has no {name} node'
    extra = sorted(n for n in nodes if n not in PLAIN_NODES and not n.endswith('_controller'))
    if extra:
        return f'the plain loop has no model of the node(s) {", ".join(extra)}'
    algorithm = str(nodes['estimator'].get('algorithm', 'magnetic_filter'))
    if algorithm not in PLAIN_ESTIMATORS:
        return f'the plain loop does not wire the estimator {algorithm!r}'
    for name, params in nodes.items():
        if name.endswith('_controller'):
            law = str(params.get('controller', name[:-len('_controller')]))
            if law not in PLAIN_CONTROLLERS:
                return f'the plain loop does not wire the controller {law!r}'
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
        return 'plain', 'auto: the plain loop runs this scenario'
    return 'graph', f'auto: {problem}'
