"""Controller-manager logic (adcs_nodes.core.manager): switching, zero frame, schedule, auto
sequence, fallback and limits."""
import math

import numpy as np
import pytest

from adcs_nodes.core import attitude
from adcs_nodes.core.control import Command, Estimate, Target
from adcs_nodes.core.manager import AutoSequence, ControllerManagerCore

DT = 2.0
MAG = np.array([1.0, 0.0, 0.0])            # magnetic controller's (recognisable) dipole
BDOT = np.array([0.0, 2.0, 0.0])           # B-dot's


def _cmd(dipole, wheels=(), torque=(0.0, 0.0, 0.0)):
    return Command(np.asarray(dipole, float), np.asarray(wheels, float),
                   np.asarray(torque, float))


def _both(t, mag=MAG, bdot=BDOT):
    return {'magnetic': (t, _cmd(mag)), 'bdot': (t, _cmd(bdot))}


def _mgr(**kw):
    args = dict(controllers=['magnetic', 'bdot'], safe='bdot', initial='magnetic',
                max_dipole_Am2=40.0, stale_after_s=0.0)
    args.update(kw)
    return ControllerManagerCore(**args)


def _source(cmd):
    if np.array_equal(cmd.dipole_body, MAG):
        return 'magnetic'
    if np.array_equal(cmd.dipole_body, BDOT):
        return 'bdot'
    return 'zero' if np.all(cmd.dipole_body == 0.0) else 'other'


def _est(rate_deg_s, q=(0.0, 0.0, 0.0, 1.0), valid=True):
    return Estimate(np.asarray(q, float), np.array([math.radians(rate_deg_s), 0.0, 0.0]),
                    1.0625e-3, valid)


# ---------------------------------------------------------------------------- switching
def test_unknown_name_refused_and_nothing_changes():
    mgr = _mgr()
    ok, msg = mgr.request_switch('fuzzy', 0.0)
    assert not ok and "unknown controller 'fuzzy'" in msg and 'magnetic, bdot' in msg
    cmd, st = mgr.step(2.0, _both(2.0))
    assert _source(cmd) == 'magnetic' and st['switch_count'] == 0 and st['pending'] == ''
    assert mgr.list_controllers() == (['magnetic', 'bdot'], 'magnetic', 'bdot')


def test_exactly_one_zero_frame_at_each_switch():
    """magnetic -> bdot -> magnetic: the frame after the request is zero, then the new one."""
    mgr = _mgr()
    seq = []
    for i in range(12):
        t = i * DT
        cmd, st = mgr.step(t, _both(t))
        seq.append(_source(cmd))
        if i == 2:
            ok, msg = mgr.request_switch('bdot', t)
            assert ok and 'one frame of zero' in msg
            assert mgr.status()['pending'] == ''        # status of the last step
        if i == 6:
            assert mgr.request_switch('magnetic', t)[0]
    assert seq == ['magnetic'] * 3 + ['zero'] + ['bdot'] * 3 + ['zero'] + ['magnetic'] * 4
    assert st['switch_count'] == 2 and st['active'] == 'magnetic' and st['missed_frames'] == 0
    assert st['last_fault'] == ''


def test_request_timing_and_same_controller():
    mgr = _mgr()
    mgr.step(0.0, _both(0.0))
    mgr.request_switch('bdot', 2.0)              # made "at" frame 2, before it was stepped
    cmd, st = mgr.step(2.0, _both(2.0))          # not after t_req: still magnetic
    assert _source(cmd) == 'magnetic' and st['pending'] == 'bdot'
    cmd, st = mgr.step(4.0, _both(4.0))
    assert _source(cmd) == 'zero' and st['zero_frame'] and st['active'] == 'bdot'
    assert 'switch magnetic -> bdot' in cmd.reason
    ok, msg = mgr.request_switch('bdot')         # already active: no zero frame
    assert ok and 'already active' in msg
    cmd, st = mgr.step(6.0, _both(6.0))
    assert _source(cmd) == 'bdot' and st['switch_count'] == 1
    mgr.request_switch('magnetic')               # t = None: the next frame whatever its time
    assert _source(mgr.step(8.0, _both(8.0))[0]) == 'zero'
    assert _source(mgr.step(10.0, _both(10.0))[0]) == 'magnetic'


