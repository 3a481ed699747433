"""The launcher stops the recorder only once its bag has every message (no lost data).

After the graph stops, the recorder's ``recorder/status`` (its message count) comes from its
wall timer only, every 0.5 s. The launcher used to wait a fixed 0.3 s for the count to
change: that window could fall between two statuses while the recorder was still writing a
backlog, and the recorder was then stopped with messages still queued. The rule now: two
statuses in a row carry the same count. The truth is a scripted status stream (a fake spin
delivers it; a fake monotonic clock advances 0.1 s a spin).
"""
from types import SimpleNamespace

import adcs_nodes.tools.run.launcher.monitor as launcher
from adcs_nodes.tools.run.launcher.monitor import Monitor as _Monitor


def _monitor(script, clock):
    """A stand-in for ``_Monitor`` whose spin delivers ``script``'s next entry (a message
    count from a recorder status, or None: no status during that spin)."""
    mon = SimpleNamespace(recorder_statuses=0, recorder_count=0, spins=0)

    def spin(seconds):
        clock[0] += seconds
        mon.spins += 1
        count = script.pop(0) if script else None
        if count is not None:
            mon.recorder_count = count
            mon.recorder_statuses += 1
    mon.spin = spin
    return mon


def _fake_clock(monkeypatch):
    clock = [1000.0]
    monkeypatch.setattr(launcher.time, 'monotonic', lambda: clock[0])
    return clock


def test_settles_only_after_two_statuses_with_the_same_count(monkeypatch):
    clock = _fake_clock(monkeypatch)
    # statuses every 5 spins (0.5 s); the backlog is written while no status comes
    script = [None] * 4 + [500] + [None] * 4 + [900] + [None] * 4 + [1200] + [None] * 4 + [1200]
    mon = _monitor(list(script), clock)
    assert _Monitor.wait_recorder_settled(mon, clock[0] + 10.0)
    assert mon.spins == len(script)              # returned at the second 1200, not before
    assert mon.recorder_count == 1200


def test_a_count_that_keeps_growing_ends_at_the_deadline(monkeypatch):
    clock = _fake_clock(monkeypatch)
    mon = _monitor([n * 10 for n in range(1, 1000)], clock)
    t0 = clock[0]
    assert not _Monitor.wait_recorder_settled(mon, t0 + 2.0)
    assert 2.0 <= clock[0] - t0 < 2.2


def test_a_silent_recorder_ends_at_the_deadline(monkeypatch):
    clock = _fake_clock(monkeypatch)
    mon = _monitor([], clock)
    t0 = clock[0]
    assert not _Monitor.wait_recorder_settled(mon, t0 + 1.0)
    assert 1.0 <= clock[0] - t0 < 1.2
