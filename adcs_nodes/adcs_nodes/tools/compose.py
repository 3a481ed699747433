"""Composed deployment: several ADCS nodes in one process on one ``EventsExecutor``.

Like a ROS 2 component container: the same node classes and parameters as the one process
per node deployment, so both give the same trajectory (tested), but messages skip the
process boundaries. Used by ``adcs run --compose``::

    python -m adcs_nodes.tools.compose --params-file params.yaml \\
        --nodes environment=sim_node.nodes.environment:EnvironmentNode \\
                dynamics=sim_node.nodes.dynamics:DynamicsNode

The process ends when the clock master (the node named ``dynamics``) is done, after a short
drain so the last messages reach the recorder; or on SIGINT/SIGTERM.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import time
from typing import Any, Dict, List, Tuple

import rclpy
import yaml
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from adcs_nodes.nodes.runtime import limit_blas_threads, spin_nodes
from adcs_nodes.tools.graph import flatten


def overrides_for(params_doc: Dict[str, Any], name: str) -> List[Parameter]:
    """Parameter overrides of node ``name`` from a ROS 2 parameter-file document."""
    section = params_doc.get(f'/{name}', params_doc.get(name, {})).get('ros__parameters', {})
    flat: Dict[str, Any] = {}
    flatten('', section, flat)
    return [Parameter(k, value=v) for k, v in flat.items()]


def parse_node_spec(text: str) -> Tuple[str, str, str]:
    """``name=package.module:Class`` -> (name, module, class)."""
    try:
        name, target = text.split('=', 1)
        module, cls = target.split(':', 1)
    except ValueError:
        raise SystemExit(f'compose: bad node spec {text!r} (want name=module:Class)') from None
    return name, module, cls


def build_nodes(specs: List[str], params_doc: Dict[str, Any]):
    """Instantiate each node class with its overrides (same as --params-file would give)."""
    nodes = []
    for text in specs:
        name, module, cls = parse_node_spec(text)
        node_cls = getattr(importlib.import_module(module), cls)
        nodes.append(node_cls(name, parameter_overrides=overrides_for(params_doc, name)))
    return nodes


def main(argv=None) -> int:
    """Entry point of the composed runner."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--params-file', required=True)
    ap.add_argument('--nodes', nargs='+', required=True)
    ap.add_argument('--drain-s', type=float, default=0.5)
    args = ap.parse_args(argv)
    with open(args.params_file) as fh:
        doc = yaml.safe_load(fh) or {}
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    try:
        try:
            nodes = build_nodes(args.nodes, doc)
        except ValueError as exc:
            print(f'[compose] configuration error: {exc}', file=sys.stderr)
            return 2
        limit_blas_threads()   # again after the node modules' imports (idempotent)
        master = next((n for n in nodes if n.get_name() == 'dynamics'), None)
        drain = {'until': None}

        def finished() -> bool:
            if master is None or not master.done:
                return False
            if drain['until'] is None:
                drain['until'] = time.monotonic() + args.drain_s
            return time.monotonic() >= drain['until']

        spin_nodes(nodes, until=finished, poll_s=0.05)
        return 0
    finally:
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == '__main__':
    raise SystemExit(main())