# ----------------------------------------------------------------------------- fallback
@pytest.mark.parametrize('entry, word', [
    (None, 'stale: no command received'),
    ((8.0, _cmd(MAG)), 'older than the frame'),
    ((12.0, _cmd(MAG)), 'ahead of the frame'),
    ((10.0, None), 'stale: no command'),
    ((10.0, _cmd([np.nan, 0.0, 0.0])), 'non-finite'),
    ((10.0, _cmd([0.0, np.inf, 0.0])), 'non-finite'),
    ((10.0, _cmd([0.0, 0.0, -50.0])),
     'out of range: dipole_body[2] = -50 A m^2 exceeds the limit 40 A m^2'),
    ((10.0, _cmd(MAG, torque=[0.0, 1e-3, 0.0])), 'out of range: torque_body[1]'),
    ((10.0, _cmd([1.0, 0.0])), 'malformed dipole_body'),
])
def test_fallback_to_safe_with_reason(entry, word):
    mgr = _mgr()
    commands = _both(10.0)
    if entry is None:
        del commands['magnetic']
    else:
        commands['magnetic'] = entry
    cmd, st = mgr.step(10.0, commands)
    assert _source(cmd) == 'bdot' and st['source'] == 'bdot' and st['fallback']
    assert st['last_fault'].startswith('magnetic: ') and word in st['last_fault']
    assert 'fallback to bdot' in st['last_fault'] and st['missed_frames'] == 1
    assert st['active'] == 'magnetic' and st['switch_count'] == 0
    # the magnetic command is valid again: forwarded, the last fault is kept
    cmd, st = mgr.step(12.0, _both(12.0))
    assert _source(cmd) == 'magnetic' and st['fault'] == '' and word in st['last_fault']


def test_staleness_window_and_wheels():
    mgr = _mgr(stale_after_s=2.5, max_wheel_torque=[0.01, 0.02], max_torque=0.0)
    cmds = _both(8.0)                               # 2 s old, window 2.5 s: fresh
    cmd, st = mgr.step(10.0, cmds)
    assert _source(cmd) == 'magnetic' and cmd.wheel_torque.shape == (2,)
    assert np.all(cmd.wheel_torque == 0.0)          # empty wheel vector read as zeros
    cmds['magnetic'] = (10.0, _cmd(MAG, wheels=[0.005, -0.03]))
    cmd, st = mgr.step(10.0, cmds)
    assert 'out of range: wheel_torque[1] = -0.03 N m' in st['last_fault']
    cmds['magnetic'] = (10.0, _cmd(MAG, wheels=[0.005, 0.0, 0.0]))
    _, st = mgr.step(10.0, cmds)
    assert 'malformed wheel_torque' in st['last_fault']
    cmds['magnetic'] = (10.0, _cmd(MAG, wheels=[0.005, -0.02]))
    cmd, st = mgr.step(10.0, cmds)
    assert _source(cmd) == 'magnetic' and np.allclose(cmd.wheel_torque, [0.005, -0.02])


def test_safe_controller_bad_too_gives_zero():
    mgr = _mgr()
    cmd, st = mgr.step(4.0, {'magnetic': (4.0, _cmd([np.nan] * 3)),
                             'bdot': (2.0, _cmd(BDOT))})
    assert _source(cmd) == 'zero' and cmd.is_finite() and st['source'] == ''
    assert 'non-finite' in st['last_fault'] and 'safe controller bdot: stale' in st['last_fault']
    assert not st['fallback'] and st['missed_frames'] == 1
    mgr = _mgr(initial='bdot')                      # the safe controller itself is active
    cmd, st = mgr.step(4.0, {'bdot': (4.0, _cmd([0.0, 99.0, 0.0]))})
    assert _source(cmd) == 'zero' and st['last_fault'].startswith('bdot: out of range')


