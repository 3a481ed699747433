"""An ``external: true`` magnetometer fed by a driver process of the test's own (issue 23):
``tests/graph/mag_driver.py``, written as a driver author writes one (its own node and QoS,
samples every 7.3 s off the 2 s frame grid, +-20 ms stamp jitter, 5 % lost, paper 000's
noise, bias and misalignment, values from the true field it reads as hardware). The run is
``adcs run --real-time`` with paper000_estimation's own estimator; the driver joins with the
environment the launcher prints.

* make test: the contract, short (best effort, composed): frame 0 waits for the driver, the
  samples are used (the run summary counts them), estimates on the frame grid (160 s at rate
  20); and a driver that matches but never publishes: the run exits 3 naming the topic.
* make test-long (``long``): the accuracy against the lockstep run of the same scenario (the
  simulated magnetometer, plain engine) over 1500-3000 s: median within 0.2 deg, 95th
  percentile within 0.5 deg, no error above 3 deg once converged; best effort (one process
  per node, beside two CPU burners) and reliable (composed).

The estimate is judged against the recorded truth interpolated at its stamp
(:func:`adcs_nodes.tools.analyse.metrics.estimate_errors_deg`). Waits are deadlines, never sleeps.
"""
import multiprocessing
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import yaml

from adcs_launch import ROOT, RUNS, SCENARIOS, adcs
from adcs_nodes.bag import header_stamp_ns, read_messages
from adcs_nodes.tools.analyse.metrics import estimate_errors_deg

DRIVER = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'mag_driver.py')
TOPIC = '/sensors/magnetometer'
EPOCH_NS = 1767225600 * 10**9          # paper000_estimation's epoch, 2026-01-01T00:00:00Z


