"""Wheel health (adcs_nodes/core/wheel_health.py): a wheel whose measured speed does not follow
the applied torque for ``confirm_frames`` informative frames is ``stuck`` or has ``lost
torque``, with a reason; it is ``ok`` again after ``recover_frames`` good ones (its probe
torque). What a wheel controller then sends, and what the manager makes of it.

Truth: a healthy wheel changes speed by ``tau dt / J`` per interval (plus tachometer noise); a
stuck one does not change at all; one that lost torque changes by a fraction of it.
"""
import math

import numpy as np
import pytest

from adcs_nodes.components.controller import ControllerComponent, command_of
from adcs_nodes.core.samples import ActuatorCommand, WheelSpeeds
from adcs_nodes.core.control import Command
from adcs_nodes.core.manager import ControllerManagerCore
from adcs_nodes.core.wheel_health import CONFIRM_FRAMES, RECOVER_FRAMES, WheelHealth

J = np.array([3e-4, 3e-4, 3e-4])
H_MAX = np.array([0.2, 0.2, 0.2])
NAMES = ['wheel_x', 'wheel_y', 'wheel_z']


def _run(health, torques, stuck=(), noise=0.0, seed=0, w0=None, share=0.0):
    """Feed ``health`` one interval per torque row (1 s each); wheels in ``stuck`` follow
    ``share`` of their torque (0: keep their speed). Returns the reason after each interval."""
    rng = np.random.default_rng(seed)
    w = np.zeros(3) if w0 is None else np.array(w0, float)
    reasons = [health.update(0.0, w + noise * rng.standard_normal(3), None, None)]
    for k, tau in enumerate(torques):
        tau = np.asarray(tau, float)
        step = tau * 1.0 / J
        step[list(stuck)] *= share
        w = w + step
        reasons.append(health.update(k + 1.0, w + noise * rng.standard_normal(3), float(k),
                                     tau))
    return reasons


def test_a_healthy_wheel_with_tachometer_noise_never_fails():
    health = WheelHealth(J, H_MAX, 1.0, names=NAMES)
    tau = [[1e-4 * math.sin(0.1 * k), -2e-4, 5e-5 * (-1) ** k] for k in range(300)]
    reasons = _run(health, tau, noise=0.01)          # the default tachometer's noise
    assert not any(reasons) and health.state == ['ok'] * 3
    assert health.judged_frames == 300


def test_a_stuck_wheel_fails_after_confirm_frames_with_a_reason_naming_it():
    health = WheelHealth(J, H_MAX, 1.0, names=NAMES)
    tau = [[2e-4, 2e-4, -2e-4]] * 10
    reasons = _run(health, tau, stuck=[0], noise=0.005)
    first = next(i for i, r in enumerate(reasons) if r)
    assert first == CONFIRM_FRAMES                   # the 5th bad interval
    assert reasons[first].startswith('wheel wheel_x stuck since t = 5 s: speed change')
    assert '5 frames in a row' in reasons[first]
    assert health.state == ['stuck', 'ok', 'ok'] and list(health.ok) == [False, True, True]
    assert reasons[-1] == reasons[first]             # still stuck: unchanged
    health.reset()
    assert health.reason() == '' and health.state == ['ok'] * 3


def test_a_wheel_with_a_third_of_its_torque_has_lost_torque():
    health = WheelHealth(J, H_MAX, 1.0, names=NAMES)
    reasons = _run(health, [[0.0, 3e-4, 0.0]] * 6, stuck=[1], share=0.3, noise=0.005)
    assert health.state == ['ok', 'lost torque', 'ok']
    assert reasons[-1].startswith('wheel wheel_y lost torque since t = 5 s')


def test_a_freed_wheel_recovers_after_recover_frames_of_its_probe_and_not_before():
    health = WheelHealth(J, H_MAX, 1.0, names=NAMES, max_torque_Nm=[0.01] * 3)
    _run(health, [[2e-4, 0.0, 0.0]] * CONFIRM_FRAMES, stuck=[0])
    assert health.state[0] == 'stuck'
    w, t = health._w.copy(), float(CONFIRM_FRAMES)
    probes = []
    for k in range(RECOVER_FRAMES):
        tau = health.probe()
        probes.append(tau[0])
        assert tau[1] == tau[2] == 0.0               # only the failed wheel is probed
        assert health.state[0] == 'stuck'            # not before the N-th good frame
        w = w + tau / J                              # the wheel is free again: it follows
        health.update(t + 1.0, w, t, tau)
        t += 1.0
    assert health.state[0] == 'ok' and health.reason() == '' and health.recoveries == 1
    # the probe: 2 x the smallest judged change, its sign alternating (net momentum zero)
    assert probes[0] == pytest.approx(2 * 0.2 * J[0]) and probes[1] == -probes[0]
    assert sum(probes[:4]) == 0.0


def test_a_still_stuck_wheel_is_not_recovered_by_its_probe():
    health = WheelHealth(J, H_MAX, 1.0, names=NAMES)
    _run(health, [[2e-4, 0.0, 0.0]] * CONFIRM_FRAMES, stuck=[0])
    w, t = health._w.copy(), float(CONFIRM_FRAMES)
    for _ in range(20):
        health.update(t + 1.0, w, t, health.probe())  # the speed does not move
        t += 1.0
    assert health.state[0] == 'stuck'


