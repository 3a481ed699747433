"""Self-healing before frame 0: a node stuck at the handshake or in its lifecycle is restarted,
at most :data:`MAX_RESTARTS` times (nothing has happened yet: still deterministic)."""
from __future__ import annotations

import re
from typing import Callable, Dict, Iterable, List, Tuple

import adcs_nodes.tools.run.launcher.processes as processes

#: Wall seconds a node may wait for its endpoints while every other is ready.
HEAL_WAIT_S = 30.0
#: ... seconds a managed node's lifecycle requests may go unanswered.
HEAL_UNANSWERED_S = 30.0
#: CPU time [s] over :data:`HEAL_BUSY_WINDOW_S` of a busy, not stuck, unanswering node.
HEAL_BUSY_CPU_S = 1.0
HEAL_BUSY_WINDOW_S = 10.0
#: Restarts per node before frame 0; a node stuck again after them fails the run.
MAX_RESTARTS = 1
_WAITING = re.compile(r'still waiting for endpoints after ([0-9.]+) s: (.*)')


def heal_decision(expected: List[str], ready: Iterable[str], waiting: Dict[str, Tuple[float, str]],
                  master: str, restarts: Dict[str, int], guards: Dict[str, List[str]],
                  wait_s: float = HEAL_WAIT_S, max_restarts: int = MAX_RESTARTS):
    """Which nodes to restart before frame 0 (``waiting``: per node ``(seconds, unmatched)``):
    None, ``('restart', [(node, reason), ...])`` or ``('fail', node, reason)``."""
    ready = set(ready)
    unready = [n for n in expected if n not in ready]
    if not unready or any(waiting.get(n, (0.0, ''))[0] < wait_s for n in unready):
        return None
    targets = [n for n in unready if n != master] or [master]
    for name in targets:
        if restarts.get(name, 0) >= max_restarts:
            return ('fail', name, f'node {name} still has unmatched endpoints after '
                    f'{restarts.get(name, 0)} restart(s) before frame 0: {waiting[name][1]}')
    return ('restart', restart_plan(
        [(n, f'its endpoints stayed unmatched for {waiting[n][0]:g} s while every other '
          f'node was ready: {waiting[n][1]}') for n in targets], ready, master, guards))


def restart_plan(targets: List[Tuple[str, str]], ready: Iterable[str], master: str,
                 guards: Dict[str, List[str]]) -> List[Tuple[str, str]]:
    """``targets`` ``(node, reason)`` plus the guarding consumers and the clock master."""
    ready = set(ready)
    out = list(targets)
    names = {n for n, _ in targets}
    for name, _ in targets:
        for guard in guards.get(name, []):
            if guard in ready and guard not in names:
                names.add(guard)
                out.append((guard, f'it accepts {name}\'s messages only from the publisher it '
                            'locked at its handshake (the old process)'))
    if master not in names and names & ready:
        out.append((master, 'a node that had said ready is restarted: the clock master must '
                    'wait for its new ready'))
    return out


class Healer:
    """The launcher's self-healing state over the graph's ``nodes`` and the run's ``procs``."""

    def __init__(self, nodes, procs: processes.Processes, master: str,
                 respawn: Callable[[str, str], None], log=print) -> None:
        self.nodes, self.procs, self.master, self.respawn, self.log = (nodes, procs, master,
                                                                       respawn, log)
        self.restarts: Dict[str, int] = {}
        self.notes: List[str] = []
        self.cpu_seen: Dict[str, float] = {}
        #: per node, the nodes that accept its messages only from its publisher identity
        self.guards: Dict[str, List[str]] = {}
        for node in nodes:
            for item in node.params.get('expected_publishers', []) or []:
                self.guards.setdefault(str(item).rsplit('=', 1)[-1], []).append(node.name)

    def waiting(self, name: str) -> Tuple[float, str]:
        """``(seconds, unmatched)`` of the node's last ``still waiting`` log line."""
        last = (0.0, '')
        for m in _WAITING.finditer(self.procs.current_log(name)):
            last = (float(m.group(1)), m.group(2).strip())
        return last

    def check(self, monitor, transitions=None):
        """Restart what :func:`heal_decision` says; ``(1, message)``: stuck again."""
        expected = [n.name for n in self.nodes if n.lockstep and n.name in self.procs.procs]
        waiting = {n: self.waiting(n) for n in expected if n not in monitor.ready}
        verdict = heal_decision(expected, monitor.ready, waiting, self.master, self.restarts,
                                self.guards, HEAL_WAIT_S, MAX_RESTARTS)
        if verdict is None:
            return None
        if verdict[0] == 'fail':
            name = verdict[1]
            return 1, (f'{verdict[2]}; last lines of its log '
                       f'({self.procs.log_path(name)}):\n{self.procs.tail(name)}')
        for name, reason in verdict[1]:
            self.restart(monitor, transitions, name, reason)
        return None

    def lifecycle(self, monitor, transitions, name: str):
        """Restart an unanswering managed node unless busy; ``(name, 'unanswered')``."""
        proc = self.procs.procs.get(name)
        cpu = processes.cpu_seconds(proc.pid) if proc is not None else None
        if cpu is not None:
            if name not in self.cpu_seen:       # measure its CPU time over a window first
                self.cpu_seen[name] = cpu
                transitions.postpone(name, HEAL_BUSY_WINDOW_S)
                return None
            used = cpu - self.cpu_seen.pop(name)
            if used >= HEAL_BUSY_CPU_S:          # working (configure, a kernel compile)
                self.log(f'[adcs] node {name} has not answered its lifecycle requests for '
                         f'{HEAL_UNANSWERED_S:g} s but is busy ({used:.1f} s CPU in '
                         f'{HEAL_BUSY_WINDOW_S:g} s): waiting')
                transitions.postpone(name, HEAL_UNANSWERED_S)
                return None
        if self.restarts.get(name, 0) >= MAX_RESTARTS:
            return name, 'unanswered'
        reason = (f'its lifecycle requests went unanswered for {HEAL_UNANSWERED_S:g} s '
                  f'and it used no CPU (step: {transitions.step.get(name)})')
        for node, why in restart_plan([(name, reason)], monitor.ready, self.master,
                                      self.guards):
            self.restart(monitor, transitions, node, why)
        return None

    def restart(self, monitor, transitions, name: str, reason: str) -> None:
        """Stop node ``name`` and start it again with the same command (before frame 0)."""
        k = self.restarts.get(name, 0) + 1
        self.restarts[name] = k
        self.notes.append(f'{name}: {reason}')
        self.log(f'[adcs] restarting node {name} before frame 0 (restart {k} of at most '
                 f'{MAX_RESTARTS}): {reason}')
        self.respawn(name, f'restarted by the launcher before frame 0: {reason}')
        monitor.ready.discard(name)
        self.cpu_seen.pop(name, None)
        if transitions is not None and name in transitions.step:
            transitions.reset(name)
