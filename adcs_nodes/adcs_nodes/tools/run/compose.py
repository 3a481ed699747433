"""Composed deployment (``adcs run --engine composed``): the graph's nodes in one process on
one ``EventsExecutor``, the same trajectory. Ends when the clock master is done or on
SIGINT/SIGTERM; managed nodes are configured and activated in process (a refusal: exit 2).
Volatile topics go straight to the local subscriptions while no outside one is matched
(:class:`InProcessBus`; ``--dds`` or ``ADCS_COMPOSE_INPROC=0``: all over DDS)."""
from __future__ import annotations

import argparse
import collections
import functools
import importlib
import json
import os
import sys
import time
from typing import Any, Callable, Deque, Dict, List, Tuple

import rclpy
import yaml
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from adcs_nodes.nodes.runtime import limit_blas_threads, spin_nodes, stop_handler_from_start
from adcs_nodes.graph import flatten


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


class InProcessBus:
    """Direct delivery between the composed ``nodes``, first in first out after the
    publishing callback (else by a one-shot timer): no callback runs inside another."""

    def __init__(self, nodes, max_batch: int = 500) -> None:
        self.queue: Deque[Tuple[List[Callable], Any]] = collections.deque()
        self.busy = False
        self.max_batch = int(max_batch)
        self.local = 0        # messages delivered in process
        self.dds = 0          # messages of linked publishers sent over DDS
        self.timer_drains = 0  # deliveries started by the fallback timer
        self.topics: List[str] = []
        subs: Dict[Tuple[str, Any], List[Subscription]] = collections.defaultdict(list)
        originals: Dict[int, Callable] = {}
        skip = set()
        for node in nodes:
            for sub in node.subscriptions:
                key = (sub.topic_name, sub.msg_type)
                # a callback taking the message info (publisher_guard) gets None in process
                info = sub._callback_type != Subscription.CallbackType.MessageOnly
                if sub.qos_profile.durability != DurabilityPolicy.VOLATILE:
                    skip.add(key)
                subs[key].append(sub)
                cb = sub.callback
                if sub.raw and getattr(cb, 'raw_codec', None) is None:
                    # a raw subscription (a composed recorder) records DDS's bytes: on DDS
                    skip.add(key)
                originals[id(sub)] = (lambda m, cb=cb: cb(m, None)) if info else cb
                sub.callback = self._wrap(cb, info)
        self._timer = nodes[0].create_timer(0.0, self._on_timer)
        self._timer.cancel()
        for node in nodes:
            for pub in list(node.publishers):
                key = (pub.topic_name, pub.msg_type)
                if key in skip or not subs.get(key) \
                        or pub.qos_profile.durability != DurabilityPolicy.VOLATILE:
                    continue
                self._link(pub, [originals[id(sub)] for sub in subs[key]])
                if pub.topic_name not in self.topics:
                    self.topics.append(pub.topic_name)

    def _wrap(self, callback: Callable, info: bool = False) -> Callable:
        def wrapped(msg, *rest) -> None:
            if self.busy:     # cannot happen from the executor; keep the order anyway
                callback(msg, *rest)
                return
            self.busy = True
            try:
                callback(msg, *rest)
            finally:
                self.busy = False
            if self.queue:
                self._drain()
        if info:     # still given the message info by rclpy, from any executor
            from adcs_nodes.nodes.publisher_guard import WithInfo
            return WithInfo(wrapped)
        return wrapped

    def _link(self, pub, callbacks: List[Callable]) -> None:
        dds_publish = pub.publish
        n_local = len(callbacks)
        # the rcl call itself, without rclpy's cross-thread guard (this is the only thread)
        subscription_count = pub.handle.get_subscription_count

        def publish(msg) -> None:
            if not getattr(pub, 'is_activated', True):   # an inactive lifecycle publisher
                return
            if subscription_count() > n_local:   # someone outside listens: DDS
                self.dds += 1
                dds_publish(msg)
                return
            self.local += 1
            self.queue.append((callbacks, msg))
            if not self.busy:
                self._timer.reset()   # published outside a wrapped callback: deliver soon

        pub.publish = publish

    def _on_timer(self) -> None:
        self._timer.cancel()
        if not self.busy:
            self.timer_drains += 1
            self._drain()

    def _drain(self) -> None:
        self.busy = True
        try:
            for _ in range(self.max_batch):
                if not self.queue:
                    return
                callbacks, msg = self.queue.popleft()
                for cb in callbacks:
                    cb(msg)
        finally:
            self.busy = False
            if self.queue:
                self._timer.reset()   # more to deliver: after the executor's other work


