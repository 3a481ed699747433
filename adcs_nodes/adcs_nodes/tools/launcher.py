"""The launcher behind ``adcs run``: start the scenario's graph, watch it, stop it cleanly.

* Isolation: each run takes a free ``ROS_DOMAIN_ID`` (1..100, claimed with a lock file so
  parallel runs never share one) and localhost-only discovery.
* One process per node (``python -m <module> --ros-args -r __node:=<name> --params-file ...``),
  or all nodes in one process (``--compose``, :mod:`adcs_nodes.tools.compose`).
* Progress: sim time, real-time factor, frames/s and missed frames, read from ``/clock`` and
  ``lockstep/status`` by a small monitor node in the launcher process.
* End: the clock master (dynamics) exits 0 after the last frame; the launcher waits until the
  recorder has seen the final clock, then stops every child with SIGINT (SIGKILL after a grace
  period). An essential child (world, recorder) that dies first stops the run with a message
  naming it and the tail of its log; a flight-software node that dies is reported and the run
  goes on (its consumers time out and fall back). A configuration error (exit code 2) of any
  node stops the run.
* Ctrl-C stops every child the same way; the bag is closed and valid.
* While a run is active, ``~/.cache/adcs/runs/active-<pid>.json`` names its domain, run
  directory, bag and node PIDs (for ``adcs switch``/``adcs status`` and the tests).
"""
from __future__ import annotations

import fcntl
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from typing import Dict, Iterable, List, Optional

import yaml

from adcs_nodes.tools.graph import NodeSpec, build_graph, params_file_text

DOMAIN_LOCK_DIR = os.path.join(tempfile.gettempdir(), 'adcs-domain-locks')
RUNS_DIR = os.path.join(os.path.expanduser('~'), '.cache', 'adcs', 'runs')
#: Nodes whose death ends the run: the simulated world, the recorder, the composed process.
#: Any other node (flight software) may die; the run goes on and its consumers fall back.
ESSENTIAL = {'dynamics', 'environment', 'recorder', 'composed'}


class LaunchError(RuntimeError):
    """The graph could not be started or a node failed; the message says which and why."""


@dataclass
class RunResult:
    """Outcome of a run."""

    exit_code: int
    sim_time_s: float
    wall_time_s: float
    frames: int
    missed_frames: int
    bag: Optional[str]
    run_dir: str
    message: str
    #: lockstep throughput measured by the clock master from frame 0 to its end [frames/s]
    frames_per_s: float = 0.0


def acquire_domain(domains: Iterable[int] = range(1, 101)):
    """Claim a free ROS_DOMAIN_ID of ``domains`` with an exclusive lock file.

    Returns ``(id, handle)``; the domain stays claimed until the handle is closed.
    """
    os.makedirs(DOMAIN_LOCK_DIR, exist_ok=True)
    ids = list(domains)
    random.shuffle(ids)
    for dom in ids:
        fh = open(os.path.join(DOMAIN_LOCK_DIR, f'{dom}.lock'), 'w')
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            continue
        return dom, fh
    raise LaunchError(f'no free ROS_DOMAIN_ID in {ids[0] if ids else "?"}.. '
                      f'({len(ids)} runs at once?)')


