"""``adcs fault``: one fault injected into a running composed graph (paper 000's closed loop,
magnetometer-only filter): it is announced on ``sim/faults`` like a scenario's, the
magnetometer's samples are NaN for its duration, the estimator refuses each of them (its
diagnostics count and say why), no NaN reaches an actuator; a fault the run cannot take is
refused with the reason (exit 2) before anything is sent.

Live injection is not deterministic (the frame it starts in depends on wall time), so the
checks are relative to the announced time.
"""
import math
import os
import re
import signal
import time

import numpy as np
import yaml

from adcs_launch import SCENARIOS, adcs, start_adcs, wait_manifest
from adcs_nodes.bag import header_stamp_ns, read_messages
from adcs_nodes.tools.run import live

EPOCH_NS = 1767225600 * 10**9          # paper000_control's epoch


def _scenario(tmp_path):
    """paper000_control, recording what the test reads."""
    with open(os.path.join(SCENARIOS, 'paper000_control.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['record'] = {'topics': ['/clock', 'sim/faults', 'sensors/magnetometer',
                               'adcs/estimator/diagnostics', 'adcs/actuator_command']}
    path = tmp_path / 'live.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


def _t(msg):
    return (header_stamp_ns(msg) - EPOCH_NS) / 1e9


def _faults(bag):
    """(t, message) of every sim/faults status in the bag (a bag being written reads too)."""
    try:
        return [(_t(m), s.message) for _, _, m in read_messages(bag, ['/sim/faults'])
                for s in m.status]
    except (FileNotFoundError, ValueError):       # not created yet
        return []


def test_a_live_magnetometer_nan_is_announced_and_refused_by_the_estimator(tmp_path):
    bag = str(tmp_path / 'live')
    # paced (at most 100 x real time): open-ended, it leaves the CPU to the fault clients
    proc = start_adcs('run', _scenario(tmp_path), '--compose', '--record', bag,
                      '--duration', '2000000', '--quiet', '--rate', '100')
    try:
        wait_manifest(proc)
        pid = str(proc.pid)
        bad = adcs('fault', 'nan', 'magnetometr', '--run', pid, check=False)
        assert bad.returncode == 2 and "cannot strike 'magnetometr'" in bad.stderr
        assert 'magnetometer' in bad.stderr
        bad = adcs('fault', 'nan', 'magnetometer', '--param', 'duration_s=-5', '--run', pid,
                   check=False)
        assert bad.returncode == 2 and 'duration_s' in bad.stderr
        out = adcs('fault', 'nan', 'magnetometer', '--param', 'duration_s=100', '--run',
                   pid).stdout
        m = re.search(r'announced on sim/faults at t = ([0-9.]+) s: active: nan magnetometer',
                      out)
        assert m, out
        t_fault = float(m.group(1))
        assert 'not deterministic' in out
        # a valid future time: the command returns once the fault is scheduled, with its
        # time (200 s of wall time ahead at the pace: it strikes after this test)
        t0 = time.monotonic()
        out = adcs('fault', 'dropout', 'magnetometer', '--at', f'{t_fault + 20000:g}',
                   '--run', pid).stdout
        assert time.monotonic() - t0 < live.ANNOUNCE_WAIT_S, out
        assert f'scheduled from t = {t_fault + 20000:g} s' in out, out
        # the run goes on past the fault's end: its end is in the bag being written
        deadline = time.monotonic() + 60.0
        while not any('cleared' in msg for _, msg in _faults(bag)):
            assert time.monotonic() < deadline, 'the fault did not end in the bag'
            time.sleep(0.5)
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=90)
    assert proc.returncode == 130, out + err
    assert _faults(bag) == [(t_fault, 'active: nan magnetometer'),
                            (t_fault + 100.0, 'cleared: nan magnetometer')]
    nan = [_t(m) for _, _, m in read_messages(bag, ['/sensors/magnetometer'])
           if not math.isfinite(m.magnetic_field.x)]
    assert nan and min(nan) >= t_fault and max(nan) < t_fault + 100.0
    assert len(nan) == 10                            # a 10 s magnetometer over 100 s
    diag = [(_t(m), m.rejected_count, m.last_rejection)
            for _, _, m in read_messages(bag, ['/adcs/estimator/diagnostics'])]
    before = [n for t, n, _ in diag if t < t_fault]
    after = [(n, why) for t, n, why in diag if t >= t_fault + 100.0]
    assert before and after and after[0][0] - before[-1] == len(nan)
    assert 'magnetometer sample is not finite' in after[0][1]
    for _, _, m in read_messages(bag, ['/adcs/actuator_command']):
        assert np.all(np.isfinite([m.dipole_body.x, m.dipole_body.y, m.dipole_body.z]))


def test_what_a_receiver_makes_of_a_live_fault():
    """sim_node.faults.injected: the same registry checks as a scenario's fault, another
    sensor's fault ignored, the start never before the receiver's next frame; the dynamics
    announces an added fault like a scripted one (no process)."""
    import json as _json

    import pytest

    from sim_node.faults import ActuatorFaults, injected

    def text(**kw):
        return _json.dumps({'index': 1001, 'kind': 'nan', 'target': 'magnetometer',
                            'at_s': None, 'params': {'duration_s': 10.0}, **kw})
    f = injected(text(), 5 * 10**9, sensors=['magnetometer'])
    assert (f.kind, f.target) == ('nan', 'magnetometer')
    assert (f.start_ns, f.end_ns) == (5 * 10**9, 15 * 10**9)
    assert injected(text(at_s=8.0), 5 * 10**9, sensors=['magnetometer']).start_ns == 8 * 10**9
    assert injected(text(at_s=2.0), 5 * 10**9, sensors=['magnetometer']).start_ns == 5 * 10**9
    assert injected(text(), 0, sensors=['gyro']) is None            # another sensor's
    assert injected(text(), 0, sensors=None).target == 'magnetometer'   # the dynamics
    with pytest.raises(ValueError, match='duration_s'):
        injected(text(params={'duration_s': -1.0}), 0, sensors=['magnetometer'])
    with pytest.raises(ValueError, match='unknown fault'):
        injected(text(kind='melt'), 0, sensors=['magnetometer'])
    with pytest.raises(ValueError, match='cannot strike'):
        injected(text(kind='wheel_stuck', target='wheel_q'), 0, wheels=['wheel_x'])
    with pytest.raises(ValueError, match='not JSON'):
        injected('{', 0)
    faults = ActuatorFaults([], ['wheel_x'])
    stuck = injected(text(kind='wheel_stuck', target='wheel_x', params={}), 4 * 10**9,
                     wheels=['wheel_x'])
    faults.add(stuck)
    assert [e['fault'].kind for e in faults.events(4 * 10**9, 10**9)] == ['wheel_stuck']
    _, torque = faults.apply(4 * 10**9, np.zeros(3), np.array([0.01]))
    assert torque[0] == 0.0
