"""Lockstep replay: nodes started alone get what they awaited in the run, frame by frame, and
publish the recorded outputs again, bit for bit."""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence

from adcs_nodes.tools.replay.common import (NS_PER_S, STATIC_TOPICS, LockstepStall, ReplayError,
                                            Sample, bag_topics, latched_qos, message_class,
                                            read_samples, topic_name)

STATUS_TOPIC = '/lockstep/status'


@dataclass
class LockstepPlan:
    """What a lockstep replay publishes, and when each node is done (``last_done`` [ns])."""

    types: Dict[str, str]
    subscribers: Dict[str, int]
    clocks: List[Sample]
    timed: List[Sample]
    static: List[Sample]
    frame_ns: int
    last_done: Dict[str, int]
    params: Dict[str, Dict]


def graph_nodes(bag: str, nodes: Sequence[str], plugins: Sequence[str] = ()):
    """Node specs of ``nodes`` in the graph of the bag's scenario (with the given plugins)."""
    from adcs_nodes.graph import build_graph
    from adcs_nodes.tools.bagfile import BagError, validated_scenario
    if 'dynamics' in nodes:
        raise ReplayError('dynamics is the clock master: it paces a run, a replay cannot '
                          'pace it')
    try:
        sc = validated_scenario(bag, plugins)
        specs = {n.name: n for n in build_graph(sc, float(sc['duration_s']), record=True)}
    except (BagError, ValueError) as exc:
        import os
        if not os.path.exists(bag):
            raise ReplayError(f'{bag}: not found') from None
        raise ReplayError(str(exc)) from None
    unknown = [n for n in nodes if n not in specs]
    if unknown:
        raise ReplayError(f'no node {", ".join(unknown)} in the graph of {sc["_path"]} (it '
                          f'has: {", ".join(sorted(specs))})')
    return [specs[n] for n in nodes]


def lockstep_params(spec) -> Dict:
    """The launcher's parameters of ``spec`` for a lockstep run alone, fed by the replay."""
    params = dict(spec.params, timing_mode='lockstep')
    for key in ('expected_publishers', 'autostart'):
        params.pop(key, None)
    subs = [e for e in params.pop('expected_matches', []) if e.startswith('sub:')]
    if subs:        # (an empty list has no type in a ROS parameter file)
        params['expected_matches'] = subs
    return params


def lockstep_plan(bag: str, nodes: Sequence[str] = ('estimator',),
                  topics: Optional[Sequence[str]] = None,
                  plugins: Sequence[str] = ()) -> LockstepPlan:
    """What a lockstep replay for ``nodes`` needs from ``bag``; ReplayError."""
    if not nodes:
        raise ReplayError('--nodes: name at least one node to follow')
    params = {s.name: lockstep_params(s) for s in graph_nodes(bag, nodes, plugins)}
    needed: Dict[str, List[str]] = {}
    for name, par in params.items():
        awaited = [topic_name(e[4:].rsplit('=', 1)[0])
                   for e in par.get('expected_matches', []) if e.startswith('sub:')]
        for t in [topic_name(t) for t in topics] + ['/clock'] if topics else awaited:
            needed.setdefault(t, []).append(name)
    available = bag_topics(bag)
    if topics and '/tf_static' in available:
        needed.setdefault('/tf_static', list(nodes))
    needed.setdefault('/clock', [])           # the frames, even for a node without it
    missing = [t for t in needed if t not in available]
    if missing:
        raise ReplayError(f'{bag}: no topic ' + ', '.join(
            f'{t} (needed by {", ".join(needed[t] or ["the frames"])})' for t in missing)
            + f' (it has: {", ".join(sorted(available))})')
    decode = [STATUS_TOPIC] if STATUS_TOPIC not in needed else []
    timed, static, statuses = read_samples(bag, list(needed) + decode, decode)
    clocks = [s for s in timed if s.topic == '/clock']
    if not clocks:
        raise ReplayError(f'{bag}: no /clock ticks: nothing to pace the frames by')
    last_done = {n: clocks[-1].stamp_ns for n in params}
    for name in params:
        done = [stamp for _, stamp, msg in statuses if msg.node == name]
        last_done[name] = max(done, default=last_done[name])
    steps = [b.stamp_ns - a.stamp_ns for a, b in zip(clocks, clocks[1:])
             if b.stamp_ns > a.stamp_ns]
    return LockstepPlan(types={t: available[t] for t in needed},
                        subscribers={t: len(n) for t, n in needed.items()}, clocks=clocks,
                        timed=[s for s in timed if s.topic != '/clock'], static=static,
                        frame_ns=min(steps) if steps else NS_PER_S, last_done=last_done,
                        params=params)


