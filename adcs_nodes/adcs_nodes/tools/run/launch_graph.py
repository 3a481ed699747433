"""The graph of ``adcs run`` for the standard ROS 2 launch file (``ros2 launch adcs_nodes
adcs.launch.py scenario:=NAME [duration:=S] [record:=BAG]``): the nodes of
:func:`adcs_nodes.graph.build_graph` and their parameters, without ``adcs run``'s private
domain, progress, manifest, stop on a world node's death and lifecycle driving (the managed
nodes activate themselves). Stopping (:func:`stop_timeouts`): SIGINT, SIGTERM, SIGKILL, each
node its time."""
from __future__ import annotations

import os
from typing import List, Optional, Tuple

from adcs_nodes.graph import NodeSpec, build_graph, params_file_text
from adcs_nodes.scenario import load_scenario

PACKAGE = 'adcs_nodes'
CLOCK_MASTER = 'dynamics'
#: Node classes of the graph that are managed (lifecycle) nodes
#: (:class:`adcs_nodes.nodes.managed.ManagedLockstepNode`); the world nodes and the recorder
#: are plain nodes.
MANAGED_CLASSES = ('EstimatorNode', 'ControllerNode', 'ControllerManagerNode', 'GuidanceNode')
#: ``sigterm_timeout`` [s] of a lockstep node: it exits within 2 s of SIGINT, but a node whose
#: reader lags (a stalled recorder) waits up to ``runtime.FLUSH_BUDGET_S`` (4 s) for its last
#: samples to be acknowledged, then up to ``runtime.TEARDOWN_BUDGET_S`` (1 s) for rclpy.
NODE_SIGTERM_TIMEOUT_S = 6.0
#: ``sigterm_timeout`` [s] of the recorder: it closes its bag (last chunk, summary,
#: ``metadata.yaml``) after SIGINT; 0.6-3 s of wall time beside a CPU burner here (load
#: 15-18), more for a long bag on a slow disk.
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
    """A scenario file: ``name`` when it exists, else ``<name>`` or ``<name>.yaml`` in the
    installed scenarios; ValueError (listing them) when neither exists."""
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
    """Scenario ``sc`` (validated) with ``duration_s`` (``--duration``), validated again as
    the file would be (a fault after the end, frames, the epoch; ScenarioError)."""
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
    """Nodes and parameter-file text of ``scenario`` (a path or an installed name) as ``adcs
    run`` builds them, for ``duration_s`` (default the scenario's), recording to ``record``."""
    sc = with_duration(load_scenario(scenario_path(scenario)), duration_s)
    nodes = build_graph(sc, float(sc['duration_s']), record=bool(record))
    if record:
        next(n for n in nodes if n.name == 'recorder').params['output'] = \
            os.path.abspath(record)
    return nodes, params_file_text(nodes)