def test_latched_fallback_makes_safe_active():
    mgr = _mgr(latch_fallback=True)
    cmd, st = mgr.step(0.0, {'bdot': (0.0, _cmd(BDOT))})
    assert _source(cmd) == 'bdot' and st['active'] == 'bdot' and st['switch_count'] == 1
    cmd, st = mgr.step(2.0, _both(2.0))             # magnetic is back, but bdot stays
    assert _source(cmd) == 'bdot' and st['missed_frames'] == 1


def test_output_always_finite_and_inside_limits_fuzz():
    """Random commands (NaN, inf, huge, stale, missing, wrong shapes) and random switch
    requests: the output is always finite and inside the limits; same inputs, same outputs."""
    lim_d, lim_w, lim_t = np.array([40.0, 30.0, 20.0]), np.array([0.01, 0.02]), np.full(3, 1e-3)

    def run(seed):
        rng = np.random.default_rng(seed)
        mgr = _mgr(controllers=['magnetic', 'bdot', 'mpi'], max_dipole_Am2=lim_d,
                   max_wheel_torque=lim_w, max_torque=lim_t, stale_after_s=DT)
        out = []
        for i in range(1500):
            t = i * DT
            cmds = {}
            for name in ('magnetic', 'bdot', 'mpi'):
                r = rng.random()
                if r < 0.05:
                    continue
                scale = 10.0 ** rng.uniform(-3, 3)
                d = rng.normal(size=3) * scale
                w = rng.normal(size=rng.choice([0, 2, 3])) * scale * 1e-3
                tq = rng.normal(size=3) * scale * 1e-4
                if r < 0.15:
                    d[rng.integers(3)] = rng.choice([np.nan, np.inf, -np.inf])
                stamp = t - DT * rng.integers(0, 3) if r < 0.3 else t
                cmds[name] = (stamp, None if r > 0.97 else _cmd(d, w, tq))
            if rng.random() < 0.05:
                mgr.request_switch(rng.choice(['magnetic', 'bdot', 'mpi', 'nope']), t)
            cmd, st = mgr.step(t, cmds)
            assert cmd.is_finite()
            assert np.all(np.abs(cmd.dipole_body) <= lim_d)
            assert cmd.wheel_torque.shape == (2,) and np.all(np.abs(cmd.wheel_torque) <= lim_w)
            assert np.all(np.abs(cmd.torque_body) <= lim_t)
            assert st['active'] in ('magnetic', 'bdot', 'mpi')
            out.append(np.concatenate([cmd.dipole_body, cmd.wheel_torque, cmd.torque_body]))
        return np.array(out), st

    a, st_a = run(11)
    b, st_b = run(11)
    assert np.array_equal(a, b) and st_a == st_b
    assert st_a['switch_count'] > 10 and st_a['missed_frames'] > 100


# ----------------------------------------------------------------------------- schedule
def test_schedule_at_exact_times_with_one_zero_frame():
    mgr = _mgr(schedule=[(20.0, 'magnetic'), (10.0, 'bdot'), (31.0, 'bdot')])
    seq = {}
    for i in range(20):
        t = i * DT
        cmd, st = mgr.step(t, _both(t))
        seq[t] = _source(cmd)
    assert seq[8.0] == 'magnetic' and seq[10.0] == 'zero' and seq[12.0] == 'bdot'
    assert seq[18.0] == 'bdot' and seq[20.0] == 'zero' and seq[22.0] == 'magnetic'
    assert seq[30.0] == 'magnetic' and seq[32.0] == 'zero' and seq[34.0] == 'bdot'   # 31 s
    assert st['switch_count'] == 3
    # nanosecond-level time from integer ns still hits the exact frame
    mgr = _mgr(schedule=[(0.3, 'bdot')])
    assert _source(mgr.step(0.1 + 0.2, _both(0.1 + 0.2))[0]) == 'zero'
    mgr.reset()
    assert mgr.active == 'magnetic' and _source(mgr.step(0.3, _both(0.3))[0]) == 'zero'


def test_operator_request_beats_schedule_in_the_same_frame():
    mgr = _mgr(controllers=['magnetic', 'bdot', 'mpi'], schedule=[(4.0, 'bdot')])
    mgr.step(2.0, _both(2.0))
    mgr.request_switch('mpi', 2.0)
    mgr.step(4.0, _both(4.0))
    assert mgr.active == 'mpi'


