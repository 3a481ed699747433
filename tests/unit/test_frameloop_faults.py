"""Fault injection (issue 21), every kind on the FrameLoop: what the sensor or actuator does,
what the flight software and the run say, and that no NaN reaches an actuator. The graph
gives the same series (tests/graph/test_faults_graph.py).

Scenarios: paper001_mpi (wheels, star tracker, gyro, MEKF) for the sensor faults on the gyro and
the star tracker and the wheel faults; paper000_control (magnetorquers, magnetometer) for the
magnetometer and coil faults. Short runs; each check against the fault-free run of the same
seed (the same draws), so a difference is the fault's.
"""
import math
import os

import numpy as np
import pytest
import yaml

from adcs_nodes.msgs.fields import quat, vec3
from frameloop_run import messages
from adcs_nodes.scenario import ScenarioError, load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def scenario(tmp_path, name, faults, exact_wheels=False):
    """A shipped scenario with ``faults``; ``exact_wheels``: without paper 001's wheel
    momentum control error (so a wheel's torque is its motor's alone)."""
    with open(os.path.join(ROOT, 'scenarios', f'{name}.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['faults'] = faults
    if exact_wheels:
        sc['spacecraft']['wheel_error_std_Nms'] = 0.0
    path = tmp_path / f'{name}_faults.yaml'
    path.write_text(yaml.safe_dump(sc))
    return load_scenario(str(path))


def run(sc, duration):
    """Every frame's outputs by topic: {topic: [(t_s, msg), ...]}, and the loop."""
    from sim_node.engine import FrameLoop
    loop = FrameLoop.from_scenario(sc, duration)
    out = {}
    for frame in loop.run():
        for topic, msg in messages(frame, loop):
            out.setdefault(topic, []).append((frame.t_ns / 1e9, msg))
    return out, loop


def no_nan_to_actuators(out):
    for _, m in out['adcs/actuator_command']:
        assert np.all(np.isfinite(vec3(m.dipole_body)))
        assert np.all(np.isfinite(np.asarray(m.wheel_torque, float)))
        assert np.all(np.isfinite(vec3(m.torque_body)))


def announced(out):
    """(t_s, level, message) of every sim/faults status."""
    return [(t, ord(st.level), st.message) for t, m in out.get('sim/faults', [])
            for st in m.status]


@pytest.fixture(scope='module')
def mpi_clean(tmp_path_factory):
    return run(scenario(tmp_path_factory.mktemp('clean'), 'paper001_mpi', []), 6.0)[0]


def test_star_tracker_dropout_is_silent_and_the_mekf_coasts_on_the_gyro(tmp_path):
    from adcs_nodes.core.lockstep import REVIVE_HOLD_FRAMES
    out, loop = run(scenario(tmp_path, 'paper001_mpi', [
        {'at_s': 2.0, 'kind': 'dropout', 'target': 'star_tracker',
         'params': {'duration_s': 2.0}}]), 16.0)
    stamps = [t for t, _ in out['sensors/star_tracker']]
    assert not any(2.0 <= t < 4.0 for t in stamps) and 4.0 in stamps
    # the estimator counted the silent input (3 misses, then dead) and kept estimating
    assert loop.estimator.rejected_count == 3
    assert len(out['adcs/attitude_estimate']) == 16 * 5 + 1      # every 0.2 s frame of 16 s
    truth = {t: quat(m.q_eci_body) for t, m in out['sim/state']}
    err = {round(t, 6): math.degrees(2 * math.acos(min(1.0, abs(float(
        quat(m.q_eci_body) @ truth[t]))))) for t, m in out['adcs/attitude_estimate']}
    # the sample at 4.0 s revives the star tracker, which is re-admitted after the hold
    # (core.lockstep.REVIVE_HOLD_FRAMES of 0.2 s): on the gyro alone until then
    back = 4.0 + REVIVE_HOLD_FRAMES * 0.2
    assert back < 15.0
    coasting = [e for t, e in err.items() if 2.0 <= t <= back]
    assert max(coasting) < 0.1      # seconds on the gyro alone: about a tenth of a degree
    assert err[16.0] < 0.5 * max(coasting)     # the star tracker back: the error comes down
    assert announced(out) == [(2.0, 1, 'active: dropout star_tracker'),
                              (4.0, 0, 'cleared: dropout star_tracker')]
    no_nan_to_actuators(out)


def test_gyro_nan_samples_are_rejected_and_never_reach_an_actuator(tmp_path):
    out, loop = run(scenario(tmp_path, 'paper001_mpi', [
        {'at_s': 1.0, 'kind': 'nan', 'target': 'gyro', 'params': {'duration_s': 1.0}}]), 4.0)
    bad = [t for t, m in out['sensors/gyro'] if not np.all(np.isfinite(vec3(m.angular_velocity)))]
    assert bad == pytest.approx([1.0, 1.2, 1.4, 1.6, 1.8])
    assert loop.estimator.rejected_count == 5
    no_nan_to_actuators(out)


def test_gyro_stuck_repeats_the_last_sample(tmp_path, mpi_clean):
    out, _ = run(scenario(tmp_path, 'paper001_mpi', [
        {'at_s': 1.0, 'kind': 'stuck', 'target': 'gyro', 'params': {'duration_s': 1.0}}]), 3.0)
    g = {round(t, 6): vec3(m.angular_velocity) for t, m in out['sensors/gyro']}
    for t in (1.0, 1.2, 1.8):
        assert np.array_equal(g[t], g[0.8])
    assert not np.array_equal(g[2.0], g[0.8])


def test_gyro_bias_step_and_noise_burst_change_the_samples_by_their_size(tmp_path, mpi_clean):
    bias = [2e-5, 0.0, -1e-5]
    out, _ = run(scenario(tmp_path, 'paper001_mpi', [
        {'at_s': 1.0, 'kind': 'bias_step', 'target': 'gyro', 'params': {'bias': bias}}]), 1.6)
    clean = {round(t, 6): vec3(m.angular_velocity) for t, m in mpi_clean['sensors/gyro']}
    got = {round(t, 6): vec3(m.angular_velocity) for t, m in out['sensors/gyro']}
    assert np.array_equal(got[0.8], clean[0.8])
    np.testing.assert_allclose(got[1.0] - clean[1.0], bias, rtol=0, atol=1e-18)
    std = 1e-4
    out, _ = run(scenario(tmp_path, 'paper001_mpi', [
        {'at_s': 0.0, 'kind': 'noise_burst', 'target': 'gyro',
         'params': {'duration_s': 6.0, 'std': [std, std, std]}}]), 6.0)
    noise = np.array([vec3(m.angular_velocity) - clean[round(t, 6)]
                      for t, m in out['sensors/gyro'] if round(t, 6) in clean])
    assert noise.shape == (31, 3)
    # 93 draws: the sample std within 25 % of the given one (chi-square, far beyond 5 sigma)
    assert 0.75 * std < noise.std() < 1.25 * std and abs(noise.mean()) < 0.5 * std


def test_wheel_stuck_freezes_its_speed_and_the_others_go_on(tmp_path, mpi_clean):
    sc = scenario(tmp_path, 'paper001_mpi', [])
    name = sc['spacecraft']['wheels'][0]['name']
    out, _ = run(scenario(tmp_path, 'paper001_mpi', [
        {'at_s': 1.0, 'kind': 'wheel_stuck', 'target': name}], exact_wheels=True), 4.0)
    speeds = {round(t, 6): np.asarray(m.speed) for t, m in out['sim/wheels']}
    torque = {round(t, 6): np.asarray(m.torque) for t, m in out['sim/wheels']}
    assert all(torque[t][0] == 0.0 for t in torque if t >= 1.2)
    # no motor torque: the wheel's momentum does not change; its speed relative to the
    # body changes only with the body rate about its axis (tiny here)
    mom = {round(t, 6): np.asarray(m.momentum) for t, m in out['sim/wheels']}
    assert abs(mom[4.0][0] - mom[1.2][0]) < 1e-12 * max(1.0, abs(mom[1.2][0]))
    assert abs(speeds[4.0][0] - speeds[1.2][0]) < 1e-3
    assert any(np.any(torque[t][1:] != 0.0) for t in torque if t >= 1.2)
    no_nan_to_actuators(out)


def test_wheel_torque_lost_delivers_the_fraction(tmp_path):
    sc = scenario(tmp_path, 'paper001_mpi', [])
    name = sc['spacecraft']['wheels'][1]['name']
    out, _ = run(scenario(tmp_path, 'paper001_mpi', [
        {'at_s': 0.0, 'kind': 'wheel_torque_lost', 'target': name,
         'params': {'fraction': 0.25}}], exact_wheels=True), 2.0)
    cmd = {round(t, 6): np.asarray(m.wheel_torque) for t, m in out['adcs/actuator_command']}
    applied = {round(t, 6): np.asarray(m.torque) for t, m in out['sim/wheels']}
    for t in (0.2, 1.0, 2.0):     # sim/wheels at t carries the torque applied over [t - dt, t]
        np.testing.assert_allclose(applied[t][1], 0.25 * cmd[round(t - 0.2, 6)][1],
                                   rtol=1e-12, atol=1e-15)


def test_coil_open_zeroes_one_magnetorquer_axis_and_magnetometer_faults(tmp_path):
    from sim_node.engine import FrameLoop
    sc = scenario(tmp_path, 'paper000_control', [
        {'at_s': 0.0, 'kind': 'coil_open', 'target': 'z'},
        {'at_s': 20.0, 'kind': 'nan', 'target': 'magnetometer',
         'params': {'duration_s': 20.0}}])
    loop = FrameLoop.from_scenario(sc, 200.0)
    commanded, applied = [], []
    for frame in loop.run():
        cmd = [m for topic, m in messages(frame, loop) if topic == 'adcs/actuator_command']
        if cmd and not loop.done:       # the dipole the world applied over this frame
            commanded.append(vec3(cmd[0].dipole_body))
            applied.append(np.array(loop.dynamics.applied['dipole_body']))
    commanded, applied = np.array(commanded), np.array(applied)
    assert np.abs(commanded[:, 2]).max() > 0.1           # the law asks for a z dipole ...
    assert np.all(applied[:, 2] == 0.0)                  # ... the open coil gives none
    np.testing.assert_array_equal(applied[:, :2], commanded[:, :2])
    assert loop.estimator.rejected_count == 2            # the samples at 20 and 30 s
    out, _ = run(sc, 60.0)
    assert [s[2] for s in announced(out)] == ['active: coil_open z',
                                              'active: nan magnetometer',
                                              'cleared: nan magnetometer']
    no_nan_to_actuators(out)


@pytest.mark.parametrize('fault, why', [
    ({'at_s': 1.0, 'kind': 'melt', 'target': 'gyro'}, "unknown fault 'melt'"),
    ({'at_s': 1.0, 'kind': 'dropout', 'target': 'sun_sensor'}, 'cannot strike'),
    ({'at_s': 1e9, 'kind': 'dropout', 'target': 'gyro'}, 'outside the run'),
    ({'at_s': 1.0, 'kind': 'noise_burst', 'target': 'gyro',
      'params': {'std': [5.0, 0.0, 0.0]}}, 'std'),
    ({'at_s': 1.0, 'kind': 'coil_open', 'target': 'z'}, 'none in this scenario'),
    ({'at_s': 1.0, 'kind': 'dropout'}, 'faults[0].target: missing required key'),
])
def test_bad_faults_are_refused_with_the_key(tmp_path, fault, why):
    with pytest.raises(ScenarioError, match='faults') as exc:
        scenario(tmp_path, 'paper001_mpi', [fault])
    assert why in str(exc.value), str(exc.value)


def test_a_star_tracker_back_during_its_filter_restart_is_held_like_any_return(tmp_path):
    """Issue 38's case on the plain engine: two overlapping star-tracker bias steps make the
    MEKF refuse 10 samples and restart (no estimate until a star-tracker sample initialises
    it); the star tracker is then silent 3 frames (dead) and returns stuck: its returning
    samples are held for ``REVIVE_HOLD_FRAMES`` frames like any dead producer's return, so
    no estimate in the run after the restart (the composed engine used to resume at the
    return: tests/node/test_fault_parity.py)."""
    from adcs_nodes.core.lockstep import REVIVE_HOLD_FRAMES
    at = {'target': 'star_tracker'}
    sc = scenario(tmp_path, 'demo_mission', [
        {**at, 'at_s': 2.0, 'kind': 'bias_step',
         'params': {'bias': [0.01, 0, 0], 'duration_s': 15.0}},
        {**at, 'at_s': 3.0, 'kind': 'bias_step',
         'params': {'bias': [0, 0.01, 0], 'duration_s': 15.0}},
        {**at, 'at_s': 12.0, 'kind': 'dropout', 'params': {'duration_s': 5.0}},
        {**at, 'at_s': 13.0, 'kind': 'stuck', 'params': {'duration_s': 10.0}}])
    out, loop = run(sc, 40.0)
    est = [t for t, _ in out['adcs/attitude_estimate']]
    assert est == [float(k) for k in range(11)]          # the 10th refusal (11 s) restarts
    assert 17.0 + REVIVE_HOLD_FRAMES > 40.0               # back at 17 s: held past the end
    assert [t for t, _ in out['sensors/star_tracker']] == \
        [float(k) for k in range(41) if not 12 <= k < 17]