def child_env(domain: int) -> Dict[str, str]:
    """Environment of every child: the run's domain, localhost discovery, unbuffered output."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    # UDP on loopback only: Fast DDS shared-memory segments left in /dev/shm by killed
    # processes once kept two nodes of a new run from ever matching (seen in CI); UDP
    # loopback measured as fast for this graph (125-163 vs 131-132 frames/s)
    env.setdefault('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')
    return env


class _Monitor:
    """Launcher-side rclpy node: progress from /clock, lockstep/status and recorder/status."""

    def __init__(self, epoch_ns: int) -> None:
        import rclpy
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock

        from adcs_msgs.msg import LockstepStatus
        from adcs_nodes.nodes.convert import stamp_ns
        from adcs_nodes.nodes.runtime import make_executor

        self._rclpy = rclpy
        self._stamp_ns = stamp_ns
        self.epoch_ns = epoch_ns
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('adcs_launcher', context=self.context,
                                      start_parameter_services=False)
        self.sim_ns = 0
        self.status: Dict[str, LockstepStatus] = {}
        self.recorder_clock_ns = -1
        self.recorder_count = 0
        be = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.node.create_subscription(Clock, '/clock', self._on_clock, be)
        self.node.create_subscription(LockstepStatus, 'lockstep/status', self._on_status, 50)
        self.node.create_subscription(LockstepStatus, 'recorder/status', self._on_rec, 10)
        self.executor = make_executor(self.context)
        self.executor.add_node(self.node)

    def _on_clock(self, msg) -> None:
        self.sim_ns = max(self.sim_ns, self._stamp_ns(msg.clock) - self.epoch_ns)

    def _on_status(self, msg) -> None:
        self.status[msg.node] = msg

    def _on_rec(self, msg) -> None:
        self.recorder_clock_ns = self._stamp_ns(msg.header.stamp) - self.epoch_ns
        self.recorder_count = int(msg.frames)

    def spin(self, seconds: float) -> None:
        from rclpy.task import Future
        self.executor.spin_until_future_complete(Future(), timeout_sec=seconds)

    @property
    def missed_frames(self) -> int:
        return sum(int(s.missed_frames) for s in self.status.values())

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self.executor.shutdown()
        self._rclpy.shutdown(context=self.context)


class Launcher:
    """Start, watch and stop one scenario run (see module docstring)."""

    def __init__(self, scenario: dict, duration_s: Optional[float] = None,
                 record: Optional[str] = None, real_time: bool = False,
                 rate_factor: float = 1.0, compose: bool = False, progress: bool = True,
                 run_dir: Optional[str] = None, log=print) -> None:
        self.sc = scenario
        self.duration_s = float(duration_s if duration_s is not None else scenario['duration_s'])
        if not self.duration_s > 0:
            raise LaunchError(f'duration must be positive, got {self.duration_s}')
        frames = self.duration_s / scenario['timing']['frame_s']
        if abs(frames - round(frames)) > 1e-9:
            raise LaunchError(f'duration {self.duration_s} s is not a whole number of '
                              f'{scenario["timing"]["frame_s"]} s frames')
        self.record = os.path.abspath(record) if record else None
        if self.record and os.path.exists(self.record):
            raise LaunchError(f'bag {self.record} exists already; choose another --record path')
        self.real_time = real_time
        self.rate_factor = rate_factor
        self.compose = compose
        self.progress = progress
        self.log = log
        stamp = time.strftime('%Y%m%dT%H%M%S')
        self.run_dir = run_dir or os.path.join(RUNS_DIR, f'{stamp}-{scenario["name"]}-'
                                               f'{os.getpid()}')
        self.nodes: List[NodeSpec] = build_graph(scenario, self.duration_s, real_time,
                                                 rate_factor, record=bool(record))
        if self.record:
            rec = next(n for n in self.nodes if n.name == 'recorder')
            rec.params['output'] = self.record
        self.result_file = os.path.join(self.run_dir, 'dynamics_result.json')
        next(n for n in self.nodes if n.name == 'dynamics').params['result_file'] = \
            self.result_file
        self.procs: Dict[str, subprocess.Popen] = {}
        self.lost: set = set()     # non-essential nodes that died during the run
        self._stop_requested = False

    # ------------------------------------------------------------------ processes
    def _commands(self, params_path: str) -> Dict[str, List[str]]:
        if self.compose:
            spec = [f'{n.name}={n.module}:{n.cls}' for n in self.nodes]
            return {'composed': [sys.executable, '-m', 'adcs_nodes.tools.compose',
                                 '--params-file', params_path, '--nodes', *spec]}
        return {n.name: [sys.executable, '-m', n.module, '--ros-args', '-r',
                         f'__node:={n.name}', '--params-file', params_path]
                for n in self.nodes}

    def _spawn(self, env: Dict[str, str], params_path: str) -> None:
        logs = os.path.join(self.run_dir, 'logs')
        os.makedirs(logs, exist_ok=True)
        for name, cmd in self._commands(params_path).items():
            fh = open(os.path.join(logs, f'{name}.log'), 'w')
            self.procs[name] = subprocess.Popen(cmd, env=env, stdout=fh,
                                                stderr=subprocess.STDOUT,
                                                stdin=subprocess.DEVNULL,
                                                start_new_session=True)

    def _log_tail(self, name: str, lines: int = 15) -> str:
        path = os.path.join(self.run_dir, 'logs', f'{name}.log')
        try:
            with open(path, encoding='utf-8', errors='replace') as fh:
                return ''.join(fh.readlines()[-lines:])
        except OSError:
            return ''

    def _signal_and_wait(self, names: List[str], grace_s: float) -> None:
        """SIGINT the named children, wait up to ``grace_s``, SIGKILL what is left."""
        for name in names:
            proc = self.procs[name]
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + grace_s
        for name in names:
            proc = self.procs[name]
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                self.log(f'[adcs] {name} did not stop within {grace_s:g} s: killing it')
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait()

    def _stop_all(self, monitor: Optional['_Monitor'] = None, grace_s: float = 10.0) -> None:
        """Stop every child: the graph first, then the recorder once it has written
        everything that was published (its message count stops growing), so an
        interrupted run loses no recorded data."""
        others = [n for n in self.procs if n != 'recorder']
        self._signal_and_wait(others, grace_s)
        if 'recorder' in self.procs:
            if monitor is not None and self.procs['recorder'].poll() is None:
                deadline = time.monotonic() + grace_s
                last = -1
                while monitor.recorder_count != last and time.monotonic() < deadline:
                    last = monitor.recorder_count
                    monitor.spin(0.3)
            self._signal_and_wait(['recorder'], grace_s)

    # ------------------------------------------------------------------ run
    def run(self) -> RunResult:
        """Run the scenario to its end (or Ctrl-C / a failed node); returns the outcome."""
        from adcs_nodes.nodes.lockstep_node import epoch_to_ns, parse_epoch

        os.makedirs(self.run_dir, exist_ok=True)
        params_path = os.path.join(self.run_dir, 'params.yaml')
        with open(params_path, 'w') as fh:
            fh.write(params_file_text(self.nodes))
        domain, lock = acquire_domain()
        env = child_env(domain)
        os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE',
                                               'FASTDDS_BUILTIN_TRANSPORTS')})
        manifest = {'pid': os.getpid(), 'domain': domain, 'scenario': self.sc['_path'],
                    'epoch': self.sc['epoch'],
                    'bag': self.record, 'run_dir': self.run_dir, 'compose': self.compose}
        os.makedirs(RUNS_DIR, exist_ok=True)
        manifest_path = os.path.join(RUNS_DIR, f'active-{os.getpid()}.json')
        with open(manifest_path, 'w') as fh:
            json.dump(manifest, fh)
        epoch_ns = epoch_to_ns(parse_epoch(self.sc['epoch']))
        monitor = _Monitor(epoch_ns)
        old_int = signal.signal(signal.SIGINT, self._on_signal)
        old_term = signal.signal(signal.SIGTERM, self._on_signal)
        self.log(f'[adcs] run {self.sc["name"]}: {len(self.nodes)} nodes '
                 f'({"composed in one process" if self.compose else "one process each"}), '
                 f'ROS_DOMAIN_ID={domain}, logs in {self.run_dir}/logs')
        t0 = time.monotonic()
        code, message = 0, ''
        try:
            self._spawn(env, params_path)
            manifest['pids'] = {name: proc.pid for name, proc in self.procs.items()}
            with open(manifest_path, 'w') as fh:
                json.dump(manifest, fh)
            code, message = self._watch(monitor, t0)
        finally:
            self._stop_all(monitor)
            if self.progress:
                sys.stderr.write('\n')
            wall = time.monotonic() - t0
            sim_s = monitor.sim_ns / 1e9
            frames = int(round(sim_s / self.sc['timing']['frame_s']))
            missed = monitor.missed_frames
            fps = self._master_fps()
            monitor.close()
            signal.signal(signal.SIGINT, old_int)
            signal.signal(signal.SIGTERM, old_term)
            os.unlink(manifest_path)
            lock.close()
            self._save_scenario()
        return RunResult(code, sim_s, wall, frames, missed, self.record, self.run_dir, message,
                         fps)

    def _master_fps(self) -> float:
        """Lockstep frames/s measured by the clock master (its result file), 0 if none."""
        try:
            with open(self.result_file) as fh:
                return float(json.load(fh)['frames_per_s'])
        except (OSError, ValueError, KeyError):
            return 0.0

    def _save_scenario(self) -> None:
        """Store the effective scenario (defaults filled in) beside the bag's files.

        ``<bag>/scenario.yaml`` lets ``adcs report`` pick the paper comparison and lets a
        campaign check what each run really used; rosbag2 readers ignore the extra file.
        """
        if not self.record or not os.path.isdir(self.record):
            return
        sc = {k: v for k, v in self.sc.items() if not k.startswith('_')}
        sc['duration_s'] = self.duration_s
        with open(os.path.join(self.record, 'scenario.yaml'), 'w') as fh:
            fh.write(f'# effective scenario of this bag (from {self.sc.get("_path", "?")})\n')
            yaml.safe_dump(sc, fh, sort_keys=False)

    def _on_signal(self, signum, frame) -> None:
        self._stop_requested = True

    def _master_name(self) -> str:
        return 'composed' if self.compose else 'dynamics'

    def _watch(self, monitor: _Monitor, t0: float):
        total_ns = int(round(self.duration_s * 1e9))
        last_print = 0.0
        master = self._master_name()
        while True:
            monitor.spin(0.1)
            now = time.monotonic()
            if self.progress and now - last_print > 0.5:
                last_print = now
                self._print_progress(monitor, now - t0, total_ns)
            if self._stop_requested:
                return 130, ('interrupted (Ctrl-C): nodes stopped'
                             + (', bag closed' if self.record else ''))
            for name, proc in self.procs.items():
                rc = proc.poll()
                if rc is None or name in self.lost:
                    continue
                if name == master and rc == 0:
                    return self._finish(monitor, total_ns)
                tail = self._log_tail(name)
                if name not in ESSENTIAL and rc != 2:
                    # flight software died (a crash, a kill): the graph goes on without it;
                    # its consumers time out and fall back (manager -> safe controller)
                    self.lost.add(name)
                    self.log(f'[adcs] WARNING: node {name} exited with code {rc}; the graph '
                             f'goes on without it (log: {self.run_dir}/logs/{name}.log)')
                    continue
                return 1, (f'node {name} exited with code {rc} before the end of the run; '
                           f'last lines of its log ({self.run_dir}/logs/{name}.log):\n{tail}')

    def _finish(self, monitor: _Monitor, total_ns: int):
        monitor.sim_ns = max(monitor.sim_ns, total_ns)
        if self.record and not self.compose:
            deadline = time.monotonic() + 15.0
            while monitor.recorder_clock_ns < total_ns and time.monotonic() < deadline:
                if self.procs['recorder'].poll() is not None:
                    break
                monitor.spin(0.1)
            # every node has done its last frame (the master waited for them): the recorder
            # has everything once its message count stops growing
            last = -1
            while monitor.recorder_count != last and time.monotonic() < deadline:
                last = monitor.recorder_count
                monitor.spin(0.3)
            if monitor.recorder_clock_ns < total_ns:
                return 1, ('recorder did not receive the final frame within 15 s: '
                           'the bag may miss the end of the run')
        return 0, 'done'

    def _print_progress(self, monitor: _Monitor, wall: float, total_ns: int) -> None:
        frac = min(1.0, monitor.sim_ns / total_ns) if total_ns else 0.0
        sim_s = monitor.sim_ns / 1e9
        rtf = sim_s / wall if wall > 0 else 0.0
        width = 30
        bar = '#' * int(frac * width) + '.' * (width - int(frac * width))
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
