"""The closed-loop graph: run-time switching, unknown names, a killed controller, estimation.

Runs go through the real ``adcs`` command; switches through ``adcs switch`` on the running
graph (a long lockstep run, stopped with Ctrl-C once the checks are done).
"""
import os
import re
import signal
import time

import numpy as np
import pytest
import yaml

from adcs_launch import SCENARIOS, adcs, control_scenario, start_adcs, wait_manifest
from adcs_nodes.core import attitude as att
from adcs_nodes.tools.bag import header_stamp_ns, read_messages, topic_summary

EPOCH_NS = 1767225600 * 10**9


def commands(bag):
    out = []
    for _, _, m in read_messages(bag, ['/adcs/actuator_command']):
        out.append(((header_stamp_ns(m) - EPOCH_NS) / 1e9, m.source,
                    np.array([m.dipole_body.x, m.dipole_body.y, m.dipole_body.z])))
    return out


def running(status_text, sim_s=20.0):
    """True once the controller manager has run past ``sim_s`` (the lockstep is going)."""
    m = re.search(r'sim time: ([0-9.]+) s', status_text)
    return m is not None and float(m.group(1)) >= sim_s


def sim_time(status_text):
    """Sim time [s] an ``adcs status`` text reports."""
    return float(re.search(r'sim time: ([0-9.]+) s', status_text).group(1))


def wait_status(pid, predicate, timeout=120.0):
    """The first ``adcs status`` text that satisfies ``predicate``. One poll takes 3 s of
    listening plus the start of a Python process with rclpy (10-13 s in all at load 18), so
    the deadline is generous; it costs nothing when the condition comes early."""
    deadline = time.monotonic() + timeout
    out = None
    while time.monotonic() < deadline:
        out = adcs('status', '--run', str(pid), check=False)
        if out.returncode == 0 and predicate(out.stdout):
            return out.stdout
        time.sleep(0.5)
    raise AssertionError(f'status condition not reached; last: {out.stdout} {out.stderr}')


def wait_log_stamp(run_dir, name, text, after, timeout=60.0):
    """Wall-clock stamp [s since the epoch] of the first line of node ``name``'s log that
    holds ``text`` and is stamped after ``after`` (ROS log format ``[LEVEL] [stamp] [node]:
    message``)."""
    path = os.path.join(run_dir, 'logs', f'{name}.log')
    pattern = re.compile(r'^\[\w+\] \[(\d+\.\d+)\] \[' + re.escape(name) + r'\]: .*'
                         + re.escape(text), re.M)
    deadline = time.monotonic() + timeout
    while True:
        with open(path) as fh:
            stamps = [float(m.group(1)) for m in pattern.finditer(fh.read())]
        stamps = [t for t in stamps if t > after]
        if stamps:
            return stamps[0]
        if time.monotonic() > deadline:
            raise AssertionError(f'no {text!r} in {path} within {timeout} s')
        time.sleep(0.1)


def test_switch_mid_run_gives_one_zero_frame_each_and_unknown_is_refused(tmp_path):
    bag = str(tmp_path / 'switching')
    proc = start_adcs('run', control_scenario(tmp_path), '--record', bag,
                      '--duration', '200000', '--quiet')
    try:
        wait_manifest(proc)
        wait_status(proc.pid, lambda s: 'controller: magnetic' in s and running(s))
        bad = adcs('switch', 'no_such_law', '--run', str(proc.pid), check=False)
        assert bad.returncode == 2
        assert "unknown controller 'no_such_law'" in bad.stderr and 'magnetic' in bad.stderr
        assert 'switch magnetic -> bdot' in adcs('switch', 'bdot', '--run', str(proc.pid)).stdout
        status = wait_status(proc.pid, lambda s: 'controller: bdot' in s and 'switches: 1' in s)
        wait_status(proc.pid, lambda s: running(s, sim_time(status) + 10.0))   # 5 bdot frames
        back = adcs('switch', 'magnetic', '--run', str(proc.pid)).stdout
        assert 'switch bdot -> magnetic' in back
        status = wait_status(proc.pid,
                             lambda s: 'controller: magnetic' in s and 'switches: 2' in s)
        wait_status(proc.pid, lambda s: running(s, sim_time(status) + 10.0))
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, out + err
    cmds = commands(bag)
    sources = [s for _, s, _ in cmds]
    # runs of sources: magnetic..., zero, bdot..., zero, magnetic...
    runs = [sources[0]] + [s for a, s in zip(sources, sources[1:]) if s != a]
    assert runs == ['magnetic', 'zero', 'bdot', 'zero', 'magnetic'], runs
    zero_idx = [i for i, s in enumerate(sources) if s == 'zero']
    assert len(zero_idx) == 2                                  # exactly one frame each
    for i in zero_idx:
        assert np.all(cmds[i][2] == 0.0)
    # every command is stamped on the 2 s control grid, none missing
    times = [t for t, _, _ in cmds]
    assert np.allclose(np.diff(times), 2.0)
    status = [m for _, _, m in read_messages(bag, ['/adcs/controller_status'])]
    assert status[-1].switch_count == 2 and status[-1].active == 'magnetic'


