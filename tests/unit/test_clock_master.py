"""The clock master's frame state machine without DDS: frame order, zero command on timeout,
dead command producer after N misses, flow control, end of run.

Wall time is injected (``now``), so every timeout is exercised without sleeping.
"""
import pytest

from adcs_nodes.core.lockstep import ZERO, Act, ClockMaster, MasterPhase

S = 1_000_000_000


def kinds(actions):
    return [(a.kind, a.t_ns // S) for a in actions]


def steps(actions):
    return [(a.t_ns // S, a.value[1]) for a in actions if a.kind is Act.STEP]


def test_free_body_frames_in_order_and_done_at_the_duration():
    m = ClockMaster(S, duration_ns=2 * S)
    out = m.start(now=0.0)
    assert kinds(out) == [(Act.CLOCK, 0)] and m.phase is MasterPhase.WAIT_ENV
    out = m.on_environment(0, 'e0', now=0.0)
    assert kinds(out) == [(Act.STATE, 0), (Act.STEP, 0), (Act.CLOCK, 1)]
    assert out[1].value == ('e0', None)            # no command: hold (the zero start)
    m.on_environment(S, 'e1', now=0.0)
    out = m.on_environment(2 * S, 'e2', now=0.0)
    assert kinds(out) == [(Act.STATE, 2), (Act.FINISH, 2)]   # no node to wait for
    assert m.phase is MasterPhase.DONE and m.missed_frames == 0


def test_waits_for_the_command_due_then_holds_it_between_command_frames():
    m = ClockMaster(S, command_period_ns=2 * S)
    m.start(0.0)
    out = m.on_environment(0, 'e0', 0.0)
    assert kinds(out) == [(Act.STATE, 0)] and m.phase is MasterPhase.WAIT_CMD
    m.on_command(2 * S, 'c2', 0.0)                 # early command of frame 2 does not count
    assert m.phase is MasterPhase.WAIT_CMD
    out = m.on_command(0, 'c0', 0.0)
    assert steps(out) == [(0, 'c0')]
    out = m.on_environment(S, 'e1', 0.0)           # frame 1: no command due -> hold
    assert steps(out) == [(1, None)]
    out = m.on_environment(2 * S, 'e2', 0.0)       # frame 2: c2 arrived early, used now
    assert steps(out) == [(2, 'c2')]


def test_missing_command_gives_a_zero_command_after_the_timeout_and_says_so():
    m = ClockMaster(S, command_period_ns=S, timeout_s=10.0)
    m.start(0.0)
    m.on_environment(0, 'e0', 0.0)
    assert m.tick(9.9) == []                       # not yet
    out = m.tick(10.0)
    missed = [a for a in out if a.kind is Act.MISSED]
    assert missed[0].value == ['adcs/actuator_command']
    assert 'zero command' in missed[0].text and 'last value' not in missed[0].text
    assert steps(out) == [(0, ZERO)] and m.missed_frames == 1


def test_dead_manager_costs_n_timeouts_then_no_wait_until_it_publishes_again():
    """Issue 12: a killed controller_manager made dynamics wait 2 x timeout every frame."""
    m = ClockMaster(S, command_period_ns=S, timeout_s=10.0, dead_after=3)
    now = 0.0
    m.start(now)
    m.on_environment(0, 'e0', now)
    m.on_command(0, 'c0', now)
    waited = 0.0
    for k in range(1, 21):                          # the manager died after frame 0
        out = m.on_environment(k * S, f'e{k}', now)
        if m.phase is MasterPhase.WAIT_CMD:         # still awaited: time out
            now += 10.0
            waited += 10.0
            out = m.tick(now)
        assert steps(out) == [(k, ZERO)]
    assert waited == 30.0                           # 3 timeouts, then 17 frames at once
    assert m.missed_frames == 3 and m.sync.is_dead('cmd')
    out = m.on_environment(21 * S, 'e21', now)
    assert steps(out) == [(21, ZERO)]
    logs = m.on_command(22 * S, 'c22', now)         # it publishes again ...
    assert any(a.kind is Act.LOG and 'again' in a.text for a in logs)
    out = m.on_environment(22 * S, 'e22', now)
    assert steps(out) == [(22, ZERO)]               # ... the reviving command is not applied
    m.on_environment(23 * S, 'e23', now)            # (it might have come after the step)
    assert m.phase is MasterPhase.WAIT_CMD          # ... and it is awaited again
    out = m.on_command(23 * S, 'c23', now)
    assert steps(out) == [(23, 'c23')]


def test_missing_environment_goes_on_with_the_last_one():
    m = ClockMaster(S, timeout_s=1.0)
    m.start(0.0)
    out = m.tick(1.5)                               # frame 0: nothing to go on with
    assert kinds(out) == [(Act.MISSED, 0), (Act.CLOCK, 0)] and m.phase is MasterPhase.WAIT_ENV
    m.on_environment(0, 'e0', 1.5)
    out = m.tick(3.0)                               # frame 1 never answered
    assert [a.value for a in out if a.kind is Act.STATE] == ['e0']
    assert steps(out) == [(1, None)] and m.missed_frames == 2


def test_flow_control_throttles_and_resumes_on_progress():
    m = ClockMaster(S, wait_for_nodes=['est', 'recorder'], max_lag_frames=2,
                    lag_frames={'recorder': 5}, timeout_s=1.0, no_final=['recorder'])
    m.start(0.0)
    for k in range(3):
        m.on_environment(k * S, 'e', 0.0)
    assert m.phase is MasterPhase.THROTTLED and m.t_ns == 3 * S and m.lagging() == 'est'
    assert m.on_progress('est', 0, False, 0.0) == []          # 3 frames behind: still
    assert m.phase is MasterPhase.THROTTLED and m.throttled_frames == 1
    out = m.on_progress('est', S, False, 0.0)                     # 2 behind: allowed
    assert kinds(out) == [(Act.CLOCK, 3)]
    m.on_progress('est', 10 * S, False, 0.0)
    for k in range(3, 6):                                         # recorder may lag 5
        m.on_environment(k * S, 'e', 0.0)
    assert m.phase is MasterPhase.THROTTLED and m.lagging() == 'recorder' and m.t_ns == 6 * S


def test_a_lagging_recorder_is_waited_for_patience_timeouts_then_not():
    # going on without the recorder loses what the publishers no longer keep: it is waited
    # for `patience` timeouts (a warning each), then the clock goes on with an error
    m = ClockMaster(S, wait_for_nodes=['recorder'], max_lag_frames=2, timeout_s=1.0,
                    no_final=['recorder'], always_wait=['recorder'], patience=3)
    m.start(0.0)
    for k in range(3):
        m.on_environment(k * S, 'e', 0.0)
    assert m.phase is MasterPhase.THROTTLED and m.lagging() == 'recorder'
    for now in (1.5, 3.0):                    # timeouts: a warning each, no frame, not gone
        out = m.tick(now)
        assert [a.kind for a in out] == [Act.LOG] and 'waiting for recorder' in out[0].text
        assert m.phase is MasterPhase.THROTTLED and not m.gone and m.t_ns == 3 * S
    out = m.on_progress('recorder', S // 2, False, 3.5)  # some progress: patience restarts
    assert out == [] and m.phase is MasterPhase.THROTTLED
    for now in (4.6, 5.7):
        assert 'waiting for recorder' in m.tick(now)[0].text
    out = m.tick(6.8)                                   # the third timeout in a row
    assert out[0].value == 'error' and 'misses' in out[0].text and m.gone == {'recorder'}
    assert kinds(out)[-1] == (Act.CLOCK, 3)
    out = m.on_progress('recorder', 2 * S, False, 7.0)   # reports again: waited for again
    assert not m.gone


def test_a_dead_lagging_node_does_not_stop_the_world():
    m = ClockMaster(S, duration_ns=100 * S, wait_for_nodes=['est', 'ctl'], max_lag_frames=1,
                    timeout_s=1.0)
    m.start(0.0)
    m.on_progress('ctl', 2 * S, False, 0.0)
    m.on_environment(0, 'e', 0.0)
    m.on_environment(S, 'e', 0.0)
    assert m.phase is MasterPhase.THROTTLED and m.throttled_frames == 1
    out = m.tick(1.0)
    assert kinds(out)[:2] == [(Act.LOG, 2), (Act.CLOCK, 2)]
    assert m.phase is MasterPhase.WAIT_ENV and m.gone == {'est'}
    # one timeout, not one per max_lag_frames: 'est' is not waited for any more ...
    m.on_progress('ctl', 100 * S, False, 1.0)
    for k in range(2, 100):
        m.on_environment(k * S, 'e', 1.0)
    assert m.t_ns == 100 * S and m.throttled_frames == 1
    m.on_environment(100 * S, 'e', 1.0)
    out = m.on_progress('ctl', 100 * S, True, 1.0)
    assert [a.kind for a in out] == [Act.FINISH]       # ... nor at the end
    m2 = ClockMaster(S, wait_for_nodes=['est'], max_lag_frames=1, timeout_s=1.0)
    m2.start(0.0)
    for k in range(2):
        m2.on_environment(k * S, 'e', 0.0)
    m2.tick(1.0)
    out = m2.on_progress('est', S, False, 1.0)         # it reports again: waited for again
    assert any(a.kind is Act.LOG and 'again' in a.text for a in out) and not m2.gone


def test_end_waits_for_final_progress_then_finishes():
    m = ClockMaster(S, duration_ns=S, wait_for_nodes=['est', 'recorder'],
                    no_final=['recorder'], timeout_s=1.0)
    m.start(0.0)
    m.on_progress('est', 0, False, 0.0)
    m.on_environment(0, 'e0', 0.0)
    out = m.on_environment(S, 'e1', 0.0)
    assert m.phase is MasterPhase.WAIT_FINAL and Act.FINISH not in [a.kind for a in out]
    out = m.on_progress('est', S, True, 0.0)
    assert [a.kind for a in out] == [Act.FINISH] and m.phase is MasterPhase.DONE
    m2 = ClockMaster(S, duration_ns=0, wait_for_nodes=['est'], timeout_s=1.0)
    assert m2.tick(100.0) == []                      # idle: nothing to time out


def test_end_waits_until_the_recorder_has_read_the_final_frame():
    # a clean-clone CI run lost the last 24 /clock messages of a bag: the master's process
    # ended while the recorder (allowed to lag) had not read them yet
    m = ClockMaster(S, duration_ns=2 * S, wait_for_nodes=['est', 'recorder'],
                    lag_frames={'recorder': 5}, no_final=['recorder'],
                    always_wait=['recorder'], patience=3, timeout_s=1.0)
    m.start(0.0)
    for k in range(3):
        m.on_progress('est', k * S, k == 2, 0.0)
        m.on_environment(k * S, 'e', 0.0)
    assert m.phase is MasterPhase.WAIT_FINAL          # est is final; the recorder read nothing
    out = m.tick(1.5)
    assert [a.kind for a in out] == [Act.LOG] and 'waiting for recorder' in out[0].text
    assert m.on_progress('recorder', S, False, 2.0) == []        # not the last frame yet
    out = m.on_progress('recorder', 2 * S, False, 2.1)
    assert [a.kind for a in out] == [Act.FINISH]
    # a recorder that never reads the end: `patience` timeouts, then the run finishes
    m2 = ClockMaster(S, duration_ns=S, wait_for_nodes=['recorder'], no_final=['recorder'],
                     always_wait=['recorder'], patience=2, timeout_s=1.0)
    m2.start(0.0)
    m2.on_progress('recorder', 0, False, 0.0)
    for k in range(2):
        m2.on_environment(k * S, 'e', 0.0)
    assert m2.phase is MasterPhase.WAIT_FINAL
    assert 'waiting for recorder' in m2.tick(1.1)[0].text
    out = m2.tick(2.2)
    assert kinds(out)[-1] == (Act.FINISH, 1) and 'recorder' in out[0].text


def test_bad_configuration_raises():
    with pytest.raises(ValueError, match='frame'):
        ClockMaster(0)
    with pytest.raises(ValueError, match='multiple'):
        ClockMaster(S, command_period_ns=S // 2)
    with pytest.raises(ValueError, match='timeout'):
        ClockMaster(S, timeout_s=0.0)
    with pytest.raises(ValueError, match='dead_after'):
        ClockMaster(S, dead_after=0)


def test_real_time_mode_steps_with_the_latest_inputs_without_waiting():
    m = ClockMaster(S, duration_ns=2 * S, command_period_ns=S)
    assert kinds(m.free_running_frame()) == [(Act.CLOCK, 0)]       # no environment yet
    m.on_environment(0, 'e0', 0.0)
    out = m.free_running_frame()
    assert kinds(out) == [(Act.CLOCK, 0), (Act.STATE, 0), (Act.STEP, 0)]
    assert out[2].value == ('e0', None)
    m.on_command(0, 'c0', 0.0)
    out = m.free_running_frame()                 # frame 1: the environment of 0, command c0
    assert out[2].value == ('e0', 'c0') and out[2].t_ns == S
    out = m.free_running_frame()
    assert kinds(out)[-1] == (Act.FINISH, 2) and m.free_running_frame() == []


def test_a_paced_run_starts_frame_k_no_earlier_than_k_paces_and_catches_up():
    m = ClockMaster(S, duration_ns=6 * S, pace_s=0.5)
    assert kinds(m.start(now=100.0)) == [(Act.CLOCK, 0)]      # frame 0 at once: the schedule
    out = m.on_environment(0, 'e0', now=100.1)
    assert kinds(out) == [(Act.STATE, 0), (Act.STEP, 0)]      # frame 1 not before 100.5
    assert m.phase is MasterPhase.PACED
    assert m.tick(100.4) == []
    assert kinds(m.tick(100.5)) == [(Act.CLOCK, 1)]
    m.on_environment(S, 'e1', now=100.6)
    # a late tick (a loaded machine): frame 2 was due at 101.0; at 102.2 frames 2, 3 and 4 are
    # all due, so they run back to back (the rate is kept on average), frame 5 waits again
    assert kinds(m.tick(102.2)) == [(Act.CLOCK, 2)]
    assert kinds(m.on_environment(2 * S, 'e2', now=102.2))[-1] == (Act.CLOCK, 3)
    assert kinds(m.on_environment(3 * S, 'e3', now=102.2))[-1] == (Act.CLOCK, 4)
    assert kinds(m.on_environment(4 * S, 'e4', now=102.3)) == [(Act.STATE, 4), (Act.STEP, 4)]
    assert m.phase is MasterPhase.PACED and kinds(m.tick(102.5)) == [(Act.CLOCK, 5)]
    # pacing is wall time only: the missed frames and the timeouts do not see it
    assert m.missed_frames == 0


def test_the_same_actions_paced_or_not():
    def actions(pace):
        m, now, out = ClockMaster(S, duration_ns=4 * S, command_period_ns=S, pace_s=pace), 0.0, []
        out += m.start(now)
        for k in range(5):
            while m.phase is MasterPhase.PACED:
                now += 0.25
                out += m.tick(now)
            out += m.on_environment(k * S, f'e{k}', now)
            if k < 4:
                out += m.on_command(k * S, f'c{k}', now)
        return [(a.kind, a.t_ns, a.value) for a in out], m.phase
    assert actions(0.0) == actions(1.0) and actions(1.0)[1] is MasterPhase.DONE
    with pytest.raises(ValueError, match='pace_s'):
        ClockMaster(S, pace_s=-1.0)
