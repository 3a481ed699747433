"""Behaviour of paper 000's flight software on the FrameLoop (the plain engine: no ROS, no
process): the estimator converging, paper 004's yaw reproduction, the manager's scheduled
switch and its automatic sequence.

These were launched-graph tests (``tests/integration/test_control_graph.py``); the assertions
are theirs, with the same numbers and tolerances. That the graph gives the FrameLoop's series
on every data topic is ``tests/graph/test_engine_parity.py``; operator switches and a killed
controller stay graph tests (``tests/graph/test_control_graph.py``: services, processes).
"""
import sys
import types

import numpy as np
import pytest
import yaml

from adcs_nodes.core import attitude as att
from frameloop_run import by_t, control_scenario, q, raw, run, source_runs, t_s, validated


def test_estimator_converges(tmp_path):
    """paper000_estimation shortened: below 2 deg after 1200 s (paper: within T/2)."""
    out, _ = run(validated(tmp_path, raw('paper000_estimation')), 1600.0)
    truth = by_t(out['sim/state'])
    errors, stamps = [], []
    for m in out['adcs/attitude_estimate']:
        t = round(t_s(m), 6)
        errors.append(np.degrees(att.angle_between(q(m.q_orbit_body),
                                                   q(truth[t].q_orbit_body))))
        stamps.append(t)
    expected = list(np.arange(0.0, 1600.1, 2.0))                   # one estimate per 2 s
    assert len(stamps) == len(expected), (len(stamps), stamps[:3], stamps[-3:])
    assert np.allclose(stamps, expected)
    errors = np.array(errors)
    late = errors[np.array(stamps) >= 1200.0]
    assert errors[0] > 30.0                                       # started far off
    assert late.max() < 2.0, f'max error after 1200 s: {late.max():.2f} deg'
    diag = out['adcs/estimator/diagnostics']
    assert diag[-1].update_count == 161 and diag[-1].rejected_count == 0


@pytest.fixture
def reproductions_without_rclpy(monkeypatch):
    """``tools.reproductions`` reads the epoch with ``nodes.lockstep_node``'s ``parse_epoch``
    and ``epoch_to_ns``, which that module only re-exports from ``components.base``; importing
    it imports rclpy. The unit tier imports no rclpy: the same two functions, from where they
    are defined."""
    from adcs_nodes.components import base
    monkeypatch.setitem(sys.modules, 'adcs_nodes.nodes.lockstep_node', types.SimpleNamespace(
        parse_epoch=base.parse_epoch, epoch_to_ns=base.epoch_to_ns))


def test_paper004_yaw_reproduction(tmp_path, reproductions_without_rclpy):
    """Formula (3) vs TRIAD over one orbit; independent truth: the digest's numbers for
    i = 82 deg, 5 % on a_x (alg. (3) 3.07 / 0.94 deg max / RMS, TRIAD 2.83 / 0.92 deg).

    The bag is the plain engine's (``adcs run --engine plain``), read as a recorded one."""
    from adcs_nodes.bag import header_stamp_ns, read_messages
    from adcs_nodes.tools.analyse.papers import paper004
    from adcs_nodes.tools.analyse.papers.series import from_bag
    from adcs_nodes.tools.analyse.reproductions import expectations_for
    from adcs_nodes.tools.run.plain import run_plain
    bag = str(tmp_path / 'paper004')
    res = run_plain(validated(tmp_path, raw('paper004_yaw')), None, bag, progress=False)
    assert res.exit_code == 0, res.message
    name, rows = expectations_for(bag)
    assert name == 'paper004_yaw' and all(ok for *_, ok in rows if ok is not None), rows
    with open(tmp_path / 'paper004' / 'scenario.yaml') as fh:
        sc = yaml.safe_load(fh)
    e = paper004.yaw_errors(from_bag(bag, paper004.TOPICS), sc)
    rms3 = float(np.sqrt(np.mean(e['eq3_deg'] ** 2)))
    rmst = float(np.sqrt(np.mean(e['triad_deg'] ** 2)))
    assert abs(rms3 - 0.94) < 0.1 and abs(rmst - 0.92) < 0.1
    # the estimator's own yaw output equals formula (3) on the same samples
    est = {header_stamp_ns(m): m for _, _, m in read_messages(bag, ['/adcs/attitude_estimate'])}
    truth = {header_stamp_ns(m): m for _, _, m in read_messages(bag, ['/sim/state'])}
    epoch_ns = 1767225600 * 10**9
    for t, err in zip(e['t_s'][:50], e['eq3_deg'][:50]):
        k = epoch_ns + int(round(t * 1e9))
        yaw_est = att.to_euler_321(q(est[k].q_orbit_body))[2]
        yaw_true = att.to_euler_321(q(truth[k].q_orbit_body))[2]
        assert np.degrees(yaw_est - yaw_true) == pytest.approx(err, abs=1e-9)


def _commands(out):
    return [(t_s(m), m.source, np.array([m.dipole_body.x, m.dipole_body.y, m.dipole_body.z]))
            for m in out['adcs/actuator_command']]


def test_scheduled_switch_happens_at_the_exact_sim_time(tmp_path):
    """manager.schedule from the scenario: magnetic until 20 s, zero at 20 s, bdot after."""
    sc = control_scenario(tmp_path)
    sc['manager']['schedule'] = [{'t_s': 20.0, 'controller': 'bdot'}]
    out, _ = run(validated(tmp_path, sc), 40.0)
    cmds = _commands(out)
    assert [t for t, _, _ in cmds] == [float(t) for t in range(0, 41, 2)]
    by = {t: s for t, s, _ in cmds}
    assert all(by[t] == 'magnetic' for t in range(0, 20, 2))
    assert by[20.0] == 'zero'
    assert all(by[t] == 'bdot' for t in range(22, 41, 2))


def test_automatic_sequence_detumble_then_acquire(tmp_path):
    """manager.auto: B-dot until the estimated rate is below the threshold for 3 frames."""
    sc = control_scenario(tmp_path)
    sc['manager'] = {'safe': 'bdot', 'auto': {
        'detumble': 'bdot', 'acquire': 'magnetic', 'rate_enter_deg_s': 8.0,
        'rate_exit_deg_s': 30.0, 'confirm_frames': 3}}
    out, _ = run(validated(tmp_path, sc), 60.0)
    sources = [s for _, s, _ in _commands(out)]
    assert source_runs(sources) == ['bdot', 'zero', 'magnetic'], sources
    assert sources.count('zero') == 1
    status = out['adcs/controller_status']
    assert status[-1].mode == 'acquire' and status[-1].active == 'magnetic'