# ------------------------------------------------------------------------ auto sequence
def _auto_mgr(**kw):
    auto = AutoSequence(detumble='bdot', acquire='magnetic', rate_enter_rad_s=math.radians(0.5),
                        rate_exit_rad_s=math.radians(1.0), confirm_frames=3, **kw)
    return ControllerManagerCore(['magnetic', 'bdot'], safe='bdot', max_dipole_Am2=40.0,
                                 auto=auto)


def test_auto_sequence_with_confirmation_and_hysteresis():
    mgr = _auto_mgr()
    assert mgr.active == 'bdot' and mgr.mode == 'detumble'
    rates = [2.0, 0.4, 0.4, 0.6, 0.4, 0.4, 0.4, 0.3, 0.8, 0.9, 0.8, 1.2, 0.9, 0.3]
    seq, modes = [], []
    for i, r in enumerate(rates):
        t = i * DT
        cmd, st = mgr.step(t, _both(t), estimate=_est(r))
        seq.append(_source(cmd))
        modes.append(st['mode'])
    # 0.6 at frame 3 resets the count; frames 4, 5, 6 below 0.5: switch (zero) at frame 6;
    # 0.8-0.9 is inside the hysteresis band; 1.2 > 1.0 at frame 11: back to detumble (zero)
    assert seq == (['bdot'] * 6 + ['zero'] + ['magnetic'] * 4 + ['zero'] + ['bdot'] * 2)
    assert modes[5] == 'detumble' and modes[6] == 'acquire' and modes[11] == 'detumble'
    assert st['switch_count'] == 2


def test_auto_holds_on_invalid_estimate_and_point_mode_without_zero_frame():
    mgr = _auto_mgr(point='magnetic', angle_enter_rad=math.radians(5.0),
                    angle_exit_rad=math.radians(10.0))
    t = 0.0
    for est in [_est(0.1), _est(0.1), _est(0.1, valid=False), None, _est(0.1), _est(0.1)]:
        cmd, st = mgr.step(t, _both(t), estimate=est)
        t += DT
    assert st['mode'] == 'detumble'                  # the invalid ones broke the count
    cmd, st = mgr.step(t, _both(t), estimate=_est(0.1))
    assert st['mode'] == 'acquire' and _source(cmd) == 'zero'
    q20 = attitude.from_axis_angle([0.0, 1.0, 0.0], math.radians(20.0))
    q3 = attitude.from_axis_angle([0.0, 1.0, 0.0], math.radians(3.0))
    q7 = attitude.from_axis_angle([0.0, 1.0, 0.0], math.radians(7.0))
    modes = []
    for q in [q20, q3, q3, q3, q7, q20, q3]:
        t += DT
        cmd, st = mgr.step(t, _both(t), estimate=_est(0.1, q))
        modes.append(st['mode'])
        assert _source(cmd) == 'magnetic'            # same controller: never a zero frame
    assert modes == ['acquire', 'acquire', 'acquire', 'point', 'point', 'acquire', 'acquire']
    # error measured to the target, not to the orbit frame
    t += DT
    st = mgr.step(t, _both(t), estimate=_est(0.1, q20), target=Target(q20))[1]
    assert st['mode'] == 'acquire'


def test_manual_switch_suspends_auto_and_auto_restarts_it():
    mgr = _auto_mgr()
    mgr.step(0.0, _both(0.0), estimate=_est(3.0))
    assert mgr.request_switch('magnetic', 0.0)[0]
    cmd, st = mgr.step(2.0, _both(2.0), estimate=_est(3.0))
    assert _source(cmd) == 'zero' and st['mode'] == '' and st['active'] == 'magnetic'
    cmd, st = mgr.step(4.0, _both(4.0), estimate=_est(3.0))   # fast, but auto is off
    assert _source(cmd) == 'magnetic'
    ok, msg = mgr.request_switch('auto', 4.0)
    assert ok and 'detumble' in msg
    cmd, st = mgr.step(6.0, _both(6.0), estimate=_est(0.1))
    assert _source(cmd) == 'zero' and st['mode'] == 'detumble' and st['active'] == 'bdot'
    # scheduled 'auto' and scheduled controller
    auto = AutoSequence(confirm_frames=1)
    mgr = ControllerManagerCore(['magnetic', 'bdot'], 'bdot', max_dipole_Am2=40.0, auto=auto,
                                schedule=[(2.0, 'magnetic'), (6.0, 'auto')])
    modes = [mgr.step(t, _both(t), estimate=_est(3.0))[1]['mode'] for t in (0, 2, 4, 6, 8)]
    assert modes == ['detumble', '', '', 'detumble', 'detumble']


