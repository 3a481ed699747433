"""``adcs soak``: launch short runs back to back beside CPU burners and count how they end.

Every shipped scenario (or those given), a few frames each, one process per node and
``--compose``, in turn, until ``--launches`` runs were made or ``--time-budget`` seconds are
spent, beside ``--burners`` busy-looping processes that this command starts and stops itself.
Each run is an ``adcs run`` child process with a deadline; its outcome is one of
:data:`OUTCOMES`:

* ``finished``: exit 0 (or 3, degraded, with no node lost to a signal);
* ``healed``: finished after the launcher restarted a node before frame 0 (its summary says
  ``restarted``);
* ``start_timeout``: the lockstep never started (``lockstep not started``), with the nodes
  that never said ready and each node's last ``still waiting for endpoints`` line (the
  unmatched endpoints and how many peer endpoints its discovery knew);
* ``lifecycle_timeout``: a managed node not active by its deadline;
* ``crash``: the launcher or a node killed by a signal (``signal`` names it);
* ``hang``: the run outlived its deadline and was killed (``at teardown`` when the graph had
  finished its frames, else ``before the end``);
* ``failed``: any other non-zero exit (the first line of its message);
* ``cut``: stopped because the time budget ran out (not counted as a failure).

The launcher output and a copy of the run directory (``~/.cache/adcs/runs/...``: node logs,
parameters) of every launch that is not ``finished`` are kept under ``OUT/failures/``; every
launch is a row of ``OUT/soak.csv``; the table printed at the end is also ``OUT/summary.md``.
Every wait has a deadline: the command ends within the time budget plus one kill grace
(:data:`KILL_GRACE_S`) and the burners' stop.

The outcome classification (:func:`classify`) and the bounded loop (:class:`Soak`, with any
command in place of ``adcs run``) are tested without ROS: ``tests/unit/test_soak.py``.
"""
from __future__ import annotations

import argparse
import csv
import glob
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import Callable, Dict, List, Optional, Sequence

OUTCOMES = ('finished', 'healed', 'start_timeout', 'lifecycle_timeout', 'crash', 'hang',
            'failed', 'cut')
#: Outcomes that count as a failed launch.
FAILURES = ('start_timeout', 'lifecycle_timeout', 'crash', 'hang', 'failed')
MODES = ('processes', 'composed')
#: Seconds between SIGINT and SIGKILL of a run that outlived its deadline.
KILL_GRACE_S = 15.0
#: Default wall-clock deadline of one run [s]: the launcher's lifecycle deadline (120 s from a
#: node's start or restart) and the clock master's start limit in a launched run (180 s) end
#: a failed start by themselves before this.
RUN_DEADLINE_S = 260.0
#: A launch is not started with less than this much of the time budget left [s].
MIN_LAUNCH_S = 15.0
#: Busy loop of one CPU burner; it dies with the soak process (parent-death signal).
BURNER = ('import ctypes, signal\n'
          'try:\n'
          '    ctypes.CDLL(None).prctl(1, int(signal.SIGKILL), 0, 0, 0)\n'
          'except Exception:\n'
          '    pass\n'
          'while True:\n'
          '    pass\n')

_RUN_DIR = re.compile(r'logs in (\S+)/logs')
_NOT_STARTED = re.compile(r'lockstep not started after [0-9.]+ s: (.*)')
_WAITING = re.compile(r'still waiting for endpoints after ([0-9.]+) s: (.*)')
_NOT_ACTIVE = re.compile(r'node (\S+) was not active [0-9.]+ s after its start '
                         r'\(lifecycle: ([^)]*)\)')
_EXITED = re.compile(r'node (\S+) exited with code (-?\d+)')
_RESTARTED = re.compile(r'\[adcs\] restart(?:ed|ing) (?:node )?(\S+?)[: ]')
_RESTARTS = re.compile(r'restarts?: (\d+)')
_RESTART_WHY = re.compile(r'\[adcs\] restarting node (\S+) before frame 0 \([^)]*\): (.*)')
_SEGV_TEXT = re.compile(r'Fatal Python error: (Segmentation fault|Aborted|Bus error)')


