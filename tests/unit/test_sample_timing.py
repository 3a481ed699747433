"""The sample-timing rule (``adcs_nodes.core.sample_timing``) without ROS: each sample checked
once on arrival, used once at its own stamp in stamp order by the first frame that covers it,
refused and named otherwise. The node-level behaviour (a driver process, a launched run) is in
tests/node/test_external_inputs.py and tests/graph/test_external_driver.py."""
from adcs_nodes.core.sample_timing import REASONS, ExternalInputs, admit

S = 1_000_000_000
EPOCH = 1_767_225_600 * S


def test_admit_names_each_refusal_and_accepts_at_the_limits():
    future, age = S // 2, 5 * S
    now = EPOCH + 100 * S
    assert admit(0, now, None, future, age)[0] == 'zero_stamp'
    assert admit(now + future + 1, now, None, future, age)[0] == 'future'
    assert admit(now + future, now, None, future, age) is None           # at the limit
    assert admit(now - age - 1, now, None, future, age)[0] == 'too_old'
    assert admit(now - age, now, None, future, age) is None
    assert admit(now - S, now, now - S, future, age)[0] == 'out_of_order'   # a duplicate
    assert admit(now - 2 * S, now, now - S, future, age)[0] == 'out_of_order'
    assert admit(now - S // 2, now, now - S, future, age) is None
    # no clock yet (live, use_sim_time before /clock): only the stamp itself is checked
    assert admit(now + 10 ** 6 * S, 0, None, future, age) is None
    assert 'ahead of the clock' in admit(now + S, now, None, future, age)[1]


def _queue(period=S):
    return ExternalInputs({'mag': S, 'sun': S}, {}, period, 3, EPOCH, max_future_ns=S // 2,
                          max_age_ns=5 * S, counts=_counts())


def _offer(q, name, t, now_t, msg=None):
    return q.offer(name, EPOCH + t, now_t, msg if msg is not None else (name, t))


def test_a_frame_takes_the_samples_one_period_before_it_in_stamp_order_once():
    q = _queue()
    assert _offer(q, 'mag', int(0.3 * S), S) is None
    assert _offer(q, 'sun', int(0.2 * S), S) is None
    assert _offer(q, 'mag', int(1.4 * S), 2 * S) is None     # after the next frame's cover
    got = q.take(2 * S)                                       # covers stamps <= 1 s
    assert [(t, n) for t, n, _ in got] == [(int(0.2 * S), 'sun'), (int(0.3 * S), 'mag')]
    assert q.take(2 * S) == []                                # each sample once
    assert [(t, n) for t, n, _ in q.take(3 * S)] == [(int(1.4 * S), 'mag')]
    assert q.last_usable('mag') == int(1.4 * S) and q.last_usable('sun') == int(0.2 * S)


def test_a_sample_after_the_frame_that_covered_its_stamp_is_late_and_never_used():
    q = _queue()
    q.take(3 * S)                                             # frame 3 s covered <= 2 s
    why = _offer(q, 'mag', int(1.9 * S), 3 * S)
    assert why[0] == 'late'
    assert q.last_usable('mag') is None
    assert _offer(q, 'mag', int(2.1 * S), 3 * S) is None      # the next one is on time
    assert [t for t, _, _ in q.take(4 * S)] == [int(2.1 * S)]


def test_the_future_limit_allows_one_own_period_of_clock_lag():
    q = _queue(period=S)                    # limit 0.5 s + the node's 1 s period
    assert _offer(q, 'mag', 11 * S + S // 2, 10 * S) is None
    assert _offer(q, 'sun', 11 * S + S // 2 + 1, 10 * S)[0] == 'future'


def test_every_refusal_reason_is_one_of_the_counted_reasons():
    q = _queue()
    seen = {q.offer('mag', 0, S, None)[0]}                     # stamped zero
    seen.add(_offer(q, 'mag', 100 * S, S)[0])
    seen.add(_offer(q, 'mag', S, 100 * S)[0])
    _offer(q, 'sun', 5 * S, 5 * S)
    seen.add(_offer(q, 'sun', 5 * S, 5 * S)[0])
    q.take(10 * S)
    seen.add(_offer(q, 'sun', 8 * S, 10 * S)[0])
    assert seen == set(REASONS)


def _counts():
    from adcs_nodes.core.run_status import SampleCounts
    return SampleCounts(REASONS)


def test_live_ticks_take_the_newest_stamp_and_never_a_late_trigger():
    from adcs_nodes.core.sample_timing import LiveSamples
    c = _counts()
    live = LiveSamples(['mag', 'cmd'], ['mag'], EPOCH, S // 2, 5 * S, S // 20, c)
    now = EPOCH + 100 * S
    assert live.choose(0) == (None, [])                       # no clock yet
    assert live.offer('mag', now - 2 * S, now, 'a') is None
    assert live.offer('mag', now - S, now, 'b') is None       # replaces 'a' unread
    assert c.superseded == 1
    t, late = live.choose(now)
    assert (t, late) == (99 * S, [])                          # at the newest trigger stamp
    assert live.take(t, now) == {'mag': 'b', 'cmd': None}
    assert live.fresh('mag', now - S)                         # no frame before
    live.offer('mag', now - S // 2, now, 'c')
    t2, _ = live.choose(now)
    assert t2 == 99 * S + S // 2 and live.take(t2, now)['mag'] == 'c'
    assert not live.fresh('mag', now - S) and live.fresh('mag', now - S // 2)
    # nothing new: the clock's time minus the latency; a trigger stamped before it is late
    t3, _ = live.choose(now + S)
    assert t3 == 101 * S - S // 20
    live.take(t3, now + S)
    live.offer('mag', now + S // 4, now + S, 'late one')      # newer than 'c', before t3
    t4, late = live.choose(now + 2 * S)
    assert late == ['mag'] and live.take(t4, now + 2 * S)['mag'] == 'c'


def test_external_inputs_count_use_supersede_and_starve_by_episode():
    from adcs_nodes.core.sample_timing import ExternalInputs
    c = _counts()
    ext = ExternalInputs({'mag': 10 * S}, {'mag': '/sensors/magnetometer'}, 2 * S, 3, EPOCH,
                         S // 2, 100 * S, c)
    for k in range(16):                                       # 0 .. 30 s: within 3 x 10 s
        ext.after_frame(2 * k * S, {})
        assert ext.check_starved(2 * k * S) == []
    level, text = ext.check_starved(32 * S)[0]
    assert level == 'error' and '/sensors/magnetometer' in text and 'starved' in text
    assert ext.check_starved(34 * S) == [] and ext.starved['mag']['frames'] == 2
    for s in (33, 34, 35):                                    # three samples before 36 s
        assert ext.offer('mag', EPOCH + s * S, 35 * S, s) is None
    ext.after_frame(36 * S, {'mag': EPOCH + 33 * S})          # the frame read the first
    ext.after_frame(38 * S, {})                               # 34 s never read: superseded
    assert c.used == {'mag': 1} and c.superseded == 0
    assert ext.check_starved(38 * S) == [('info', '/sensors/magnetometer: usable samples '
                                          'again at t=38 s')]
    assert ext.fresh('mag', EPOCH + 34 * S) and not ext.fresh('mag', EPOCH + 33 * S)
    # a consumer's own usability (a NaN sample is not usable): starved again from 0
    assert ext.check_starved(40 * S, lambda name: None)[0][0] == 'error'
    assert ext.starved['mag']['episodes'] == 2