def test_small_torques_are_not_judged_and_do_not_clear_the_count():
    health = WheelHealth(J, H_MAX, 1.0)
    big, small = [2e-4, 0.0, 0.0], [1e-5, 0.0, 0.0]   # 0.67 and 0.03 rad/s per second
    reasons = _run(health, [big] * 3 + [small] * 20 + [big] * 2, stuck=[0])
    assert health.bad[0] == 5 and reasons[-1].startswith('wheel wheel0 stuck')
    assert not any(reasons[:-1])


def test_a_good_interval_clears_the_count():
    health = WheelHealth(J, H_MAX, 1.0)
    tau = [[2e-4, 0.0, 0.0]] * 4
    _run(health, tau, stuck=[0])
    assert health.bad[0] == 4
    health.update(5.0, health._w + 2e-4 / J[0] * np.array([1.0, 0.0, 0.0]), 4.0,
                  [2e-4, 0.0, 0.0])
    assert health.bad[0] == 0 and health.reason() == ''


def test_no_judgement_near_the_momentum_limit_or_without_the_matching_command():
    health = WheelHealth(J, H_MAX, 1.0)
    # at 0.195 N m s (97.5 % of the limit) the motor's torque is cut on purpose
    reasons = _run(health, [[2e-4, 0, 0]] * 10, stuck=[0], w0=[0.195 / J[0], 0.0, 0.0])
    assert not any(reasons) and health.bad[0] == 0
    health = WheelHealth(J, H_MAX, 1.0)
    w = np.zeros(3)
    health.update(0.0, w, None, None)
    for k in range(1, 10):        # the command is not the one held over the interval
        assert health.update(float(k), w, k - 0.5, [2e-4, 0, 0]) == ''
    health.update(20.0, w, 19.0, [2e-4, 0, 0])      # 11 s since the last sample: not a period
    assert health.judged_frames == 0
    assert health.update(21.0, [np.nan] * 3, 20.0, [2e-4, 0, 0]) == ''   # a bad sample


def test_bad_configuration_is_refused():
    with pytest.raises(ValueError):
        WheelHealth([3e-4], [0.2, 0.2], 1.0)
    with pytest.raises(ValueError):
        WheelHealth([0.0], [0.2], 1.0)
    with pytest.raises(ValueError):
        WheelHealth([3e-4], [0.2], 0.0)
    with pytest.raises(ValueError):
        WheelHealth([3e-4], [0.2], 1.0, confirm_frames=0)
    with pytest.raises(ValueError, match='recover_frames'):
        WheelHealth([3e-4], [0.2], 1.0, recover_frames=1.5)


class _Steady:
    """A wheel controller core that always asks for the same torques."""

    def update(self, inputs, t, dt):
        return Command(np.zeros(3), np.array([2e-4, 2e-4, 2e-4]), np.zeros(3))


def _joint(t_ns, w):
    return WheelSpeeds(t_ns, 'wheel_tachometer', tuple(NAMES), np.array(w, dtype=float))


def test_a_core_that_ignores_the_health_is_refused_and_the_manager_falls_back_with_why():
    """``_Steady`` does not read ``ControlInputs.wheel_ok``: once wheel_x is stuck it still
    asks it for torque, so the component refuses its command naming the wheel first."""
    ctx = {'wheel_max_torque_Nm': [0.01] * 3, 'wheel_inertia_kgm2': list(J),
           'wheel_max_momentum_Nms': list(H_MAX), 'period_s': 1.0, 'reference': None}
    comp = ControllerComponent(_Steady(), 'mpi', ctx, None)
    manager = ControllerManagerCore(['bdot', 'mpi'], 'bdot', initial='mpi',
                                    max_dipole_Am2=[5.0] * 3, max_wheel_torque=[0.01] * 3)
    bdot = Command(np.array([0.1, 0.0, 0.0]), np.zeros(0), np.zeros(3))
    w = np.zeros(3)
    applied = None
    statuses = []
    for k in range(10):
        t_ns = k * 10**9
        samples = {'wheels': _joint(t_ns, w), 'cmd': applied}
        out = comp.step(t_ns, samples, lambda key: True)
        cmd, status = manager.step(float(k), {'mpi': (float(k), command_of(out)),
                                              'bdot': (float(k), bdot)})
        statuses.append(status)
        assert np.all(np.isfinite(out.wheel_torque_Nm))
        assert np.all(np.isfinite(out.dipole_body_Am2))
        applied = ActuatorCommand(t_ns, np.zeros(3), np.array(cmd.wheel_torque, dtype=float),
                                  np.zeros(3), 'mpi')
        w = w + np.asarray(cmd.wheel_torque) / J * np.array([0.0, 1.0, 1.0])   # wheel_x stuck
    sources = [s['source'] for s in statuses]
    # frame k judges the interval [k - 1, k] before the core runs: the 5th bad one is frame 5
    assert sources[:CONFIRM_FRAMES] == ['mpi'] * CONFIRM_FRAMES
    assert set(sources[CONFIRM_FRAMES:]) == {'bdot'}
    fault = statuses[-1]['last_fault']
    assert fault.startswith('mpi: wheel wheel_x stuck since t = 5 s')
    assert 'commands torque on the failed wheel wheel_x; fallback to bdot' in fault
    assert 'non-finite' not in fault
    assert out.source.startswith('mpi: wheel wheel_x stuck')