@dataclass
class Launch:
    """One launch and its outcome."""

    index: int
    scenario: str
    mode: str
    outcome: str = ''
    detail: str = ''
    exit_code: Optional[int] = None
    wall_s: float = 0.0
    restarts: int = 0
    signal: str = ''
    run_dir: str = ''
    kept: str = ''
    load: float = 0.0


def signal_name(num: int) -> str:
    """``SIGSEGV`` for 11 (or ``signal N``)."""
    try:
        return signal.Signals(num).name
    except ValueError:
        return f'signal {num}'


def run_dir_of(output: str) -> str:
    """The run directory the launcher named in its first line (``''`` if none)."""
    m = _RUN_DIR.search(output)
    return m.group(1) if m else ''


def waiting_lines(run_dir: str) -> Dict[str, str]:
    """Each node's last ``still waiting for endpoints`` line in the run's logs: what it had
    not matched and how many peer endpoints its discovery knew (``sub:/clock 0/1
    (discovery knows 0)``)."""
    out = {}
    for path in sorted(glob.glob(os.path.join(run_dir, 'logs', '*.log'))):
        last = ''
        try:
            with open(path, encoding='utf-8', errors='replace') as fh:
                for line in fh:
                    m = _WAITING.search(line)
                    if m:
                        last = m.group(2).strip()
        except OSError:
            continue
        if last:
            out[os.path.basename(path)[:-4]] = last
    return out


def _log_text(run_dir: str) -> str:
    text = []
    for path in sorted(glob.glob(os.path.join(run_dir, 'logs', '*.log'))):
        try:
            with open(path, encoding='utf-8', errors='replace') as fh:
                text.append(fh.read())
        except OSError:
            pass
    return '\n'.join(text)


def classify(exit_code: Optional[int], output: str, run_dir: str = '',
             timed_out: bool = False, cut: bool = False, finished_frames: bool = False):
    """Outcome of one launch: ``(outcome, detail, signal name, restarts)``.

    ``exit_code``: of the ``adcs run`` process (negative: killed by that signal; None: it
    was killed by the soak after its deadline, ``timed_out``, or because the time budget ran
    out, ``cut``); ``output``: its stdout and stderr; ``run_dir``: the run directory (node
    logs); ``finished_frames``: the graph had finished its frames (the clock master's result
    file) when a timed-out run was killed.
    """
    restarts = sum(int(n) for n in _RESTARTS.findall(output))
    if not restarts:
        restarts = len(_RESTARTED.findall(output))
    if cut:
        return 'cut', 'stopped: the time budget ran out', '', restarts
    if timed_out:
        ended = finished_frames or re.search(r'\[adcs\] \S.* s sim in', output)
        where = 'at teardown' if ended else 'before the end'
        return 'hang', f'killed after its deadline ({where})', '', restarts
    if exit_code is not None and exit_code < 0:
        name = signal_name(-exit_code)
        return 'crash', f'adcs run killed by {name}', name, restarts
    for node, code in _EXITED.findall(output):
        if int(code) < 0:
            name = signal_name(-int(code))
            return 'crash', f'node {node} killed by {name}', name, restarts
    fatal = _SEGV_TEXT.search(output) or (
        _SEGV_TEXT.search(_log_text(run_dir)) if run_dir and exit_code else None)
    if fatal and exit_code:
        name = {'Segmentation fault': 'SIGSEGV', 'Aborted': 'SIGABRT',
                'Bus error': 'SIGBUS'}[fatal.group(1)]
        return 'crash', f'{fatal.group(0)}', name, restarts
    if exit_code in (0, 3):
        detail = '' if exit_code == 0 else 'degraded: ' + _first_line(output, 'DEGRADED')
        why = _RESTART_WHY.findall(output) if restarts else []
        if why:           # which nodes, and the first one's reason (the unmatched endpoints)
            detail = '; '.join(filter(None, ['restarted ' + ', '.join(n for n, _ in why),
                                             f'{why[0][0]}: {why[0][1]}', detail]))
        return 'healed' if restarts else 'finished', detail, '', restarts
    m = _NOT_ACTIVE.search(output)
    if m:
        return 'lifecycle_timeout', f'{m.group(1)} not active (lifecycle: {m.group(2)})', '', \
            restarts
    m = _NOT_STARTED.search(output) or (
        _NOT_STARTED.search(_log_text(run_dir)) if run_dir else None)
    if m:
        waits = waiting_lines(run_dir) if run_dir else {}
        detail = m.group(1).strip()
        if waits:
            detail += '; ' + '; '.join(f'{n}: {w}' for n, w in sorted(waits.items()))
        return 'start_timeout', detail, '', restarts
    return 'failed', _message(output) or f'exit code {exit_code}', '', restarts


