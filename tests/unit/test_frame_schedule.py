"""The frame schedule of a lockstep consumer (``adcs_nodes.core.frame_schedule``) without ROS.

Expected frames are worked out by hand from the timing model (DESIGN section 6): a node of
period P fires t = 0, P, 2P, ... once time has reached t and every due input is there, or
after ``timeout_s`` of wall time without it; a node that rejoins a run fires first at the
first frame after the time it saw (plus the margin) whose awaited inputs all come after.
"""
import pytest

from adcs_nodes.core.frame_schedule import LIVE, LOCKSTEP, NEVER, FrameSchedule, timing_mode
from adcs_nodes.core.lockstep import FrameSync

S = 1_000_000_000


def _fired(sched, now=0.0):
    out = []
    while (t := sched.next_ready(now)) is not None:
        out.append(t)
        sched.take(t)
    return out


def test_frames_fire_in_order_when_time_and_inputs_have_come():
    sync = FrameSync({'mag': 2 * S, 'cmd': (S, 'previous')})
    sched = FrameSchedule(sync, S, timeout_s=5.0)
    assert _fired(sched) == []                      # no time seen: nothing
    sched.see(0)
    sync.add('mag', 0, 'm0')
    assert _fired(sched) == [0]                     # t=0: mag due, cmd (previous) not yet
    sched.see(S)
    assert _fired(sched) == []                      # t=1 s: cmd stamped 0 is due
    sync.add('cmd', 0, 'c0')
    assert _fired(sched) == [S]
    sync.add('cmd', S, 'c1')
    sync.add('mag', 2 * S, 'm2')
    sched.see(3 * S)                                # time jumps: 2 s ready, 3 s needs cmd(2)
    assert _fired(sched) == [2 * S]
    assert sched.next_ns == 3 * S and sched.wait_since == 0.0


def test_a_missing_input_times_out_once_and_dies_after_dead_after_misses():
    sync = FrameSync({'mag': S}, dead_after=2)
    sched = FrameSchedule(sync, S, timeout_s=5.0)
    sched.see(10 * S)
    assert sched.next_ready(100.0) is None and sched.wait_since == 100.0
    assert sched.timed_out(104.9) is None           # not yet 5 s
    assert sched.timed_out(105.0) == (0, ['mag'], [])
    assert sched.take(0) == {'mag': None}
    assert sched.next_ready(106.0) is None          # the wait of frame 1 starts afresh
    assert sched.timed_out(111.0) == (S, ['mag'], ['mag'])     # second miss: dead
    sched.take(S)
    assert _fired(sched) == list(range(2 * S, 11 * S, S))   # dead: no longer awaited


def test_real_time_flight_software_does_not_wait():
    sched = FrameSchedule(FrameSync({'mag': S}), S, timeout_s=5.0, wait_inputs=False)
    sched.see(2 * S)
    assert _fired(sched) == [0, S, 2 * S]


def test_a_rejoining_node_starts_after_the_time_it_saw_not_at_zero():
    # a 2 s controller of a 1 s estimate, rejoining while the world is at 20600 s
    sync = FrameSync({'est': S, 'cmd': (2 * S, 'previous')})
    sched = FrameSchedule(sync, 2 * S, timeout_s=5.0, rejoin=True, margin_ns=S)
    sched.see(20600 * S)
    assert _fired(sched) == []                      # endpoints not matched yet: nothing
    sched.arm()
    # first frame after 20601 s: 20602 s needs cmd(20600), heard before: skipped; 20604 s
    # needs cmd(20602) and est(20604), both after 20601 s
    assert sched.next_ns == 20604 * S and sched.rejoined_at == 20604 * S
    sync.add('est', 20604 * S, 'e')
    sync.add('cmd', 20602 * S, 'c')
    sched.see(20604 * S)
    assert _fired(sched) == [20604 * S]


def test_a_rejoin_armed_before_any_time_takes_the_next_time_seen():
    sched = FrameSchedule(FrameSync({'mag': S}), S, timeout_s=5.0, rejoin=True)
    sched.arm()
    assert sched.rejoining and _fired(sched) == []
    sched.see(7 * S + S // 2)
    assert sched.next_ns == 8 * S and not sched.rejoining


def test_stop_means_no_frame_ever_again():
    sync = FrameSync({'mag': S})
    sched = FrameSchedule(sync, S, timeout_s=5.0, wait_inputs=False)
    sched.see(3 * S)
    sched.stop()
    assert sched.next_ns == NEVER and _fired(sched) == []
    assert sched.timed_out(1e9) is None


@pytest.mark.parametrize('given, world, launched, real_time, want', [
    ('', False, False, False, LIVE),           # started alone
    ('', False, True, False, LOCKSTEP),        # launcher parameters given
    ('', False, False, True, LOCKSTEP),        # --real-time
    ('live', False, True, False, LIVE),        # explicit wins
    ('', True, False, False, LOCKSTEP),        # the simulated world: always lockstep
])
def test_timing_mode(given, world, launched, real_time, want):
    assert timing_mode('n', given, world, launched, real_time) == want


def test_timing_mode_refusals_name_the_value_and_the_node():
    with pytest.raises(ValueError, match="'fast'"):
        timing_mode('n', 'fast', False, False, False)
    with pytest.raises(ValueError, match='dynamics is part of the simulated world'):
        timing_mode('dynamics', 'live', True, False, False)