def test_killed_controller_falls_back_to_bdot_and_the_graph_goes_on(tmp_path):
    bag = str(tmp_path / 'killed')
    proc = start_adcs('run', control_scenario(tmp_path), '--record', bag,
                      '--duration', '200000', '--quiet')
    try:
        manifest = wait_manifest(proc)
        wait_status(proc.pid, lambda s: 'controller: magnetic' in s and running(s))
        t_kill = time.time()
        os.kill(manifest['pids']['magnetic_controller'], signal.SIGKILL)
        status = wait_status(proc.pid, lambda s: 'fallback to bdot' in s)
        # the manager fell back within a few input timeouts (3 x 1 s) of wall time after the
        # kill: the wall-clock stamp of its log line, not when a status poll saw it (one
        # poll took 12 s at load 18, and the next one would have come after the old 15 s)
        fallback_wall = wait_log_stamp(manifest['run_dir'], 'controller_manager',
                                       'fallback to bdot', after=t_kill)
        assert fallback_wall - t_kill < 15.0, fallback_wall - t_kill
        t_fallback = sim_time(status)
        # the graph keeps running on the fallback: 20 more sim seconds
        wait_status(proc.pid, lambda s: running(s, t_fallback + 20.0), timeout=120.0)
        assert proc.poll() is None, 'the run stopped when a controller died'
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, out + err
    assert 'magnetic_controller exited with code -9' in out + err
    assert 'stale' in status or 'no command' in status or 'fallback' in status
    cmds = commands(bag)
    sources = [s for _, s, _ in cmds]
    assert sources[0] == 'magnetic' and sources[-1] == 'bdot'
    after = sources[sources.index('bdot'):]
    assert len(after) > 5 and set(after) == {'bdot'}            # fallback holds
    summary = topic_summary(bag)         # the bag is valid (stopped by Ctrl-C: the topics may
    assert summary['/sim/state'][1] > 10  # end a few frames apart, as the recorder's lag)


def test_estimator_converges_in_the_launched_graph(tmp_path):
    """paper000_estimation shortened: below 2 deg after 1200 s (paper: within T/2)."""
    bag = str(tmp_path / 'estimation')
    adcs('run', os.path.join(SCENARIOS, 'paper000_estimation.yaml'), '--duration', '1600',
         '--record', bag, '--quiet')
    truth = {header_stamp_ns(m): m for _, _, m in read_messages(bag, ['/sim/state'])}
    errors = []
    stamps = []
    for _, _, m in read_messages(bag, ['/adcs/attitude_estimate']):
        t = header_stamp_ns(m)
        s = truth[t]
        q_est = [m.q_orbit_body.x, m.q_orbit_body.y, m.q_orbit_body.z, m.q_orbit_body.w]
        q_true = [s.q_orbit_body.x, s.q_orbit_body.y, s.q_orbit_body.z, s.q_orbit_body.w]
        errors.append(np.degrees(att.angle_between(q_est, q_true)))
        stamps.append((t - EPOCH_NS) / 1e9)
    expected = list(np.arange(0.0, 1600.1, 2.0))                   # one estimate per 2 s
    assert len(stamps) == len(expected), (len(stamps), stamps[:3], stamps[-3:])
    assert np.allclose(stamps, expected)
    errors = np.array(errors)
    late = errors[np.array(stamps) >= 1200.0]
    assert errors[0] > 30.0                                       # started far off
    assert late.max() < 2.0, f'max error after 1200 s: {late.max():.2f} deg'
    diag = [m for _, _, m in read_messages(bag, ['/adcs/estimator/diagnostics'])]
    assert diag[-1].update_count == 161 and diag[-1].rejected_count == 0