def test_auto_rate_relative_to_orbit_frame():
    """With rate_frame 'orbit', omega = omega0 e_N (resting in the orbit frame) is rate 0."""
    auto = AutoSequence(rate_enter_rad_s=1e-5, rate_exit_rad_s=None, confirm_frames=1,
                        rate_frame='orbit')
    mgr = ControllerManagerCore(['magnetic', 'bdot'], 'bdot', max_dipole_Am2=40.0, auto=auto)
    est = Estimate(np.array([0, 0, 0, 1.0]), np.array([0.0, 1.0625e-3, 0.0]), 1.0625e-3)
    assert mgr.step(0.0, _both(0.0), estimate=est)[1]['mode'] == 'acquire'
    auto_eci = AutoSequence(rate_enter_rad_s=1e-5, confirm_frames=1)
    mgr = ControllerManagerCore(['magnetic', 'bdot'], 'bdot', max_dipole_Am2=40.0, auto=auto_eci)
    assert mgr.step(0.0, _both(0.0), estimate=est)[1]['mode'] == 'detumble'


def test_auto_sequence_from_dict_degrees():
    auto = AutoSequence.from_dict({'rate_enter_deg_s': 0.3, 'rate_exit_deg_s': 2.0,
                                   'confirm_frames': 5, 'point': 'magnetic',
                                   'angle_enter_deg': 2.0})
    assert auto.rate_enter_rad_s == pytest.approx(math.radians(0.3))
    assert auto.angle_enter_rad == pytest.approx(math.radians(2.0))
    assert auto.angle_exit_rad is None and auto.confirm_frames == 5
    with pytest.raises(ValueError, match='rate_enter: unknown key'):
        AutoSequence.from_dict({'rate_enter': 1.0})


# -------------------------------------------------------------------------- bad config
@pytest.mark.parametrize('kw, word', [
    ({'controllers': []}, 'non-empty'),
    ({'controllers': ['bdot', 'bdot']}, 'unique'),
    ({'safe': 'x'}, "safe controller 'x'"),
    ({'initial': 'x'}, "initial controller 'x'"),
    ({'stale_after_s': -1.0}, 'stale_after_s'),
    ({'max_dipole_Am2': [40.0, 40.0]}, 'max_dipole_Am2'),
    ({'max_dipole_Am2': -1.0}, 'max_dipole_Am2'),
    ({'max_wheel_torque': [0.1, np.nan]}, 'max_wheel_torque'),
    ({'schedule': [(1.0, 'x')]}, r'schedule\[0\]: unknown controller'),
    ({'schedule': [(np.nan, 'bdot')]}, 'finite'),
    ({'schedule': [(1.0, 'auto')]}, 'unknown controller'),
    ({'schedule': [5.0]}, r'schedule\[0\] must be'),
    ({'auto': AutoSequence(acquire='x')}, "acquire controller 'x'"),
    ({'auto': AutoSequence()}, 'conflicts with the auto'),
])
def test_bad_manager_configuration(kw, word):
    with pytest.raises(ValueError, match=word):
        _mgr(**kw)