def _first_line(output: str, key: str) -> str:
    for line in output.splitlines():
        if key in line:
            return line.strip()
    return ''


def _message(output: str) -> str:
    """The launcher's result message (the ``[adcs]`` line before the summary line)."""
    lines = [ln.strip() for ln in output.splitlines() if ln.strip()]
    for i, line in enumerate(lines):
        if re.search(r'\[adcs\] \S.* s sim in', line) and i > 0:
            return lines[i - 1][:300]
    return lines[-1][:300] if lines else ''


# ---------------------------------------------------------------------------------- burners
class Burners:
    """``n`` busy-looping processes (each one core at normal priority) while in ``with``."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.procs: List[subprocess.Popen] = []

    def __enter__(self) -> 'Burners':
        for _ in range(self.n):
            self.procs.append(subprocess.Popen([sys.executable, '-S', '-c', BURNER],
                                               stdin=subprocess.DEVNULL,
                                               stdout=subprocess.DEVNULL,
                                               stderr=subprocess.DEVNULL))
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def stop(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
        for proc in self.procs:
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                pass
        self.procs = []


# ---------------------------------------------------------------------------------- runs
def frame_s_of(path: str) -> float:
    """A scenario's base frame [s] (1.0 if it cannot be read: the launcher then says why)."""
    import yaml
    try:
        with open(path, encoding='utf-8') as fh:
            return float(yaml.safe_load(fh)['timing']['frame_s'])
    except (OSError, ValueError, TypeError, KeyError, AttributeError, yaml.YAMLError):
        return 1.0


def adcs_run_command(scenario: str, mode: str, duration_s: float) -> List[str]:
    """``adcs run`` of one launch (the soak's own interpreter and environment)."""
    cmd = [sys.executable, '-m', 'adcs_nodes.tools.cli', 'run', scenario, '--duration',
           f'{duration_s:g}', '--quiet']
    return cmd + (['--compose'] if mode == 'composed' else [])


def _manifest_pids(pid: int) -> List[int]:
    """Node PIDs of a live launcher's run (its ``active-<pid>.json``)."""
    from adcs_nodes.tools.run.launcher import RUNS_DIR
    try:
        with open(os.path.join(RUNS_DIR, f'active-{pid}.json')) as fh:
            return [int(p) for p in json.load(fh).get('pids', {}).values()]
    except (OSError, ValueError, TypeError, AttributeError):
        return []


