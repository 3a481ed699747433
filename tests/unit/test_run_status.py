"""Counts, run summary, diagnostics and the pacing of ``lockstep/status`` and
``lockstep/progress`` (``adcs_nodes.core.run_status``) without ROS: the expected values are
counted by hand from the events fed in."""
from adcs_nodes.core.lockstep import PROGRESS_EVERY
from adcs_nodes.core.run_status import (MONITOR_NODE, MONITOR_STATUS_OF, MONITOR_STATUS_WALL_S,
                                        SampleCounts, StatusPacer, run_summary, timing_values)

S = 1_000_000_000


def test_counts_summary_and_diagnostics_say_what_happened():
    c = SampleCounts(('late', 'future'))
    for stamp in (0, 0, S, S, 2 * S):          # a frame input read by 5 frames: 3 new stamps
        c.use('mag', stamp)
    c.use('gyro')
    line = c.reject('late', '/sensors/gyro', 'arrived after its frame')
    assert line == ('sample rejected (late): /sensors/gyro: arrived after its frame '
                    '(rejected so far: 1)')
    c.superseded += 2
    starved = {'gyro': {'since_s': 4.0, 'frames': 3, 'over': False}}
    topics = {'mag': '/sensors/magnetometer', 'gyro': '/sensors/gyro'}
    out = run_summary(7, 1, c, c.used, topics, starved, {'check': 2, 'late': 1}, resets=0)
    assert out == {'frames': 7, 'missed_frames': 1,
                   'samples_used': {'/sensors/gyro': 1, '/sensors/magnetometer': 3},
                   'rejected': {'late': 2, 'check': 2}, 'superseded': 2, 'resets': 0,
                   'starved': {'/sensors/gyro': {'since_s': 4.0, 'frames': 3}}}
    d = timing_values('lockstep', 7, 1, 'mag', ['/sensors/magnetometer'], c, starved, topics)
    assert (d['rejected_samples'], d['rejected_late'], d['rejected_future']) == ('1', '1', '0')
    assert d['starved_inputs'] == '/sensors/gyro' and d['dead_inputs'] == '/sensors/magnetometer'
    starved['gyro']['over'] = True
    assert timing_values('live', 0, 0, '', [], c, starved, topics)['starved_inputs'] == ''


def test_progress_every_progress_every_frames_and_at_the_end():
    p = StatusPacer('estimator', S, S, now_s=0.0)
    due = [t for t in range(0, 35 * S, S) if p.progress_due(t, final=False)]
    assert due == [0, PROGRESS_EVERY * S, 2 * PROGRESS_EVERY * S, 3 * PROGRESS_EVERY * S]
    assert not p.progress_due(31 * S, final=False) and p.progress_due(31 * S, final=True)


def test_status_once_per_period_held_only_for_the_monitor_alone():
    p = StatusPacer('estimator', S // 10, S, now_s=0.0)
    readers = lambda: 1                              # noqa: E731
    due = [t for t in range(0, 3 * S, S // 10) if p.status_due(t, False, 0, readers, 0.0)]
    assert due == [0, S, 2 * S]                      # 0.1 s frames, 1 s period
    # the only reader is the monitor (known by name) and this node is not the one it follows
    assert not p.wanted(1, lambda: [MONITOR_NODE], missed=0, now_s=0.0)
    assert p.wanted(1, lambda: [MONITOR_NODE], missed=1, now_s=0.0)      # missed frames: kept
    p.last_wall = 10.0
    assert not p.status_due(3 * S, False, 0, readers, 10.0 + MONITOR_STATUS_WALL_S / 2)
    assert p.status_due(3 * S, False, 0, readers, 10.0 + 2 * MONITOR_STATUS_WALL_S)
    assert p.status_due(3 * S, True, 0, readers, 10.0)                  # the final one: always
    master = StatusPacer(MONITOR_STATUS_OF, S, S, now_s=0.0)
    assert master.wanted(1, lambda: [MONITOR_NODE], missed=0, now_s=0.0)
    assert not master.wanted(0, lambda: [], missed=5, now_s=0.0)        # nobody reads


def test_unnamed_readers_are_asked_again_and_count_as_someone_else():
    p = StatusPacer('estimator', S, S, now_s=0.0)
    asked = []

    def names():
        asked.append(1)
        return ['_NODE_NAME_UNKNOWN_'] if len(asked) == 1 else [MONITOR_NODE]
    assert p.wanted(1, names, 0, now_s=0.0)          # unknown: publish
    assert p.wanted(1, names, 0, now_s=0.1) and len(asked) == 1    # not asked again so soon
    assert not p.wanted(1, names, 0, now_s=0.2) and len(asked) == 2
    assert p.stalled(2.0) and not p.stalled(1.9)