def _scenario(tmp_path, name, duration, external=True):
    with open(os.path.join(SCENARIOS, 'paper000_estimation.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['name'] = name
    sc['duration_s'] = float(duration)
    if external:
        sc['sensors']['magnetometer']['external'] = True
    sc['record'] = {'topics': ['sim/state', 'adcs/attitude_estimate']}
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


class _Lines:
    """The stdout lines of a process, read by a thread (so a wait has a deadline)."""

    def __init__(self, stream):
        self.lines, self._q = [], queue.Queue()
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream):
        for line in stream:
            self._q.put(line)
        self._q.put(None)

    def _lines(self, timeout):
        """The lines read within ``timeout`` s, each kept in ``self.lines``, until the stream
        ends."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self._q.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                return
            if line is None:
                return
            self.lines.append(line)
            yield line

    def wait_for(self, text, timeout):
        for line in self._lines(timeout):
            if text in line:
                return line
        raise AssertionError(f'no line with {text!r} within {timeout} s:\n' + ''.join(self.lines))

    def rest(self, timeout=30.0):
        for _ in self._lines(timeout):
            pass
        return ''.join(self.lines)


def _start_run(scenario, *args):
    proc = subprocess.Popen([sys.executable, '-m', 'adcs_nodes.tools.cli', 'run', scenario,
                             '--quiet', *args], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    return proc, _Lines(proc.stdout)


def _driver_env(lines):
    """The environment the launcher prints for a driver (what a user copies)."""
    line = lines.wait_for('a driver joins with: ', 180.0)
    pairs = line.split('a driver joins with: ', 1)[1].split()
    env = dict(p.split('=', 1) for p in pairs)
    assert env.get('ROS_DOMAIN_ID', '').isdigit(), line
    return {**os.environ, **env}


def _start_driver(env, tmp_path, *args):
    log = str(tmp_path / 'driver_samples.txt')
    out = open(tmp_path / 'driver.out', 'w')
    proc = subprocess.Popen([sys.executable, DRIVER, '--log', log, *args], cwd=ROOT, env=env,
                            stdout=out, stderr=subprocess.STDOUT)
    return proc, log


def _stop(proc, timeout=20.0):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _sent(log):
    """Driver log: stamps [ns] of the published samples and the number dropped."""
    with open(log) as fh:
        rows = [ln.split() for ln in fh if ln.strip()]
    return [int(r[0]) for r in rows if r[1] == 'published'], sum(
        1 for r in rows if r[1] == 'dropped')


def _used(out, node='estimator'):
    m = re.search(rf'\[adcs\] {node}: samples used {re.escape(TOPIC)} (\d+); rejected ([^;]*);'
                  r' superseded (\d+); filter resets (\d+)', out)
    assert m, f'no run summary line for {node}:\n{out}'
    return int(m.group(1)), m.group(2), int(m.group(3)), int(m.group(4))


def _q(m):
    return [m.q_orbit_body.x, m.q_orbit_body.y, m.q_orbit_body.z, m.q_orbit_body.w]


def _series(bag):
    truth, est = [], []
    for topic, _, m in read_messages(bag, ['/sim/state', '/adcs/attitude_estimate']):
        (truth if topic == '/sim/state' else est).append((header_stamp_ns(m), _q(m)))
    truth.sort()
    est.sort()
    return truth, est


def _errors(bag):
    truth, est = _series(bag)
    t0 = truth[0][0]
    out = estimate_errors_deg([(t - t0) / 1e9 for t, _ in truth], [q for _, q in truth],
                              [(t - t0) / 1e9 for t, _ in est], [q for _, q in est])
    return out['t'], out['deg']


def _run_with_driver(tmp_path, name, duration, rate, qos, compose, burners=0):
    scenario = _scenario(tmp_path, name, duration)
    bag = str(tmp_path / f'{name}_bag')
    hogs = [multiprocessing.Process(target=_burn, args=(duration / rate + 600.0,))
            for _ in range(burners)]
    for h in hogs:
        h.start()
    run, lines = _start_run(scenario, '--real-time', '--rate', str(rate), '--record', bag,
                            *(['--compose'] if compose else []))
    driver = None
    try:
        driver, log = _start_driver(_driver_env(lines), tmp_path, '--qos', qos)
        rc = run.wait(timeout=duration / rate + 400.0)
        out = lines.rest()
    finally:
        for p in (run, driver):
            if p is not None:
                _stop(p)
        for h in hogs:
            h.terminate()
            h.join()
    return rc, out, bag, log


def _burn(seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass


def test_a_best_effort_driver_off_the_grid_feeds_the_scenario_estimator(tmp_path):
    """The contract, short: every sample the driver sent reaches the filter at its own
    stamp (the run summary counts them; a late one would be rejected and counted, never
    used) and estimates stay on the frame grid."""
    duration, rate = 160.0, 20.0
    rc, out, bag, log = _run_with_driver(tmp_path, 'ext_contract', duration, rate,
                                         'best_effort', compose=True)
    assert rc == 0, out
    sent, dropped = _sent(log)
    epoch = EPOCH_NS
    # a sample is counted (used or rejected) only if it arrives before the run's last frame:
    # the driver publishes a sample once the truth frame after its stamp has reached it, and
    # beside a CPU burner and the other test worker that can take more than 6 s of sim time
    # (300 ms of wall time) for the last one (the likely cause of CI runs 40 and 41: 19 of 20
    # counted, none refused; not reproduced in 12 runs beside a burner);
    # so every sample stamped at least 10 s (500 ms of wall time) before the end is counted,
    # the later ones may be, and none is counted twice
    covered = [s for s in sent if s - epoch <= (duration - 10.0) * 1e9]
    assert len(covered) >= 15, (len(sent), dropped)
    used, rejected, superseded, resets = _used(out)
    # best effort on loopback, 2 s of sim time = 100 ms of wall time to arrive: under load
    # some are late (beside the soak's 2 burners, load 10-15: 3 of 20), each rejected and
    # counted, never used; one delayed by more than max_sample_age_s (5 s of sim time, 250
    # ms of wall time at rate 20) is refused as too old (1 of 20 in a CI run beside a
    # burner); none is used twice, none superseded, none lost unaccounted
    late = {k: int(v) for k, v in re.findall(r'(\w+) (\d+)', rejected)}
    assert set(late) <= {'late', 'too_old'}, rejected
    counted = used + sum(late.values())
    assert len(covered) <= counted <= len(sent), (used, len(covered), len(sent), rejected)
    assert used >= 0.75 * len(covered), (used, len(covered), rejected)
    assert superseded == 0 and resets == 0
    _, est = _series(bag)
    assert len(est) == int(duration / 2.0) + 1
    assert all((t - epoch) % (2 * 10**9) == 0 for t, _ in est)       # on the 2 s grid
    assert all(np.all(np.isfinite(q)) for _, q in est)


def test_a_driver_that_never_publishes_degrades_the_run_naming_the_topic(tmp_path):
    """Frame 0 waits until the driver's publisher is matched (the estimator says why it is
    not ready); a driver that matches but never publishes starves the estimator: exit 3,
    the reason names the node and the topic (lockstep world, fast)."""
    scenario = _scenario(tmp_path, 'ext_silent', 200.0)
    bag = str(tmp_path / 'silent_bag')
    run, lines = _start_run(scenario, '--compose', '--record', bag)
    driver = None
    try:
        env = _driver_env(lines)
        manifest = os.path.join(RUNS, f'active-{run.pid}.json')
        deadline = time.monotonic() + 180.0
        log_path = None
        while time.monotonic() < deadline and log_path is None:
            if os.path.exists(manifest):
                with open(manifest) as fh:
                    text = fh.read()
                m = re.search(r'"run_dir": "([^"]+)"', text)
                if m:
                    log_path = os.path.join(m.group(1), 'logs', 'composed.log')
            if log_path is None:
                time.sleep(0.05)
        assert log_path, 'no run manifest'
        deadline = time.monotonic() + 180.0
        waiting = ''
        while time.monotonic() < deadline and not waiting:
            if os.path.exists(log_path):
                with open(log_path, errors='replace') as fh:
                    waiting = next((ln for ln in fh if 'waiting for a publisher on '
                                    f'{TOPIC}' in ln), '')
            if not waiting:
                time.sleep(0.05)
        assert waiting, 'the estimator never said what it waits for'
        assert run.poll() is None                      # still waiting, not started
        started = time.time_ns()
        driver, _ = _start_driver(env, tmp_path, '--silent')
        rc = run.wait(timeout=300.0)
        out = lines.rest()
    finally:
        for p in (run, driver):
            if p is not None:
                _stop(p)
    assert rc == 3, out
    assert 'DEGRADED' in out and f'estimator got nothing usable from {TOPIC}' in out, out
    assert '[adcs] estimator: samples used none; rejected none' in out
    # frame 0 came after the driver was started (the clock master's start line, wall time)
    with open(log_path, errors='replace') as fh:
        start = re.search(r'\[INFO\] \[([0-9.]+)\] \[dynamics\]: lockstep start', fh.read())
    assert start and float(start.group(1)) * 1e9 > started


def _accuracy(tmp_path, name, qos, compose, burners):
    duration, rate, window = 3000.0, 20.0, (1500.0, 3000.0)
    rc, out, bag, log = _run_with_driver(tmp_path, name, duration, rate, qos, compose,
                                         burners)
    assert rc == 0, out
    ref_bag = str(tmp_path / 'lockstep_bag')
    adcs('run', _scenario(tmp_path, 'lockstep_ref', duration, external=False), '--engine',
         'plain', '--record', ref_bag, '--quiet', timeout=600)
    t, e = _errors(bag)
    t_ref, e_ref = _errors(ref_bag)
    win, win_ref = (t >= window[0]) & (t <= window[1]), (t_ref >= window[0]) & (
        t_ref <= window[1])
    med, p95 = np.median(e[win]), np.percentile(e[win], 95)
    med_ref, p95_ref = np.median(e_ref[win_ref]), np.percentile(e_ref[win_ref], 95)
    # converged: below 2 deg and staying there for 300 s; no spike over 3 deg after it
    below = e < 2.0
    conv = next(i for i in range(len(t)) if below[i:i + 150].all())
    spike = e[conv:].max()
    used, rejected, superseded, _ = _used(out)
    sent, _ = _sent(log)
    print(f'{name}: median {med:.3f} deg p95 {p95:.3f} deg (lockstep {med_ref:.3f} / '
          f'{p95_ref:.3f}), converged at {t[conv]:.0f} s, max after {spike:.2f} deg, '
          f'used {used} of {len(sent)} sent, rejected {rejected}, superseded {superseded}')
    assert abs(med - med_ref) <= 0.2
    assert abs(p95 - p95_ref) <= 0.5
    assert spike <= 3.0
    assert used >= 0.9 * len(sent)


@pytest.mark.long
def test_best_effort_driver_reaches_lockstep_accuracy_beside_cpu_burners(tmp_path):
    _accuracy(tmp_path, 'ext_best_effort', 'best_effort', compose=False, burners=2)


@pytest.mark.long
def test_reliable_driver_reaches_lockstep_accuracy(tmp_path):
    _accuracy(tmp_path, 'ext_reliable', 'reliable', compose=True, burners=0)
