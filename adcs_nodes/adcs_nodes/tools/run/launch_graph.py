"""The graph of ``adcs run`` for ``ros2 launch adcs_nodes adcs.launch.py scenario:=NAME``."""
from __future__ import annotations

import os
from typing import List, Optional, Tuple

from adcs_nodes.graph import NodeSpec, build_graph, params_file_text
from adcs_nodes.scenario import load_scenario

PACKAGE = 'adcs_nodes'
CLOCK_MASTER = 'dynamics'
#: Node classes of the graph that are managed (lifecycle) nodes.
MANAGED_CLASSES = ('EstimatorNode', 'ControllerNode', 'ControllerManagerNode', 'GuidanceNode')
#: ``sigterm_timeout`` [s] of a lockstep node (``runtime.FLUSH_BUDGET_S`` and
#: ``TEARDOWN_BUDGET_S`` after SIGINT).
NODE_SIGTERM_TIMEOUT_S = 6.0
#: ``sigterm_timeout`` [s] of the recorder: it closes its bag after SIGINT.
RECORDER_SIGTERM_TIMEOUT_S = 10.0
#: ``sigkill_timeout`` [s] after SIGTERM (launch's default).
SIGKILL_TIMEOUT_S = 5.0


def is_managed(node: NodeSpec) -> bool:
    """True for a managed (lifecycle) node of the graph."""
    return node.cls in MANAGED_CLASSES


def stop_timeouts(node: NodeSpec) -> Tuple[float, float]:
    """``(sigterm_timeout, sigkill_timeout)`` [s] of ``node`` in the launch file."""
    term = RECORDER_SIGTERM_TIMEOUT_S if node.name == 'recorder' else NODE_SIGTERM_TIMEOUT_S
    return term, SIGKILL_TIMEOUT_S


def installed_scenario_dir() -> Optional[str]:
    """``share/adcs_nodes/scenarios`` of the installed package, or ``None``."""
    try:
        from ament_index_python.packages import get_package_share_directory
        path = os.path.join(get_package_share_directory(PACKAGE), 'scenarios')
    except (ImportError, LookupError, ValueError, OSError):
        return None
    return path if os.path.isdir(path) else None


def scenario_path(name: str) -> str:
    """``name``, else ``<name>[.yaml]`` in the installed scenarios; ValueError listing them."""
    if os.path.isfile(name):
        return os.path.abspath(name)
    share = installed_scenario_dir()
    if share is not None:
        for cand in (name, f'{name}.yaml'):
            path = os.path.join(share, os.path.basename(cand))
            if os.path.isfile(path):
                return path
    known = sorted(os.listdir(share)) if share else []
    raise ValueError(f'scenario {name!r} not found (installed: {", ".join(known) or "none"})')


def with_duration(sc: dict, duration_s: Optional[float]) -> dict:
    """Validated ``sc`` with ``duration_s`` (``--duration``), validated again."""
    if duration_s is None or duration_s == sc['duration_s']:
        return sc
    from adcs_nodes.scenario import ScenarioError, apply_overrides
    try:
        return apply_overrides(sc, {'duration_s': float(duration_s)})
    except ScenarioError as exc:
        raise ScenarioError(str(exc).replace(f'--set duration_s={float(duration_s)!r}',
                                             f'--duration {duration_s:g}', 1)) from None


def launch_graph(scenario: str, duration_s: Optional[float] = None,
                 record: Optional[str] = None) -> Tuple[List[NodeSpec], str]:
    """Nodes and parameter-file text of ``scenario`` (path or installed name) as ``adcs run``'s."""
    sc = with_duration(load_scenario(scenario_path(scenario)), duration_s)
    nodes = build_graph(sc, float(sc['duration_s']), record=bool(record))
    if record:
        next(n for n in nodes if n.name == 'recorder').params['output'] = \
            os.path.abspath(record)
    return nodes, params_file_text(nodes)