def _kill_group(proc: subprocess.Popen, grace_s: float) -> None:
    """SIGINT the run's process group (the launcher stops its nodes), SIGKILL after
    ``grace_s``; node processes the launcher named in its manifest are killed too."""
    pids = _manifest_pids(proc.pid)
    for sig, wait in ((signal.SIGINT, grace_s), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            proc.wait(timeout=wait)
            break
        except subprocess.TimeoutExpired:
            continue
    for pid in pids:      # a node that ignored its parent-death signal (stuck in C code)
        try:
            with open(f'/proc/{pid}/cmdline', 'rb') as fh:
                if b'python' not in fh.read():
                    continue
            os.kill(pid, signal.SIGKILL)
        except (OSError, ValueError):
            pass


def launch_env(base: Dict[str, str], changes: Dict[str, str], index: int) -> Dict[str, str]:
    """``base`` with ``changes`` whose ``{launch}`` is replaced by the launch's number: a
    value per launch, e.g. ``NUMBA_CACHE_DIR=/tmp/cold/{launch}`` (a cold kernel cache that
    every process of the run fills at once)."""
    env = dict(base)
    env.update({k: v.replace('{launch}', str(index)) for k, v in changes.items()})
    return env


def run_one(cmd: Sequence[str], deadline_s: float, env: Optional[Dict[str, str]] = None,
            budget_end: float = float('inf'), grace_s: float = KILL_GRACE_S):
    """Run ``cmd`` (own session) until it exits, its deadline or the budget's end.

    Returns ``(exit_code or None, output, timed_out, cut, wall_s)``; the output is read from
    a file (a child's pipe can never block it)."""
    import tempfile
    t0 = time.monotonic()
    end = min(t0 + deadline_s, budget_end)
    with tempfile.TemporaryFile(mode='w+b') as out:
        proc = subprocess.Popen(list(cmd), stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=env, start_new_session=True)
        code, timed_out, cut = None, False, False
        try:
            code = proc.wait(timeout=max(0.0, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            cut = t0 + deadline_s > budget_end and time.monotonic() >= budget_end
            timed_out = not cut
            _kill_group(proc, grace_s)
        except BaseException:      # Ctrl-C of the soak: stop this run too, then go up
            _kill_group(proc, grace_s)
            raise
        out.seek(0)
        output = out.read().decode('utf-8', errors='replace')
    return code, output, timed_out, cut, time.monotonic() - t0


@dataclass
class Soak:
    """The bounded loop: ``launches`` runs (or fewer when ``time_budget_s`` is spent)."""

    scenarios: List[str]
    launches: int = 20
    burners: int = 2
    time_budget_s: float = 600.0
    modes: Sequence[str] = MODES
    frames: int = 3
    out: str = ''
    run_deadline_s: float = RUN_DEADLINE_S
    env: Dict[str, str] = field(default_factory=dict)
    label: str = ''
    #: ``command(scenario, mode, duration_s)`` -> argv (default: ``adcs run``)
    command: Callable[[str, str, float], List[str]] = adcs_run_command
    grace_s: float = KILL_GRACE_S
    log: Callable[[str], None] = print
    results: List[Launch] = field(default_factory=list)

    def plan(self):
        """(scenario, mode) of every launch, scenarios and modes in turn."""
        pairs = [(s, m) for s in self.scenarios for m in self.modes]
        return [pairs[i % len(pairs)] for i in range(self.launches)] if pairs else []

    def run(self) -> List[Launch]:
        t0 = time.monotonic()
        budget_end = t0 + self.time_budget_s
        env = dict(os.environ)
        env.update(self.env)
        env['PYTHONUNBUFFERED'] = '1'
        os.makedirs(self.out, exist_ok=True)
        with Burners(self.burners):
            for i, (scenario, mode) in enumerate(self.plan()):
                if budget_end - time.monotonic() < min(MIN_LAUNCH_S, 0.5 * self.time_budget_s):
                    break
                duration = self.frames * frame_s_of(scenario)
                launch = Launch(i + 1, os.path.basename(scenario).rsplit('.', 1)[0], mode,
                                load=os.getloadavg()[0])
                code, output, timed_out, cut, wall = run_one(
                    self.command(scenario, mode, duration), self.run_deadline_s,
                    launch_env(env, self.env, i + 1), budget_end, self.grace_s)
                launch.exit_code, launch.wall_s = code, wall
                launch.run_dir = run_dir_of(output)
                finished_frames = bool(launch.run_dir) and os.path.isfile(
                    os.path.join(launch.run_dir, 'dynamics_result.json'))
                (launch.outcome, launch.detail, launch.signal,
                 launch.restarts) = classify(code, output, launch.run_dir, timed_out, cut,
                                             finished_frames)
                if launch.outcome != 'finished':
                    launch.kept = self._keep(launch, output)
                self.results.append(launch)
                self.log(f'[soak] {launch.index:4d} {launch.scenario:34s} {mode:9s} '
                         f'{launch.outcome:17s} {wall:6.1f} s  load {launch.load:5.1f}'
                         + (f'  {launch.detail[:150]}' if launch.detail else ''))
                if cut:
                    break
        self._write()
        return self.results

    def _keep(self, launch: Launch, output: str) -> str:
        """Copy the launcher output and the run directory of a launch that did not finish
        cleanly into ``OUT/failures/<index>-<scenario>-<mode>``."""
        dest = os.path.join(self.out, 'failures',
                            f'{launch.index:04d}-{launch.scenario}-{launch.mode}')
        try:
            os.makedirs(dest, exist_ok=True)
            with open(os.path.join(dest, 'adcs_run.out'), 'w', encoding='utf-8') as fh:
                fh.write(output)
            if launch.run_dir and os.path.isdir(launch.run_dir):
                shutil.copytree(launch.run_dir, os.path.join(dest, 'run'),
                                dirs_exist_ok=True, ignore_dangling_symlinks=True)
        except OSError as exc:
            self.log(f'[soak] could not keep the logs of launch {launch.index}: {exc}')
        return dest

    def _write(self) -> None:
        with open(os.path.join(self.out, 'soak.csv'), 'w', newline='',
                  encoding='utf-8') as fh:
            names = list(asdict(Launch(0, '', '')).keys())
            writer = csv.DictWriter(fh, fieldnames=names)
            writer.writeheader()
            for launch in self.results:
                writer.writerow(asdict(launch))
        with open(os.path.join(self.out, 'summary.md'), 'w', encoding='utf-8') as fh:
            fh.write(self.table() + '\n')

    def table(self) -> str:
        """The outcome counts per mode and the failures, as Markdown."""
        res = self.results
        loads = [r.load for r in res] or [0.0]
        wall = sum(r.wall_s for r in res)
        head = (f'soak{" " + self.label if self.label else ""}: {len(res)} launches '
                f'({wall:.0f} s of runs) beside {self.burners} CPU burner(s), '
                f'{self.frames} frames each, load average {min(loads):.1f}-{max(loads):.1f}'
                + (f'; env {" ".join(f"{k}={v}" for k, v in self.env.items())}'
                   if self.env else ''))
        lines = [head, '', '| mode | launches | ' + ' | '.join(OUTCOMES) + ' | restarts |',
                 '|---|---:|' + '---:|' * (len(OUTCOMES) + 1)]
        for mode in list(self.modes) + ['total']:
            rows = [r for r in res if mode in ('total', r.mode)]
            counts = [sum(r.outcome == o for r in rows) for o in OUTCOMES]
            lines.append(f'| {mode} | {len(rows)} | ' + ' | '.join(map(str, counts))
                         + f' | {sum(r.restarts for r in rows)} |')
        bad = [r for r in res if r.outcome not in ('finished', 'cut')]
        if bad:
            lines += ['', 'not finished cleanly:']
            for r in bad:
                lines.append(f'- #{r.index} {r.scenario} ({r.mode}): {r.outcome}'
                             + (f' [{r.signal}]' if r.signal else '')
                             + f': {r.detail} (logs: {r.kept})')
        return '\n'.join(lines)

    @property
    def failed(self) -> int:
        return sum(r.outcome in FAILURES for r in self.results)


# ---------------------------------------------------------------------------------- discovery
#: One participant of :func:`probe_discovery`: a node with a writer and a reader on one topic;
#: at the end it prints how many writers its reader matched and when it first matched all.
PROBE = (
    'import os, sys, time\n'
    'import rclpy\n'
    'from std_msgs.msg import String\n'
    't_end, n = float(sys.argv[1]), int(sys.argv[2])\n'
    'rclpy.init()\n'
    'node = rclpy.create_node("probe%d" % os.getpid())\n'
    'node.create_publisher(String, "adcs_probe", 10)\n'
    'sub = node.create_subscription(String, "adcs_probe", lambda m: None, 10)\n'
    't0, full = time.time(), -1.0\n'
    'while time.time() < t_end:\n'
    '    rclpy.spin_once(node, timeout_sec=0.05)\n'
    '    if full < 0 and sub.get_publisher_count() >= n:\n'
    '        full = time.time() - t0\n'
    'print("PROBE %d %d %.3f" % (sub.get_publisher_count(), node.count_publishers("adcs_probe"),'
    ' full), flush=True)\n'
    'os._exit(0)\n')


def probe_discovery(n: int, wait_s: float, env: Dict[str, str]) -> List[tuple]:
    """Start ``n`` participants at once on a free run domain (the launcher's discovery
    settings and Fast DDS profile, or ``env``'s); after ``wait_s`` each says how many of the
    ``n`` writers (its own included) its reader matched, how many its discovery knew, and
    when it had matched all (-1: never). Returns those ``(matched, known, full_s)``."""
    from adcs_nodes.tools.run.launcher import acquire_domain, child_env
    domain, lock = acquire_domain()
    try:
        run_env = child_env(domain)
        run_env.update(env)
        t_end = time.time() + wait_s
        procs = [subprocess.Popen([sys.executable, '-c', PROBE, f'{t_end:.3f}', str(n)],
                                  env=run_env, stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
                                  start_new_session=True) for _ in range(n)]
        out = []
        for proc in procs:
            try:
                text, _ = proc.communicate(timeout=max(1.0, t_end - time.time()) + 30.0)
            except subprocess.TimeoutExpired:
                _kill_group(proc, 1.0)
                text = b''
            m = re.search(rb'PROBE (\d+) (\d+) (-?[0-9.]+)', text or b'')
            out.append((int(m.group(1)), int(m.group(2)), float(m.group(3))) if m
                       else (-1, -1, -1.0))
        return out
    finally:
        lock.close()


def discovery_table(label: str, n: int, trials: List[List[tuple]], burners: int,
                    env: Dict[str, str]) -> str:
    """Markdown summary of :func:`probe_discovery` trials."""
    parts = [p for t in trials for p in t]
    incomplete = [p for p in parts if p[0] < n]
    fulls = sorted(p[2] for p in parts if p[2] >= 0)
    missing = sum(n - max(p[0], 0) for p in parts)
    med = fulls[len(fulls) // 2] if fulls else float('nan')
    return (f'discovery probe{" " + label if label else ""}: {len(trials)} trials of {n} '
            f'participants started at once beside {burners} CPU burner(s)'
            + (f'; env {" ".join(f"{k}={v}" for k, v in env.items())}' if env else '')
            + f'\n\n| participants | not matched with all at the end | writer matches '
            f'missing | time to all matched: median | p90 | max |\n|---:|---:|---:|---:|---:|'
            f'---:|\n| {len(parts)} | {len(incomplete)} | {missing} | {med:.2f} s | '
            + (f'{fulls[int(0.9 * (len(fulls) - 1))]:.2f} s | {fulls[-1]:.2f} s |' if fulls
               else '- | - |'))


def run_probe(args, env: Dict[str, str], out: str) -> int:
    """``adcs soak --discovery-probe N``: trials of :func:`probe_discovery`."""
    os.makedirs(out, exist_ok=True)
    trials: List[List[tuple]] = []
    end = time.monotonic() + args.time_budget
    with Burners(args.burners):
        for i in range(args.launches):
            if end - time.monotonic() < args.probe_wait + 5.0:
                break
            trials.append(probe_discovery(args.discovery_probe, args.probe_wait, env))
            print(f'[soak] probe {i + 1}: matched ' + ' '.join(str(p[0]) for p in trials[-1])
                  + '  all after ' + ' '.join(f'{p[2]:.1f}' for p in trials[-1]), flush=True)
    table = discovery_table(args.label, args.discovery_probe, trials, args.burners, env)
    with open(os.path.join(out, 'summary.md'), 'w', encoding='utf-8') as fh:
        fh.write(table + '\n')
    with open(os.path.join(out, 'probe.json'), 'w', encoding='utf-8') as fh:
        json.dump(trials, fh)
    print(table)
    parts = [p for t in trials for p in t]
    return 1 if any(p[0] < args.discovery_probe for p in parts) else 0


# ---------------------------------------------------------------------------------- CLI
def default_scenarios() -> List[str]:
    from adcs_nodes.tools.cli import _default_scenario_dir
    return sorted(glob.glob(os.path.join(_default_scenario_dir(), '*.yaml')))


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Arguments of ``adcs soak``."""
    p.add_argument('--launches', type=int, default=20, metavar='N',
                   help='runs to launch (scenarios and modes in turn; default 20)')
    p.add_argument('--burners', type=int, default=2, metavar='N',
                   help='CPU burners beside the runs (default 2)')
    p.add_argument('--time-budget', type=float, default=600.0, metavar='S',
                   help='stop launching after this many wall seconds (default 600)')
    p.add_argument('--scenarios', nargs='+', metavar='YAML',
                   help='scenario files (default: every scenarios/*.yaml)')
    p.add_argument('--modes', nargs='+', choices=MODES, default=list(MODES),
                   help='processes (one per node), composed, or both (default)')
    p.add_argument('--frames', type=int, default=3, metavar='K',
                   help='frames per run (--duration = K base frames; default 3)')
    p.add_argument('--out', metavar='DIR', help='where the table, soak.csv and the logs of '
                   'every failure go (default out/soak-<time>)')
    p.add_argument('--run-deadline', type=float, default=RUN_DEADLINE_S, metavar='S',
                   help=f'a run still alive after this is a hang (default {RUN_DEADLINE_S:g})')
    p.add_argument('--env', action='append', default=[], metavar='KEY=VALUE',
                   help='environment of the runs (A/B experiments, e.g. '
                   'FASTDDS_DEFAULT_PROFILES_FILE=other.xml); {launch} in a value is the '
                   'launch number (NUMBA_CACHE_DIR=/tmp/cold/{launch}); repeatable')
    p.add_argument('--label', default='', help='name of the experiment in the table')
    p.add_argument('--discovery-probe', type=int, default=0, metavar='N',
                   help='instead of runs: --launches trials of N bare participants started '
                   'at once (the launcher\'s discovery settings), each saying how many '
                   'writers it matched and when')
    p.add_argument('--probe-wait', type=float, default=20.0, metavar='S',
                   help='seconds each discovery-probe trial lasts (default 20)')
    p.add_argument('--launcher-cmd', default='', help=argparse.SUPPRESS)   # tests: a fake


def run_from_args(args: argparse.Namespace) -> int:
    """``adcs soak``: 0 when no launch failed, 1 otherwise, 2 for bad arguments."""
    import shlex
    if args.launches < 1 or args.burners < 0 or args.frames < 1 or args.time_budget <= 0 \
            or args.run_deadline <= 0:
        print('adcs soak: --launches and --frames must be >= 1, --burners >= 0, '
              '--time-budget and --run-deadline > 0', file=sys.stderr)
        return 2
    env = {}
    for item in args.env:
        key, sep, value = item.partition('=')
        if not sep or not key:
            print(f'adcs soak: --env wants KEY=VALUE, got {item!r}', file=sys.stderr)
            return 2
        env[key] = value
    out = args.out or os.path.join('out', time.strftime('soak-%Y%m%d-%H%M%S'))
    if args.discovery_probe > 0:
        return run_probe(args, env, out)
    scenarios = [os.path.abspath(s) for s in (args.scenarios or default_scenarios())]
    missing = [s for s in scenarios if not os.path.isfile(s)]
    if missing or not scenarios:
        print(f'adcs soak: no scenario file {", ".join(missing) or "found"}', file=sys.stderr)
        return 2
    template = args.launcher_cmd

    def fake_command(scenario, mode, duration_s):
        return [a.format(scenario=scenario, mode=mode, duration=f'{duration_s:g}')
                for a in shlex.split(template)]
    command = fake_command if template else adcs_run_command
    soak = Soak(scenarios, launches=args.launches, burners=args.burners,
                time_budget_s=args.time_budget, modes=args.modes, frames=args.frames,
                out=out, run_deadline_s=args.run_deadline, env=env, label=args.label,
                command=command)
    try:
        soak.run()
    except KeyboardInterrupt:
        soak._write()
        print(soak.table())
        print(f'[soak] interrupted; table, soak.csv and logs in {out}')
        return 130
    print(soak.table())
    print(f'[soak] table, soak.csv and the logs of every failure in {out}')
    return 1 if soak.failed else 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``make soak`` (``PYTHONPATH=tests python -m perf.soak``)."""
    p = argparse.ArgumentParser(prog='make soak', description=__doc__.split('\n\n')[0])
    add_arguments(p)
    return run_from_args(p.parse_args(argv))


if __name__ == '__main__':
    raise SystemExit(main())