def guard_callbacks(nodes) -> Dict[str, str]:
    """Guards each node's subscription and timer callbacks: an exception marks that node dead
    (said once; it does nothing more, as a crashed process) and the others go on. Returns
    ``{node: why}``, filled as nodes die."""
    dead: Dict[str, str] = {}

    def guard(callback: Callable, name: str) -> Callable:
        @functools.wraps(callback)      # the same signature: rclpy reads it (message info)
        def guarded(*args):
            if name in dead:
                return None
            try:
                return callback(*args)
            except Exception as exc:    # noqa: BLE001 - any node bug: that node only
                dead[name] = f'{type(exc).__name__}: {exc}'
                print(f'[compose] node {name} died ({dead[name]}): marked dead as a crashed '
                      'process would be; the other nodes go on', file=sys.stderr)
                return None
        return guarded

    for node in nodes:
        for entity in (*node.subscriptions, *node.timers):
            entity.callback = guard(entity.callback, node.get_name())
    return dead


def drive_lifecycle(nodes) -> str:
    """Configure, activate every unconfigured managed node; ``''`` or ``<node>: <reason>``."""
    from rclpy.lifecycle import TransitionCallbackReturn

    managed = [n for n in nodes if getattr(n, 'lifecycle_state', '') == 'unconfigured']
    for node in managed:
        if node.trigger_configure() != TransitionCallbackReturn.SUCCESS:
            return f'{node.get_name()}: {node.configure_error or "configure failed"}'
    for node in managed:
        if node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
            return f'{node.get_name()}: activate failed'
    return ''


def write_state(state: Any, path: str) -> None:
    """The fields of a state object as exact hex floats in JSON (for bit-exact comparisons)."""
    import numpy as np

    out: Dict[str, Any] = {}
    for name, value in (vars(state).items() if state is not None else ()):
        try:
            arr = np.asarray(value, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            continue
        out[name] = [float(x).hex() for x in arr]
    with open(path, 'w') as fh:
        json.dump(out, fh)


def inproc_enabled(flag: bool, dds: bool = False) -> bool:
    """The in-process path: on unless ``--dds`` or ``ADCS_COMPOSE_INPROC`` off (0/false/no)."""
    if dds:
        return False
    env = os.environ.get('ADCS_COMPOSE_INPROC', '').strip().lower()
    return flag or env not in ('0', 'false', 'no', 'off')


def main(argv=None) -> int:
    """Entry point of the composed runner."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--params-file', required=True)
    ap.add_argument('--nodes', nargs='+', required=True)
    ap.add_argument('--drain-s', type=float, default=0.5)
    ap.add_argument('--inproc', action='store_true',
                    help='in-process path between the composed nodes (DDS only for outside '
                         'subscribers): the default; also ADCS_COMPOSE_INPROC=1')
    ap.add_argument('--dds', action='store_true',
                    help='every message over DDS, as in the graph; also ADCS_COMPOSE_INPROC=0')
    ap.add_argument('--state-out', default='',
                    help='write the clock master\'s final state here (JSON, exact hex floats)')
    args = ap.parse_args(argv)
    with open(args.params_file) as fh:
        doc = yaml.safe_load(fh) or {}
    stop_handler_from_start()        # a stop during the start-up ends the spin at its start
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    try:
        try:
            nodes = build_nodes(args.nodes, doc)
        except ValueError as exc:
            print(f'[compose] configuration error: {exc}', file=sys.stderr)
            return 2
        refused = drive_lifecycle(nodes)
        if refused:
            print(f'[compose] configuration error: {refused}', file=sys.stderr)
            return 2
        limit_blas_threads()   # again after the node modules' imports (idempotent)
        guard_callbacks(nodes)
        bus = InProcessBus(nodes) if inproc_enabled(args.inproc, args.dds) and nodes else None
        if bus is not None:
            print(f'[compose] in-process path on {len(bus.topics)} topics: '
                  f'{", ".join(sorted(bus.topics))}', file=sys.stderr)
        master = next((n for n in nodes if n.get_name() == 'dynamics'), None)
        drain = {'until': None}

        def finished() -> bool:
            if master is None or not master.done:
                return False
            if drain['until'] is None:
                drain['until'] = time.monotonic() + args.drain_s
            return time.monotonic() >= drain['until']

        prof_path = os.environ.get('ADCS_COMPOSE_PROFILE', '')
        if prof_path:     # developer aid (docs/bench.md): cProfile of the spin, pstats file
            import cProfile
            # ADCS_COMPOSE_PROFILE_CLOCK=cpu: CPU time (shares of the work, waits left out)
            cpu = os.environ.get('ADCS_COMPOSE_PROFILE_CLOCK', '') == 'cpu'
            prof = cProfile.Profile(time.process_time) if cpu else cProfile.Profile()
            prof.runcall(spin_nodes, nodes, until=finished, poll_s=0.05)
            prof.dump_stats(prof_path)
        else:
            spin_nodes(nodes, until=finished, poll_s=0.05)
        if bus is not None:
            print(f'[compose] in-process deliveries {bus.local}, DDS publishes of linked '
                  f'publishers {bus.dds}, timer-started deliveries {bus.timer_drains}',
                  file=sys.stderr)
        if args.state_out and master is not None:
            write_state(getattr(master, 'state', None), args.state_out)
        return 0
    finally:
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == '__main__':
    raise SystemExit(main())
