"""Launcher summary of a degraded run (issue 12): a run that lost its controller or estimator
for part of the time says so and ends with exit code 3, not "done"."""
from types import SimpleNamespace

from adcs_nodes.tools.run.launcher import EXIT_DEGRADED
from adcs_nodes.tools.run.launcher.monitor import Monitor as _Monitor
from adcs_nodes.tools.run.launcher.result import degraded_text


def _degraded(lost=(), lost_at=None, status=None):
    return degraded_text({}, {n: (lost_at or {}).get(n, 0.0) for n in lost}, {}, 0.0, status)


def test_clean_run_is_not_degraded():
    assert _degraded() == ''
    assert _degraded(status=SimpleNamespace(missed_frames=0, last_fault='')) == ''


def test_dead_node_and_manager_fallback_are_reported():
    text = _degraded(lost=['estimator'], lost_at={'estimator': 42.0})
    assert 'lost estimator (died at sim t = 42 s)' in text
    text = _degraded(status=SimpleNamespace(missed_frames=7, last_fault='magnetic: estimator '
                                            'stale: no estimate received; fallback to bdot'))
    assert '7 frames' in text and 'fallback to bdot' in text
    assert EXIT_DEGRADED == 3


def test_total_missed_frames_is_the_highest_count_of_each_node():
    mon = SimpleNamespace(max_missed={}, status={})
    for node, missed in (('dynamics', 3), ('dynamics', 1), ('estimator', 240)):
        _Monitor._on_status(mon, SimpleNamespace(node=node, missed_frames=missed))
    assert _Monitor.missed_frames.fget(mon) == 243
