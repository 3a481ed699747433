"""FrameSync and integer-nanosecond timing (DESIGN section 6), against hand-worked cases."""
import pytest

from adcs_nodes.core.lockstep import (FrameSync, derive_seed, ns_to_seconds, period_to_frames,
                                      seconds_to_ns)

S = 1_000_000_000


def test_seconds_ns_round_trip_is_exact_for_decimal_periods():
    assert seconds_to_ns(0.1) == 100_000_000
    assert seconds_to_ns(2.0) == 2 * S
    # 0.1 s summed 10 times as floats is not 1 s; as integer ns it is
    assert sum(seconds_to_ns(0.1) for _ in range(10)) == S
    assert ns_to_seconds(1_500_000_000) == 1.5


def test_period_must_be_a_multiple_of_the_frame():
    assert period_to_frames(10.0, seconds_to_ns(2.0)) == 5
    assert period_to_frames(0.3, seconds_to_ns(0.1)) == 3
    with pytest.raises(ValueError, match='multiple'):
        period_to_frames(2.5, seconds_to_ns(1.0))
    with pytest.raises(ValueError, match='positive'):
        period_to_frames(0.0, S)


def test_due_inputs_gate_the_frame_and_others_are_latest():
    # magnetometer every frame (1 s), command every 2 s
    sync = FrameSync({'mag': S, 'cmd': 2 * S})
    assert sync.missing(0) == ['mag', 'cmd']
    sync.add('mag', 0, 'm0')
    assert not sync.ready(0)
    sync.add('cmd', 0, 'c0')
    assert sync.ready(0)
    # t = 1 s: only mag is due; cmd is taken as latest (stamped 0)
    assert sync.missing(S) == ['mag']
    sync.add('mag', S, 'm1')
    assert sync.ready(S)
    assert sync.value('cmd', S) == 'c0'
    # t = 2 s: the old command does not satisfy the new due frame
    sync.add('mag', 2 * S, 'm2')
    assert sync.missing(2 * S) == ['cmd']


def test_early_message_waits_for_its_frame_and_stale_stamp_does_not_count():
    sync = FrameSync({'env': S})
    sync.add('env', 2 * S, 'e2')      # arrived early
    assert not sync.ready(S)          # a later stamp never satisfies an earlier frame
    assert sync.value('env', S) is None
    assert sync.ready(2 * S)
    assert sync.value('env', 3 * S) == 'e2'   # latest at or before


def test_zero_period_input_is_never_waited_for():
    sync = FrameSync({'env': S, 'cmd': 0})
    sync.add('env', 0, 'e')
    assert sync.ready(0)
    assert sync.value('cmd', 0) is None


def test_prune_keeps_the_newest_older_message():
    sync = FrameSync({'a': S})
    for k in range(5):
        sync.add('a', k * S, k)
    sync.prune(4 * S)
    assert sync.value('a', 3 * S) == 3
    assert sync.value('a', 1 * S) is None


def test_bad_declarations_raise():
    with pytest.raises(ValueError):
        FrameSync({'a': -1})
    with pytest.raises(KeyError):
        FrameSync({'a': S}).add('b', 0, 1)


def test_derived_seeds_are_stable_and_distinct():
    a = derive_seed(1, 'dynamics/disturbance')
    assert a == derive_seed(1, 'dynamics/disturbance')
    assert a != derive_seed(2, 'dynamics/disturbance')
    assert a != derive_seed(1, 'magnetometer')
    assert 0 <= a < 2 ** 64


# ------------------------------------------------------------------ previous-frame inputs
def test_previous_frame_input_is_awaited_with_the_stamp_before_t():
    # estimator every 2 s, command every 2 s: at t = 4 s it needs the command of t = 2 s
    sync = FrameSync({'mag': (10 * S, 'frame'), 'cmd': (2 * S, 'previous')})
    assert sync.required_stamp('cmd', 0) is None          # nothing before the first frame
    assert sync.required_stamp('cmd', 4 * S) == 2 * S
    assert sync.required_stamp('cmd', 5 * S) == 4 * S      # off-grid consumer frame
    assert sync.required_stamp('cmd', 12 * S) == 10 * S
    sync.add('mag', 0, 'm0')
    assert sync.ready(0) and sync.value('cmd', 0) is None
    sync.add('cmd', 0, 'c0')
    sync.add('cmd', 2 * S, 'c2')       # arrived early: must not be used for t = 2 s
    assert sync.ready(2 * S)
    assert sync.value('cmd', 2 * S) == 'c0'
    assert sync.missing(6 * S) == ['cmd']                  # c4 not there yet
    assert sync.value('cmd', 6 * S) is None                # never "whatever arrived"


def test_previous_input_with_a_slower_producer_keeps_the_held_command():
    # producer every 10 s, consumer every 2 s: t = 12..20 s all need the command of 10 s
    sync = FrameSync({'cmd': (10 * S, 'previous')})
    for k in range(3):
        sync.add('cmd', 10 * k * S, f'c{10 * k}')
    for t in (12, 14, 16, 18, 20):
        sync.prune((t - 2) * S)
        assert sync.value('cmd', t * S) == 'c10'
    assert sync.value('cmd', 22 * S) == 'c20'