def write_params(bag: str, nodes: Sequence[str], path: str, log=print,
                 plugins: Sequence[str] = ()) -> None:
    """Write the parameter file of ``nodes`` for a lockstep replay of ``bag``."""
    from adcs_nodes.graph import params_file_text
    specs = [dataclasses.replace(s, params=lockstep_params(s))
             for s in graph_nodes(bag, nodes, plugins)]
    try:
        with open(path, 'w', encoding='utf-8') as fh:
            fh.write(params_file_text(specs))
    except OSError as exc:
        raise ReplayError(f'--write-params {path}: {exc}') from None
    for s in specs:
        log(f'[replay] {s.name}: ros2_ws/run.sh python -m {s.module} --ros-args '
            f'-r __node:={s.name} --params-file {path}')


class _Follower:
    """The followed nodes as the replay sees them (stamps [ns])."""

    def __init__(self, node, executor, nodes: Sequence[str], first_ns: int, frame_ns: int,
                 stall_s: float, log) -> None:
        from std_msgs.msg import String

        from adcs_msgs.msg import LockstepStatus
        from adcs_nodes.nodes.lockstep_node import QOS_DATA, QOS_READY
        self.executor, self.nodes, self.first, self.stall_s, self.log = (
            executor, list(nodes), first_ns, stall_s, log)
        self.ready: set = set()
        self.final: set = set()
        self.read = {n: first_ns - frame_ns for n in nodes}   # every message up to it read
        self.done = {n: first_ns - frame_ns for n in nodes}   # last frame processed
        node.create_subscription(String, 'lockstep/ready', self._on_ready, QOS_READY)
        self.reports = [node.create_subscription(LockstepStatus, 'lockstep/progress',
                                                 self._report(False), QOS_DATA),
                        node.create_subscription(LockstepStatus, 'lockstep/status',
                                                 self._report(True), QOS_DATA)]
        self.mark = (min(self.read.values()), min(self.done.values()))
        self.moved = self.next_log = time.monotonic()
        self.sent_t = first_ns

    def _on_ready(self, msg) -> None:
        if msg.data in self.read:
            self.ready.add(msg.data)

    def _report(self, processed: bool):
        from adcs_nodes.msgs.fields import stamp_ns

        def cb(msg) -> None:
            if msg.node not in self.read:
                return
            t = stamp_ns(msg.header.stamp)
            self.read[msg.node] = max(self.read[msg.node], t)
            if processed:
                self.done[msg.node] = max(self.done[msg.node], t)
            if msg.final:
                self.final.add(msg.node)
        return cb

    def unmatched(self, pubs: Dict, subscribers: Dict[str, int]) -> List[str]:
        out = [f'{n} not ready' for n in self.nodes if n not in self.ready]
        out += [f'{t}: {p.get_subscription_count()}/{subscribers[t]} subscribers'
                for t, p in pubs.items() if p.get_subscription_count() < subscribers[t]]
        out += [f'{r.topic_name}: {r.get_publisher_count()}/{len(self.nodes)} publishers'
                for r in self.reports if r.get_publisher_count() < len(self.nodes)]
        return out

    def wait_while(self, blocked: Callable[[], bool], what: str) -> None:
        """Spin while ``blocked()``; LockstepStall when no node moves for ``stall_s``."""
        while blocked():
            self.executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            new = (min(self.read.values()), min(self.done.values()))
            if new != self.mark:
                self.mark, self.moved = new, now
            elif now - self.moved > self.stall_s:
                state = ', '.join(f'{n} read {self.s(self.read[n]):g} s, processed '
                                  f'{self.s(self.done[n]):g} s' for n in self.nodes)
                raise LockstepStall(f'no progress for {self.stall_s:g} s {what} ({state})')
            if now >= self.next_log:
                self.show(what)

    def s(self, t_ns: int) -> float:
        return (t_ns - self.first) / NS_PER_S

    def show(self, what: str = '') -> None:
        self.next_log = time.monotonic() + 2.0
        self.log(f'[replay] lockstep: t={self.s(self.sent_t):g} s published; ' + ', '.join(
            f'{n} at {self.s(self.done[n]):g} s' for n in self.nodes)
            + (f' ({what})' if what else ''))


