"""The launcher behind ``adcs run``: start the scenario's graph, watch it (an essential child
that dies stops the run; a flight node's death is reported), stop it cleanly."""
from __future__ import annotations

import json
import math
import os
import shutil
import signal
import sys
import time
from dataclasses import replace
from typing import Dict, List, Optional, Tuple

from adcs_nodes.graph import NodeSpec, build_graph, params_file_text
from adcs_nodes.tools.run.launch_graph import is_managed, with_duration
import adcs_nodes.tools.run.launcher.isolation as isolation
from adcs_nodes.tools.run.launcher.healing import HEAL_UNANSWERED_S, Healer
from adcs_nodes.tools.run.launcher.isolation import (DDS_ENV_KEYS, RUN_DOMAINS, LaunchError,
                                                     acquire_domain, child_env, disk_full,
                                                     private_dir, prune_runs, use_dds_env,
                                                     write_private)
from adcs_nodes.tools.run.launcher.lifecycle import Transitions
from adcs_nodes.tools.run.launcher.monitor import Monitor
from adcs_nodes.tools.run.launcher.processes import Processes
from adcs_nodes.tools.run.launcher.result import (RunResult, closing_text, degraded_text,
                                                  external_devices, save_scenario,
                                                  transition_failed_text, write_failed_text)

#: Exit code of the recorder after a write error (``recorder.EXIT_WRITE_FAILED``).
RECORDER_WRITE_FAILED = 3
#: Wall seconds without sim progress before the launcher says the run is stalled.
STALL_NOTICE_S = 30.0
#: Nodes whose death ends the run: the simulated world, the recorder, the composed process.
#: Any other node (flight software) may die; the run goes on and its consumers fall back.
ESSENTIAL = {'dynamics', 'environment', 'recorder', 'composed'}
#: The clock master's ``start_timeout_s``: the launcher's own deadlines come first.
START_TIMEOUT_S = 180.0
#: The largest ``--rate`` [sim seconds per wall second].
MAX_RATE = 1e6


def check_rate(rate: float) -> float:
    """``rate`` if it is a ``--rate`` (finite, in (0, :data:`MAX_RATE`]), else LaunchError."""
    if not (math.isfinite(rate) and 0 < rate <= MAX_RATE):
        raise LaunchError(f'--rate must be in (0, 1e6] sim seconds per wall second, '
                          f'got {rate:g}')
    return float(rate)


def pace(rate: Optional[float], real_time: bool) -> Tuple[float, float]:
    """``--rate`` as ``(rate_factor, max_rate)`` (real time's pace, else lockstep's limit)."""
    if rate is not None:
        check_rate(rate)
    if real_time:
        return (1.0 if rate is None else float(rate)), 0.0
    return 1.0, (0.0 if rate is None else float(rate))