def test_paper004_yaw_reproduction_in_the_launched_graph(tmp_path):
    """Formula (3) vs TRIAD over one orbit; independent truth: the digest's numbers for
    i = 82 deg, 5 % on a_x (alg. (3) 3.07 / 0.94 deg max / RMS, TRIAD 2.83 / 0.92 deg)."""
    from adcs_nodes.tools.reproductions import expectations_for, yaw_errors_paper004
    bag = str(tmp_path / 'paper004')
    adcs('run', os.path.join(SCENARIOS, 'paper004_yaw.yaml'), '--record', bag, '--quiet')
    name, rows = expectations_for(bag)
    assert name == 'paper004_yaw' and all(ok for *_, ok in rows if ok is not None), rows
    sc = yaml.safe_load(open(os.path.join(bag, 'scenario.yaml')))
    e = yaw_errors_paper004(bag, sc)
    rms3 = float(np.sqrt(np.mean(e['eq3_deg'] ** 2)))
    rmst = float(np.sqrt(np.mean(e['triad_deg'] ** 2)))
    assert abs(rms3 - 0.94) < 0.1 and abs(rmst - 0.92) < 0.1
    # the estimator node's own yaw output equals formula (3) on the same samples
    est = {header_stamp_ns(m): m for _, _, m in read_messages(bag, ['/adcs/attitude_estimate'])}
    truth = {header_stamp_ns(m): m for _, _, m in read_messages(bag, ['/sim/state'])}
    for t_s, err in zip(e['t_s'][:50], e['eq3_deg'][:50]):
        k = EPOCH_NS + int(round(t_s * 1e9))
        q_est = est[k].q_orbit_body
        q_true = truth[k].q_orbit_body
        yaw_est = att.to_euler_321([q_est.x, q_est.y, q_est.z, q_est.w])[2]
        yaw_true = att.to_euler_321([q_true.x, q_true.y, q_true.z, q_true.w])[2]
        assert np.degrees(yaw_est - yaw_true) == pytest.approx(err, abs=1e-9)


def test_scheduled_switch_happens_at_the_exact_sim_time(tmp_path):
    """manager.schedule from the scenario: magnetic until 20 s, zero at 20 s, bdot after."""
    bag = str(tmp_path / 'scheduled')
    path = control_scenario(tmp_path)
    with open(path) as fh:
        sc = yaml.safe_load(fh)
    sc['manager']['schedule'] = [{'t_s': 20.0, 'controller': 'bdot'}]
    with open(path, 'w') as fh:
        yaml.safe_dump(sc, fh)
    adcs('run', path, '--record', bag, '--duration', '40', '--quiet')
    cmds = commands(bag)
    assert [t for t, _, _ in cmds] == [float(t) for t in range(0, 41, 2)]
    by_t = {t: s for t, s, _ in cmds}
    assert all(by_t[t] == 'magnetic' for t in range(0, 20, 2))
    assert by_t[20.0] == 'zero'
    assert all(by_t[t] == 'bdot' for t in range(22, 41, 2))


def test_automatic_sequence_detumble_then_acquire(tmp_path):
    """manager.auto: B-dot until the estimated rate is below the threshold for 3 frames."""
    bag = str(tmp_path / 'auto')
    path = control_scenario(tmp_path)
    with open(path) as fh:
        sc = yaml.safe_load(fh)
    sc['manager'] = {'safe': 'bdot', 'auto': {
        'detumble': 'bdot', 'acquire': 'magnetic', 'rate_enter_deg_s': 8.0,
        'rate_exit_deg_s': 30.0, 'confirm_frames': 3}}
    with open(path, 'w') as fh:
        yaml.safe_dump(sc, fh)
    adcs('run', path, '--record', bag, '--duration', '60', '--quiet')
    sources = [s for _, s, _ in commands(bag)]
    runs = [sources[0]] + [s for a, s in zip(sources, sources[1:]) if s != a]
    assert runs == ['bdot', 'zero', 'magnetic'], runs
    assert sources.count('zero') == 1
    status = [m for _, _, m in read_messages(bag, ['/adcs/controller_status'])]
    assert status[-1].mode == 'acquire' and status[-1].active == 'magnetic'
