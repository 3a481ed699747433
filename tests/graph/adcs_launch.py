"""Helpers for tests that launch the graph with the real `adcs` command."""
import glob
import json
import os
import subprocess
import sys
import time

import pytest
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENARIOS = os.path.join(ROOT, 'scenarios')
pytest.importorskip('rclpy')

from adcs_nodes.tools.run.launcher import RUNS_DIR  # noqa: E402

#: The launcher's runs directory (active-run manifests, run directories): ``$ADCS_RUNS_DIR``,
#: which tests/conftest.py sets to a temporary directory of the test run.
RUNS = RUNS_DIR


def phase(what):
    """One line in ``RUNS/test_phases.log``: wall clock, the current test, what was reached
    (where a launched test's wall time goes, read after a slow or failed suite run; the runs
    directory is a temporary one unless ``ADCS_RUNS_DIR`` keeps it)."""
    test = os.environ.get('PYTEST_CURRENT_TEST', '?').split(' ')[0]
    try:
        with open(os.path.join(RUNS, 'test_phases.log'), 'a') as fh:
            fh.write(f'{time.time():.3f} {test} {what}\n')
    except OSError:
        pass


def control_scenario(tmp_path, **changes):
    """paper000_control with a 2 s magnetometer (B-dot needs samples) and a 1 s input timeout,
    plus top-level ``changes``, written to ``tmp_path/control.yaml``; returns its path."""
    with open(os.path.join(SCENARIOS, 'paper000_control.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['sensors']['magnetometer']['period_s'] = 2.0
    sc['timing']['timeout_s'] = 1.0
    for key, value in changes.items():
        sc[key] = value
    path = tmp_path / 'control.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


#: Topics that are not data series: ``/tf``, ``/tf_static`` and ``/diagnostics`` (the plain
#: engine publishes none), ``adcs/security_events`` (the graph's publisher guard) and
#: ``adcs/controller_status`` (on change and once per wall second in a graph).
NOT_DATA = ('/tf', '/tf_static', '/diagnostics', '/adcs/security_events',
            '/adcs/controller_status')


def data_digest(bag):
    """Per data topic with messages: (count, hash of the values in stamp order). A topic the
    recorder subscribed to but no message came on has no connection in a plain bag."""
    from bag_digest import content_digest
    return {t: d for t, d in content_digest(bag).items() if t not in NOT_DATA and d[0] > 0}


def plain_run(scenario_path, duration_s, bag):
    """The plain engine's run of a scenario file with its bag, in this process (what
    ``adcs run --engine plain`` calls, without an interpreter start); the RunResult."""
    from adcs_nodes.scenario import load_scenario
    from adcs_nodes.tools.run.plain import run_plain
    return run_plain(load_scenario(str(scenario_path)), float(duration_s), str(bag),
                     progress=False)


def adcs(*args, timeout=300, check=True):
    """Run ``adcs ARGS`` to completion; returns the CompletedProcess (text output)."""
    phase(f'adcs {args[0]} starts')
    proc = subprocess.run([sys.executable, '-m', 'adcs_nodes.tools.cli', *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)
    phase(f'adcs {args[0]} ended ({proc.returncode})')
    if check and proc.returncode != 0:
        raise AssertionError(f'adcs {" ".join(args)} failed ({proc.returncode}):\n'
                             f'{proc.stdout}\n{proc.stderr}')
    return proc


def graph_and_plain_bags(sc, tmp_path, name, duration_s=2.0):
    """A scenario dict (its ``_`` keys dropped) written as ``name``.yaml and run for
    ``duration_s`` as a launched graph and on the plain engine, both recorded: the two bags."""
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump({k: v for k, v in sc.items() if not k.startswith('_')}))
    graph, plain = str(tmp_path / 'graph'), str(tmp_path / 'plain')
    adcs('run', str(path), '--record', graph, '--duration', f'{duration_s:g}', '--quiet',
         timeout=600)
    adcs('run', str(path), '--engine', 'plain', '--record', plain, '--duration',
         f'{duration_s:g}', '--quiet', timeout=600)
    return graph, plain


def start_adcs(*args):
    """Start ``adcs ARGS`` in the background; returns the Popen."""
    phase(f'adcs {args[0]} launched in the background')
    return subprocess.Popen([sys.executable, '-m', 'adcs_nodes.tools.cli', *args], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_manifest(proc, timeout=120.0):
    """The active-run manifest of launcher ``proc`` once its nodes are spawned (the
    launcher's own start: imports, validation, rclpy; seconds, longer under load)."""
    path = os.path.join(RUNS, f'active-{proc.pid}.json')
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if os.path.exists(path):
            with open(path) as fh:
                try:
                    data = json.load(fh)
                except ValueError:
                    data = {}
            if 'pids' in data:
                phase('manifest')
                return data
        if proc.poll() is not None:
            raise AssertionError(f'launcher exited early: {proc.communicate()}')
        time.sleep(0.05)
    raise AssertionError('no run manifest')


def node_log(run_dir, name):
    with open(os.path.join(run_dir, 'logs', f'{name}.log')) as fh:
        return fh.read()


def latest_run_dir():
    return max(glob.glob(os.path.join(RUNS, '2*')), key=os.path.getmtime)


class StatusWatch:
    """``adcs status --watch --run PID`` read as it goes: one process that stays subscribed
    for the whole test and prints a view every wall second (one ``adcs status`` per poll costs
    a Python start with rclpy plus 3 s of listening). Views are compared with runs of spaces
    collapsed (``controller: bdot``, ``sim time: 12.0 s``)."""

    def __init__(self, pid):
        import queue
        import threading
        self.views = queue.Queue()
        phase('status watch starts')
        self.proc = subprocess.Popen(
            [sys.executable, '-m', 'adcs_nodes.tools.cli', 'status', '--watch', '--run',
             str(pid)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.last = ''
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        block = []
        for line in self.proc.stdout:
            if line.strip():
                block.append(line.rstrip('\n'))
            elif block:
                self.views.put(' '.join(' '.join(block).split()))
                block = []
        if block:
            self.views.put(' '.join(' '.join(block).split()))
        self.views.put(None)                     # the watch ended

    def wait(self, predicate, timeout=120.0):
        """The first new view for which ``predicate(view)`` holds (AssertionError at the
        deadline, or when the watch ends first, with the last view)."""
        import queue
        deadline = time.monotonic() + timeout
        while True:
            try:
                view = self.views.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise AssertionError(f'status condition not reached in {timeout} s; '
                                     f'last view: {self.last}') from None
            if view is None:
                raise AssertionError(f'adcs status --watch ended; last view: {self.last}')
            if not self.last:
                phase(f'status watch: first view: {view[:120]}')
            self.last = view
            if predicate(view):
                phase(f'status watch: condition met: {view[:120]}')
                return view

    def close(self):
        if self.proc.poll() is None:
            self.proc.send_signal(2)             # SIGINT: the watch's Ctrl-C
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