class Launcher:
    """Start, watch and stop one scenario run (see module docstring)."""

    def __init__(self, scenario: dict, duration_s: Optional[float] = None,
                 record: Optional[str] = None, real_time: bool = False,
                 rate_factor: float = 1.0, compose: bool = False, progress: bool = True,
                 run_dir: Optional[str] = None, log=print,
                 domain: Optional[int] = None, max_rate: float = 0.0) -> None:
        if domain is not None and not (isinstance(domain, int) and 0 <= domain <= 232):
            raise LaunchError(f'--domain must be a ROS_DOMAIN_ID in 0..232, got {domain!r}')
        check_rate(rate_factor)
        if max_rate != 0.0:                      # (0: no pace)
            check_rate(max_rate)
        from adcs_nodes.scenario import ScenarioError
        try:
            self.sc = with_duration(scenario, duration_s)
        except ScenarioError as exc:
            raise LaunchError(str(exc)) from None
        self.duration_s = float(self.sc['duration_s'])
        self.domain = domain     # None: a free one drawn at random (RUN_DOMAINS)
        self.record = os.path.abspath(record) if record else None
        if self.record and os.path.exists(self.record):
            raise LaunchError(f'bag {self.record} exists already; choose another --record path')
        self.real_time, self.rate_factor, self.compose = real_time, rate_factor, compose
        frame_s = self.sc['timing']['frame_s']
        # a paced frame may take long by request: a stall is a wait beyond it
        self.stall_notice_s = STALL_NOTICE_S + (frame_s / max_rate if max_rate > 0 else 0.0)
        self.progress, self.log = progress, log
        self.run_dir = run_dir or os.path.join(
            isolation.RUNS_DIR,
            f'{time.strftime("%Y%m%dT%H%M%S")}-{self.sc["name"]}-{os.getpid()}')
        self.nodes: List[NodeSpec] = build_graph(self.sc, self.duration_s, real_time,
                                                 rate_factor, record=bool(record),
                                                 max_rate=max_rate)
        if self.record:
            next(n for n in self.nodes if n.name == 'recorder').params['output'] = self.record
        self.result_file = os.path.join(self.run_dir, 'dynamics_result.json')
        next(n for n in self.nodes if n.name == 'dynamics').params['result_file'] = \
            self.result_file
        self.processes = Processes(self.run_dir, log)
        self.healer = Healer(self.nodes, self.processes, self._master_name(), self._respawn,
                             log)
        self.transitions: Optional[Transitions] = None
        from sim_node.faults import node_kills
        self.kills = node_kills(self.sc.get('faults') or [])   # node_killed faults by node
        self.killed: set = set()
        self.lost: Dict[str, float] = {}   # flight-software nodes that died: sim time [s]
        self._stop_requested = False
        self._manifest: Optional[dict] = None
        self._env: Dict[str, str] = {}
        self._params_path = ''

    # ------------------------------------------------------------------ processes
    def _started_nodes(self) -> List[NodeSpec]:
        """The graph as started: managed nodes with ``autostart: false`` (driven from here)."""
        out = []
        for n in self.nodes:
            if is_managed(n):
                n = replace(n, params={**n.params, 'autostart': False})
            if n.name == 'dynamics' and not self.compose:
                n = replace(n, params={'start_timeout_s': START_TIMEOUT_S, **n.params})
            out.append(n)
        return out

    def _commands(self, params_path: str) -> Dict[str, List[str]]:
        if self.compose:
            spec = [f'{n.name}={n.module}:{n.cls}' for n in self.nodes]
            return {'composed': [sys.executable, '-m', 'adcs_nodes.tools.run.compose',
                                 '--params-file', params_path, '--nodes', *spec]}
        extra = self.processes.test_args()
        return {n.name: [sys.executable, '-m', n.module, '--ros-args', '-r',
                         f'__node:={n.name}', '--params-file', params_path]
                + extra.get(n.name, []) for n in self.nodes}

    def _respawn(self, name: str, note: str) -> None:
        """Stop node ``name`` and start it again with the same command (self-healing)."""
        self.processes.signal_and_wait([name], 5.0)
        self.processes.spawn(name, self._commands(self._params_path)[name], self._env, note)
        self._write_manifest()

    def _write_manifest(self) -> None:
        if self._manifest is None:
            return
        self._manifest['pids'] = {n: proc.pid for n, proc in self.processes.procs.items()}
        try:
            write_private(self._manifest_path, json.dumps(self._manifest))
        except OSError as exc:  # the first manifest stands; status/switch lack the pids
            self.log(f'[adcs] WARNING: cannot update {self._manifest_path}: {exc.strerror}')

    # ------------------------------------------------------------------ run
    def run(self) -> RunResult:
        """Run the scenario to its end (or Ctrl-C / a failed node); returns the outcome."""
        t0 = time.monotonic()
        try:
            private_dir(isolation.RUNS_DIR)
            prune_runs(protect=[self.run_dir])
            private_dir(self.run_dir)
            self._params_path = os.path.join(self.run_dir, 'params.yaml')
            write_private(self._params_path, params_file_text(self._started_nodes()))
        except (OSError, LaunchError) as exc:
            why = ('disk full' if isinstance(exc, OSError) and disk_full(exc)
                   else str(getattr(exc, 'strerror', None) or exc))
            return self._result(1, t0, f'cannot prepare the run directory {self.run_dir}: '
                                f'{why}')
        try:
            domain, lock = acquire_domain(RUN_DOMAINS if self.domain is None
                                          else [self.domain])
        except LaunchError as exc:
            return self._result(2, t0, f'{exc} (another run holds it: give another --domain)')
        try:
            return self._run_in(domain, t0)
        finally:
            lock.close()

    def _result(self, code: int, t0: float, message: str, monitor: Optional[Monitor] = None,
                ) -> RunResult:
        """The outcome; ``bag`` only when one was written."""
        sim_s = monitor.sim_ns / 1e9 if monitor is not None else 0.0
        bag = self.record if self.record and os.path.exists(self.record) else None
        return RunResult(code, sim_s, time.monotonic() - t0,
                         int(round(sim_s / self.sc['timing']['frame_s'])),
                         monitor.missed_frames if monitor is not None else 0, bag,
                         self.run_dir, message, self._master_result('frames_per_s'),
                         dict(self.healer.restarts))

    def _run_in(self, domain: int, t0: float) -> RunResult:
        from adcs_nodes.nodes.lockstep_node import epoch_to_ns, parse_epoch

        self._env = env = child_env(domain)
        use_dds_env(env)
        self._manifest_path = os.path.join(isolation.RUNS_DIR, f'active-{os.getpid()}.json')
        manifest = {'pid': os.getpid(), 'domain': domain, 'scenario': self.sc['_path'],
                    'epoch': self.sc['epoch'], 'bag': self.record, 'run_dir': self.run_dir,
                    'compose': self.compose}
        try:
            write_private(self._manifest_path, json.dumps(manifest))
        except OSError as exc:
            return self._result(1, t0, f'cannot write {self._manifest_path}: '
                                f'{exc.strerror or exc}')
        monitor = Monitor(epoch_to_ns(parse_epoch(self.sc['epoch'])),
                          watch_ready=not self.compose)
        old = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        self._say_start(domain, env)
        code, message = 0, ''
        try:
            self.processes.spawn_all(self._commands(self._params_path), env)
            self.transitions = Transitions(monitor.node, [] if self.compose else
                                           [n.name for n in self.nodes if is_managed(n)])
            self.transitions.unanswered_s = HEAL_UNANSWERED_S
            self._manifest = manifest
            self._write_manifest()
            code, message = self._watch(monitor, t0)
        except OSError as exc:   # a log file or the node processes could not be created
            code, message = 1, (f'cannot start the nodes: '
                                f'{"disk full" if disk_full(exc) else exc.strerror or exc}')
        finally:
            self.processes.stop_all(monitor)
            if code == 2 and not monitor.clock_seen and self.record:
                shutil.rmtree(self.record, ignore_errors=True)   # refused: nothing recorded
            if self.progress:
                sys.stderr.write('\n')
            code, message = closing_text(
                code, message, monitor, self.run_dir, self.record,
                int(self._master_result('security_events')), self.healer.notes,
                degraded_text(self.sc, self.lost, self.kills, monitor.sim_ns / 1e9,
                              monitor.controller_status))
            monitor.close()
            for sig, handler in old.items():
                signal.signal(sig, handler)
            try:
                os.unlink(self._manifest_path)
            except OSError:
                pass
            saved = save_scenario(self.sc, self.record, self.duration_s)
            if saved and code == 0:
                code, message = 1, saved
            elif saved:
                message += f'\n{saved}'
        return self._result(code, t0, message, monitor)

    def _say_start(self, domain: int, env: Dict[str, str]) -> None:
        self.log(f'[adcs] run {self.sc["name"]}: {len(self.nodes)} nodes '
                 f'({"composed in one process" if self.compose else "one process each"}), '
                 f'ROS_DOMAIN_ID={domain}, logs in {self.run_dir}/logs')
        lines = external_devices(self.sc)
        for line in lines:
            self.log(f'[adcs] {line}')
        if lines:      # what a driver needs to join this run's (private) domain
            self.log('[adcs] a driver joins with: ' + ' '.join(
                f'{k}={env[k]}' for k in DDS_ENV_KEYS if env.get(k)))

    def _kill_due(self, monitor: Monitor) -> None:
        """SIGKILL a ``node_killed`` fault's node once the clock reached it (it is silent)."""
        for name, f in self.kills.items():
            proc = self.processes.procs.get(name)
            if self.compose or proc is None or name in self.killed \
                    or monitor.sim_ns < round(float(f['at_s']) * 1e9):
                continue
            self.killed.add(name)
            try:
                os.kill(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.log(f'[adcs] {name}: killed (SIGKILL) by the scenario\'s faults[{f["index"]}] '
                     f'at sim t = {float(f["at_s"]):g} s')

    def _master_result(self, key: str) -> float:
        """A value of the clock master's result file, 0 if none."""
        try:
            with open(self.result_file) as fh:
                return float(json.load(fh)[key])
        except (OSError, ValueError, KeyError, TypeError):
            return 0.0

    def _on_signal(self, signum, frame) -> None:
        self._stop_requested = True

    def _master_name(self) -> str:
        return 'composed' if self.compose else 'dynamics'

    # ------------------------------------------------------------------ watch
    def _watch(self, monitor: Monitor, t0: float):
        """Spin the monitor until the run ends; ``(exit code, message)``."""
        total_ns = int(round(self.duration_s * 1e9))
        last_print = healed_at = 0.0
        seen_ns, seen_at = -1, time.monotonic()
        while True:
            monitor.spin(0.02 if self.transitions.pending else 0.1)
            failed = self.transitions.poll()
            if failed is not None and failed[1] == 'unanswered':
                failed = self.healer.lifecycle(monitor, self.transitions, failed[0])
            if failed is not None:
                return self._transition_failed(*failed)
            now = time.monotonic()
            if not self.compose and not monitor.clock_seen and now - healed_at >= 1.0:
                healed_at = now
                stuck = self.healer.check(monitor, self.transitions)
                if stuck is not None:
                    return stuck
            if self.progress and now - last_print > 0.5:
                last_print = now
                self._print_progress(monitor, now - t0, total_ns)
            if monitor.sim_ns != seen_ns:
                seen_ns, seen_at = monitor.sim_ns, now
            elif monitor.clock_seen and now - seen_at > self.stall_notice_s:
                seen_at = now      # a stall is said, not hidden (the run is not stopped)
                self._say_stalled(seen_ns)
            if self._stop_requested:
                return 130, ('interrupted (Ctrl-C): nodes stopped'
                             + (', bag closed' if self.record else ''))
            if monitor.recorder_error:   # also in composed mode, where the process lives on
                return 1, write_failed_text(monitor.recorder_error, self.record)
            self._kill_due(monitor)
            ended = self._check_children(monitor, total_ns)
            if ended is not None:
                return ended

    def _say_stalled(self, seen_ns: int) -> None:
        master = self._master_name()
        waits = [ln for ln in self.processes.tail(master, 40).splitlines()
                 if 'waiting' in ln or 'behind' in ln or 'no ' in ln]
        self.log(f'[adcs] WARNING: sim time has not advanced for {self.stall_notice_s:g} s '
                 f'(t = {seen_ns / 1e9:g} s)'
                 + (f'; {master}: {waits[-1].strip()}' if waits else
                    f'; see {self.run_dir}/logs/') + ' (Ctrl-C stops the run)')

    def _check_children(self, monitor: Monitor, total_ns: int):
        """``(exit code, message)`` when a child's exit ends the run, else None."""
        for name, proc in self.processes.procs.items():
            rc = proc.poll()
            if rc is None or name in self.lost:
                continue
            if name == self._master_name() and rc == 0:
                return self._finish(monitor, total_ns)
            tail = self.processes.tail(name)
            log = self.processes.log_path(name)
            if name in ('recorder', 'composed') and monitor.recorder_error:
                return 1, write_failed_text(monitor.recorder_error, self.record)
            if name == 'recorder' and rc == RECORDER_WRITE_FAILED:
                return 1, write_failed_text(('disk full' if 'disk full' in tail else
                                             'write error') + f', see {log}', self.record)
            if name not in ESSENTIAL and rc != 2 and not monitor.clock_seen:
                return 1, (f'node {name} exited with code {rc} during start-up (the lockstep '
                           f'cannot start without it); last lines of its log ({log}):\n{tail}')
            if name not in ESSENTIAL and rc != 2:
                # flight software died (a crash, a kill): the graph goes on without it;
                # its consumers time out and fall back (manager -> safe controller)
                self.lost[name] = monitor.sim_ns / 1e9
                self.log(f'[adcs] WARNING: node {name} exited with code {rc}; the graph goes '
                         f'on without it (log: {log})')
                continue
            if rc == 2:   # a node refused its configuration: bad input, as the CLI's
                return 2, (f'node {name} refused its configuration (exit code 2); last lines '
                           f'of its log ({log}):\n{tail}')
            return 1, (f'node {name} exited with code {rc} before the end of the run; last '
                       f'lines of its log ({log}):\n{tail}')
        return None

    def _transition_failed(self, name: str, transition: str):
        """Exit code and message for a managed node that was not made active."""
        stack = (self.processes.dump_stack(name) if transition in ('unanswered', 'deadline')
                 else '')
        return transition_failed_text(
            name, transition, self.processes.log_path(name), self.processes.tail(name), stack,
            HEAL_UNANSWERED_S, self.healer.restarts.get(name, 0), self.transitions.step.get(name),
            self.transitions.deadline_s)

    def _finish(self, monitor: Monitor, total_ns: int):
        monitor.sim_ns = max(monitor.sim_ns, total_ns)
        if self.record and not self.compose:
            deadline = time.monotonic() + 15.0
            while monitor.recorder_clock_ns < total_ns and time.monotonic() < deadline:
                if self.processes.procs['recorder'].poll() is not None:
                    break
                monitor.spin(0.1)
            # every node has done its last frame (the master waited for them): the recorder
            # has everything once its message count stops growing
            if self.processes.procs['recorder'].poll() is None:
                monitor.wait_recorder_settled(deadline)
            if monitor.recorder_clock_ns < total_ns:
                return 1, ('recorder did not receive the final frame within 15 s: '
                           'the bag may miss the end of the run')
        return 0, 'done'

    def _print_progress(self, monitor: Monitor, wall: float, total_ns: int) -> None:
        frac = min(1.0, monitor.sim_ns / total_ns) if total_ns else 0.0
        sim_s = monitor.sim_ns / 1e9
        rtf = sim_s / wall if wall > 0 else 0.0
        bar = '#' * int(frac * 30) + '.' * (30 - int(frac * 30))
        line = (f'[{bar}] sim {sim_s:8.1f}/{total_ns / 1e9:g} s  {rtf:7.1f}x real time  '
                f'missed frames {monitor.missed_frames}')
        if sys.stderr.isatty():
            sys.stderr.write('\r' + line)
        else:
            step = int(frac * 10)
            if step != getattr(self, '_last_step', -1):
                self._last_step = step
                sys.stderr.write(line + '\n')
        sys.stderr.flush()