def test_unknown_kind_and_latest_with_period_raise():
    with pytest.raises(ValueError, match='unknown input kind'):
        FrameSync({'a': (S, 'sometimes')})
    with pytest.raises(ValueError, match='period 0'):
        FrameSync({'a': (S, 'latest')})
    with pytest.raises(ValueError, match='dead_after'):
        FrameSync({'a': S}, dead_after=-1)


# ------------------------------------------------------------------ dead producers
def test_producer_dead_after_n_misses_in_a_row_and_revived_by_a_message():
    sync = FrameSync({'ctrl': S, 'mag': S}, dead_after=3)
    sync.add('mag', 0, 'm')
    assert sync.record_misses(0) == []            # 1st miss
    sync.add('ctrl', S, 'c1')                     # a message resets the count
    for k in range(1, 5):
        sync.add('mag', k * S, 'm')               # mag is never missed
    assert sync.record_misses(2 * S) == []        # 1
    assert sync.record_misses(3 * S) == []        # 2
    assert sync.record_misses(4 * S) == ['ctrl']  # 3 in a row: dead
    assert sync.is_dead('ctrl') and sync.dead() == ['ctrl']
    assert 'ctrl' not in sync.missing(5 * S) and not sync.due('ctrl', 5 * S)
    assert sync.add('ctrl', 5 * S, 'c5') is True  # revived ...
    assert sync.value('ctrl', 5 * S) == 'c1'      # ... by a message that is not used
    assert not sync.due('ctrl', 5 * S) and 'ctrl' not in sync.missing(5 * S)
    assert sync.due('ctrl', 6 * S) and sync.missing(6 * S) == ['ctrl', 'mag']
    assert sync.add('ctrl', 6 * S, 'c6') is False
    assert sync.value('ctrl', 6 * S) == 'c6'


def test_a_revived_input_is_dropped_and_not_awaited_for_the_hold():
    # the reviving message may arrive frames late (a node does not wait for a dead input):
    # within the hold nothing of it is stored or awaited, so frames there are the same whenever
    # it arrived
    sync = FrameSync({'st': S}, dead_after=1, revive_hold_ns=3 * S)
    sync.add('st', 0, 's0')
    assert sync.record_misses(S) == ['st']
    assert sync.add('st', 2 * S, 's2') is True            # revived at 2, held to 5
    for k in (3, 4, 5):
        assert sync.add('st', k * S, f's{k}') is False    # dropped
        assert not sync.due('st', k * S) and sync.value('st', k * S) == 's0'
    assert sync.due('st', 6 * S) and not sync.has('st', 6 * S)
    sync.add('st', 6 * S, 's6')
    assert sync.value('st', 6 * S) == 's6'
    with pytest.raises(ValueError, match='revive_hold_ns'):
        FrameSync({'a': S}, revive_hold_ns=-1)


def test_the_hold_covers_the_farthest_the_clock_master_runs_ahead():
    from adcs_nodes.core.lockstep import MAX_LAG_FRAMES, PROGRESS_EVERY, REVIVE_HOLD_FRAMES
    assert REVIVE_HOLD_FRAMES >= MAX_LAG_FRAMES + PROGRESS_EVERY


def test_dead_after_zero_never_gives_up():
    sync = FrameSync({'a': S})
    for k in range(10):
        assert sync.record_misses(k * S) == []
    assert sync.missing(10 * S) == ['a']


def test_take_is_a_frame_of_a_consumer_that_never_waits():
    """take: the missing inputs (misses counted), the values, then the older messages pruned,
    by hand: env every 10, the command of the frame before (period 20), dead after 2."""
    s = FrameSync({'env': 10, 'cmd': (20, 'previous')}, dead_after=2)
    s.add('env', 0, 'e0')
    assert s.take(0) == ({'env': 'e0', 'cmd': None}, [])       # no command before t = 0
    s.add('cmd', 0, 'c0')
    s.add('env', 10, 'e1')
    assert s.take(10) == ({'env': 'e1', 'cmd': 'c0'}, [])
    s.add('cmd', 20, 'c1')
    assert s.take(20) == ({'env': 'e1', 'cmd': 'c0'}, ['env'])  # env(20) absent: latest
    assert s.take(30) == ({'env': 'e1', 'cmd': 'c1'}, ['env'])  # second miss in a row
    assert s.is_dead('env') and not s.is_dead('cmd')
    assert s.take(40) == ({'env': 'e1', 'cmd': 'c1'}, [])       # dead env not awaited
    assert s.take(50) == ({'env': 'e1', 'cmd': None}, ['cmd'])  # no cmd(40): None, missed
    assert s._inputs['env'].stamps == [10]                      # pruned to the newest older
