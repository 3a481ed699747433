"""Real-time mode gives lockstep's results within the noise of its timing (issue 23):
``adcs run --real-time --rate 20`` (every sensor input in sample timing, the world paced by
the wall clock) against the plain engine's lockstep run of the same scenario:

* paper000_estimation: the estimator uses at least 95 % of the magnetometer's samples (its
  run summary) and its median error over T/2..T is within 0.3 deg of the lockstep run's;
* paper003_slew: it settles (5 % band of the initial eigenangle) within 10 % of the lockstep
  time.

``long`` (make test-long): a 5 min and two short real-time runs, and they depend on the
machine keeping the pace. paper000_estimation at rate 20 (one process per node, load 12-15):
592 of 592 samples, median 0.71 deg against 0.70. paper003_slew (0.1 s frames, 2026-12-02):
at rate 1, one process per node, beside a soak (load about 8): settled in 29.2 s against
26.8 s, exit 0; at rate 20 composed (near idle) 29.3 s, with 0-2 frames now and then
degraded (a command or a sample after its 5 ms frame: exit 3). One process per node keeps
about 3.7 x real time there, not 20 x. The estimate is judged against the truth interpolated
at its stamp (:func:`adcs_nodes.tools.analyse.metrics.estimate_errors_deg`).
"""
import os
import re

import numpy as np
import pytest

from adcs_launch import SCENARIOS, adcs
from adcs_nodes.bag import header_stamp_ns, read_messages
from adcs_nodes.tools.analyse.metrics import estimate_errors_deg
from adcs_nodes.tools.analyse.papers import rows_for_bag

pytestmark = pytest.mark.long


def _q(m):
    return [m.q_orbit_body.x, m.q_orbit_body.y, m.q_orbit_body.z, m.q_orbit_body.w]


def _median_error(bag, t_from):
    truth, est = [], []
    for topic, _, m in read_messages(bag, ['/sim/state', '/adcs/attitude_estimate']):
        (truth if topic == '/sim/state' else est).append((header_stamp_ns(m), _q(m)))
    truth.sort()
    est.sort()
    t0 = truth[0][0]
    out = estimate_errors_deg([(t - t0) / 1e9 for t, _ in truth], [q for _, q in truth],
                              [(t - t0) / 1e9 for t, _ in est], [q for _, q in est])
    return float(np.median(out['deg'][out['t'] >= t_from]))


def test_paper000_estimation_in_real_time_matches_lockstep(tmp_path):
    sc = os.path.join(SCENARIOS, 'paper000_estimation.yaml')
    rt, lock = str(tmp_path / 'rt'), str(tmp_path / 'lock')
    out = adcs('run', sc, '--real-time', '--rate', '20', '--record', rt, '--quiet',
               timeout=1200).stdout
    adcs('run', sc, '--engine', 'plain', '--record', lock, '--quiet', timeout=600)
    used = int(re.search(r'estimator: samples used /sensors/magnetometer (\d+)', out).group(1))
    produced = sum(1 for _ in read_messages(lock, ['/sensors/magnetometer']))
    half = 5914.0 / 2
    med, med_lock = _median_error(rt, half), _median_error(lock, half)
    print(f'real time: {used} of {produced} samples used, median {med:.3f} deg (lockstep '
          f'{med_lock:.3f})')
    assert used >= 0.95 * produced
    assert abs(med - med_lock) <= 0.3


@pytest.mark.parametrize('rate,engine', [('1', 'graph'), ('20', 'composed')])
def test_paper003_slew_in_real_time_settles_as_in_lockstep(tmp_path, rate, engine):
    """At rate 20 the 0.1 s frames are 200 a second: one process per node keeps about 60 a
    second on 2 cores (it fell behind to 3.7 x real time), all nodes in one process keep it."""
    sc = os.path.join(SCENARIOS, 'paper003_slew.yaml')
    rt, lock = str(tmp_path / 'rt'), str(tmp_path / 'lock')
    run = adcs('run', sc, '--real-time', '--rate', rate, '--engine', engine, '--record', rt,
               '--quiet', timeout=1200, check=False)
    out = run.stdout + run.stderr
    # at rate 20 a frame is 5 ms of wall time: now and then a command or a sample comes after
    # its frame (the run says DEGRADED, exit 3: frames without a command, or an estimator
    # starved for a frame or two); at most 1 % of the 800 frames each
    counts = [int(n) for n in re.findall(r'(?:in|for) (\d+) (?:of its )?frames', out)]
    assert run.returncode == 0 or (run.returncode == 3 and counts and max(counts) <= 8), out
    adcs('run', sc, '--engine', 'plain', '--record', lock, '--quiet', timeout=600)
    t_rt, t_lock = _settling(rt), _settling(lock)
    print(f'settling at rate {rate} ({engine}): real time {t_rt} s, lockstep {t_lock} s')
    assert t_rt is not None and abs(t_rt - t_lock) <= 0.1 * t_lock
    used = re.search(r'estimator: samples used /sensors/horizon (\d+)', out)
    assert used and int(used.group(1)) >= 0.95 * 800, out      # 80 s of 0.1 s samples


def _settling(bag):
    """Settling time [s] of paper 003's table for a bag (the row adcs report prints)."""
    _, rows = rows_for_bag(bag)
    text = next(measured for name, _, measured, _ in rows if name.startswith('settling time'))
    m = re.match(r'([0-9.]+) s', str(text))
    return float(m.group(1)) if m else None