@pytest.mark.parametrize('kw, word', [
    ({'rate_enter_rad_s': 0.0}, 'rate_enter_rad_s'),
    ({'rate_enter_rad_s': 0.02, 'rate_exit_rad_s': 0.01}, 'hysteresis'),
    ({'confirm_frames': 0}, 'confirm_frames'),
    ({'point': 'magnetic'}, 'angle_enter_rad'),
    ({'angle_enter_rad': 0.1}, 'without a point'),
    ({'point': 'm', 'angle_enter_rad': 0.1, 'angle_exit_rad': 0.05}, 'hysteresis'),
    ({'rate_frame': 'body'}, 'rate_frame'),
])
def test_bad_auto_sequence(kw, word):
    with pytest.raises(ValueError, match=word):
        AutoSequence(**kw)


def test_auto_is_a_reserved_name():
    with pytest.raises(ValueError, match='reserved'):
        ControllerManagerCore(['auto', 'bdot'], 'bdot', auto=AutoSequence(acquire='auto'))


# ------------------------------------------------------------- rapid requests (issue 12)
def test_rapid_requests_one_pending_the_last_wins_and_every_answer_says_so():
    mgr = _mgr(controllers=['magnetic', 'bdot', 'mpi'])
    mgr.step(0.0, {**_both(0.0), 'mpi': (0.0, _cmd(MAG))})
    names = ['bdot', 'mpi'] * 50                     # 100 requests between two frames
    answers = [mgr.request_switch(n, 0.0) for n in names]
    assert all(ok for ok, _ in answers)
    assert 'replaces the pending' not in answers[0][1]
    assert 'queued: switch magnetic -> bdot' in answers[0][1]
    for (ok, msg), prev in zip(answers[1:], names):
        assert f'replaces the pending request for {prev}, which will not be applied' in msg
    assert mgr.replaced_requests == 99
    sources = []
    for k in range(1, 4):
        t = k * DT
        out, st = mgr.step(t, {**_both(t), 'mpi': (t, _cmd(MAG))})
        sources.append((st['active'], st['zero_frame']))
    # exactly one switch (to the last request), one zero frame
    assert sources == [('mpi', True), ('mpi', False), ('mpi', False)]
    assert mgr.switch_count == 1 and mgr.status()['replaced_requests'] == 99


def test_request_for_the_active_controller_cancels_a_pending_switch():
    mgr = _mgr()
    mgr.step(0.0, _both(0.0))
    mgr.request_switch('bdot', 0.0)
    ok, msg = mgr.request_switch('magnetic', 0.0)
    assert ok and 'already active' in msg and 'replaces the pending request for bdot' in msg
    cmd, st = mgr.step(DT, _both(DT))
    assert _source(cmd) == 'magnetic' and not st['zero_frame'] and mgr.switch_count == 0


def test_huge_unknown_name_is_not_echoed_in_full():
    ok, msg = _mgr().request_switch('x' * 100_000, 0.0)
    assert not ok and len(msg) < 300


# ------------------------------------------------------------- estimator staleness
def test_stale_estimate_falls_back_to_the_safe_controller_with_the_reason():
    mgr = _mgr(estimate_period_s=DT)
    est = _est(0.1)
    cmd, st = mgr.step(0.0, _both(0.0), est, estimate_t=0.0)
    assert _source(cmd) == 'magnetic' and st['estimate_fault'] == ''
    # the estimator died: its last estimate is stamped 0 at t = 2, 4
    for t in (DT, 2 * DT):
        cmd, st = mgr.step(t, _both(t), est, estimate_t=0.0)
        assert _source(cmd) == 'bdot' and st['fallback'] and st['source'] == 'bdot'
        assert 'magnetic: estimator stale' in st['fault'] and 'fallback to bdot' in st['fault']
    assert mgr.missed_frames == 2 and mgr.estimate_stale_frames == 2
    cmd, st = mgr.step(3 * DT, _both(3 * DT), est, estimate_t=3 * DT)   # it is back
    assert _source(cmd) == 'magnetic' and not st['fallback']
    cmd, st = mgr.step(4 * DT, _both(4 * DT), None)                      # none at all
    assert _source(cmd) == 'bdot' and 'no estimate received' in st['fault']


def test_safe_controller_never_needs_the_estimate():
    mgr = _mgr(initial='bdot', estimate_period_s=DT)
    cmd, st = mgr.step(0.0, _both(0.0), None)
    assert _source(cmd) == 'bdot' and st['fault'] == '' and mgr.missed_frames == 0
    assert st['estimate_fault'] and mgr.estimate_stale_frames == 1