def replay_lockstep(bag: str, nodes: Sequence[str] = ('estimator',),
                    topics: Optional[Sequence[str]] = None, wait_s: float = 60.0,
                    stall_s: float = 30.0, log=print, plugins: Sequence[str] = ()) -> int:
    """Feed ``nodes`` frame by frame from ``bag``; the messages published. LockstepStall."""
    if not (wait_s > 0 and stall_s > 0 and math.isfinite(wait_s) and math.isfinite(stall_s)):
        raise ReplayError('--wait and --stall-timeout must be positive')
    plan = lockstep_plan(bag, nodes, topics, plugins)

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from adcs_nodes.nodes.lockstep_node import QOS_DATA

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('adcs_replay', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        pubs = {t: node.create_publisher(message_class(m), t, latched_qos()
                                         if t in STATIC_TOPICS else QOS_DATA)
                for t, m in plan.types.items()}
        follow = _Follower(node, executor, nodes, plan.clocks[0].stamp_ns, plan.frame_ns,
                           stall_s, log)
        log(f'[replay] {bag}: lockstep for {", ".join(nodes)}: {len(plan.clocks)} frames '
            f'({follow.s(plan.clocks[-1].stamp_ns):g} s), '
            f'{len(plan.clocks) + len(plan.timed)} messages on {", ".join(sorted(plan.types))}')
        for s in plan.static:
            pubs[s.topic].publish(s.data)
        deadline = time.monotonic() + wait_s
        while follow.unmatched(pubs, plan.subscribers):
            if time.monotonic() > deadline:
                raise LockstepStall(
                    f'after {wait_s:g} s: {"; ".join(follow.unmatched(pubs, plan.subscribers))}'
                    '. Start each node in lockstep with the recorded parameters (adcs replay '
                    'BAG --lockstep --write-params FILE prints how), in the same ROS_DOMAIN_ID')
            executor.spin_once(timeout_sec=0.02)
        t0_wall = follow.moved = time.monotonic()
        follow.next_log = t0_wall + 2.0
        sent = _feed(plan, pubs, follow)
        log(f'[replay] done: {sent} messages, {len(plan.clocks)} frames in '
            f'{time.monotonic() - t0_wall:.1f} s; ' + ', '.join(
                f'{n} processed ' + ('its last frame' if n in follow.final else
                                     f'up to {follow.s(follow.done[n]):g} s') for n in nodes))
        return sent
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)


def _feed(plan: LockstepPlan, pubs: Dict, follow: _Follower) -> int:
    """Publish frame by frame, at most ``MAX_LAG_FRAMES`` ahead, until every node is done."""
    from adcs_nodes.nodes.lockstep_node import MAX_LAG_FRAMES
    lag_ns = MAX_LAG_FRAMES * plan.frame_ns
    i = 0
    quarters = {len(plan.clocks) * q // 4 for q in (1, 2, 3)}
    for k, tick in enumerate(plan.clocks):
        t = tick.stamp_ns
        follow.wait_while(lambda: t - min(follow.read.values()) > lag_ns,
                          f'waiting to publish t={follow.s(t):g} s')
        while i < len(plan.timed) and plan.timed[i].stamp_ns <= t:
            pubs[plan.timed[i].topic].publish(plan.timed[i].data)
            i += 1
        pubs['/clock'].publish(tick.data)
        follow.sent_t = t
        follow.executor.spin_once(timeout_sec=0.0)
        if time.monotonic() >= follow.next_log or (k + 1) in quarters:   # progress
            follow.show()
    for s in plan.timed[i:]:             # inputs stamped after the last tick
        pubs[s.topic].publish(s.data)
    follow.wait_while(lambda: any(n not in follow.final and follow.done[n] < plan.last_done[n]
                                  for n in follow.nodes), 'after the last frame')
    return len(plan.clocks) + len(plan.timed)