def test_slower_estimator_is_not_stale_between_its_frames():
    mgr = _mgr(estimate_period_s=10.0)
    for t, stamp in ((10.0, 10.0), (12.0, 10.0), (18.0, 10.0), (20.0, 20.0)):
        cmd, st = mgr.step(t, _both(t), _est(0.1), estimate_t=stamp)
        assert _source(cmd) == 'magnetic', (t, st['fault'])
    cmd, st = mgr.step(22.0, _both(22.0), _est(0.1), estimate_t=10.0)
    assert _source(cmd) == 'bdot'


def test_invalid_or_future_estimate_is_a_fault_and_the_output_stays_finite():
    mgr = _mgr(estimate_period_s=DT, max_dipole_Am2=[1.0, 2.0, 3.0])
    for est, stamp in ((_est(0.1, valid=False), 0.0), (_est(0.1), 5.0),
                       (_est(float('nan')), 0.0), (_est(0.1), float('nan'))):
        cmd, st = mgr.step(0.0, _both(0.0, bdot=[0.5, 0.5, 0.5]), est, estimate_t=stamp)
        assert st['source'] == 'bdot' and st['estimate_fault']
        assert np.all(np.isfinite(cmd.dipole_body))
        assert np.all(np.abs(cmd.dipole_body) <= [1.0, 2.0, 3.0])


def test_stale_estimate_holds_the_automatic_sequence():
    mgr = _mgr(initial=None, estimate_period_s=DT,
               auto=AutoSequence(confirm_frames=2))
    for k in range(5):                       # slow rate, but the estimate is stale
        t = k * DT
        mgr.step(t, _both(t), _est(0.1), estimate_t=-10.0)
    assert mgr.mode == 'detumble' and mgr.active == 'bdot'
    mgr.step(10.0, _both(10.0), _est(0.1), estimate_t=10.0)     # fresh: counts start
    mgr.step(12.0, _both(12.0), _est(0.1), estimate_t=12.0)
    assert mgr.mode == 'acquire'


def test_estimate_users_must_be_known():
    with pytest.raises(ValueError, match='estimate_users'):
        _mgr(estimate_users=['fuzzy'])
    with pytest.raises(ValueError, match='estimate_period_s'):
        _mgr(estimate_period_s=-1.0)


# ---------------------------------------------------------------------------- start-up
def test_start_up_frames_before_the_first_command_are_not_missed():
    """Sample timing: the first command needs the chain's periods to come through; frames
    within ``startup_s`` of the first one that forward nothing are start-up frames (the
    command is still zero or the fallback's), later ones are missed."""
    mgr = _mgr(startup_s=3 * DT)
    for k in range(3):                          # t = 0, 2, 4: no command yet
        cmd, st = mgr.step(k * DT, {})
        assert _source(cmd) == 'zero'
    assert st['startup_frames'] == 3 and st['missed_frames'] == 0
    cmd, st = mgr.step(3 * DT, _both(3 * DT))   # t = 6 = startup_s: the first command
    assert _source(cmd) == 'magnetic' and st['missed_frames'] == 0
    cmd, st = mgr.step(4 * DT, {'bdot': (4 * DT, _cmd(BDOT))})   # a gap after it: missed
    assert _source(cmd) == 'bdot' and st['missed_frames'] == 1 and st['startup_frames'] == 3


def test_a_chain_that_never_delivers_is_missed_after_the_start_up():
    mgr = _mgr(startup_s=2 * DT)
    for k in range(6):
        _, st = mgr.step(k * DT, {})
    assert st['startup_frames'] == 3 and st['missed_frames'] == 3     # t = 0, 2, 4 | 6, 8, 10


def test_lockstep_counts_every_frame_from_the_first():
    _, st = _mgr().step(0.0, {})
    assert st['missed_frames'] == 1 and st['startup_frames'] == 0
    with pytest.raises(ValueError, match='startup_s'):
        _mgr(startup_s=-1.0)
