"""What a lockstep node reports: its counts, its run summary, its timing diagnostics, and
when its ``lockstep/status`` and ``lockstep/progress`` are due.

Pure Python, no ROS: the node adapter gives sim times [ns] (elapsed), wall times [s] and the
readers of its status topic, and publishes what is due.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, Iterable, List, Optional

from adcs_nodes.core.lockstep import PROGRESS_EVERY

#: The launcher's progress monitor (``tools.run.launcher``): its node name, and the one node
#: whose ``lockstep/status`` it takes (content filter ``node = %0 OR missed_frames > 0``).
MONITOR_NODE, MONITOR_STATUS_OF = 'adcs_launcher', 'dynamics'
#: Wall time [s] between the periodic statuses of a node whose only reader is the monitor.
MONITOR_STATUS_WALL_S = 0.1
#: Wall time [s] without a frame after which a stalled node reports once a second.
STALLED_S = 2.0


class SampleCounts:
    """What a node did with its samples: rejected by reason (and the last reason), samples
    superseded before use, samples used per input (each new stamp once)."""

    def __init__(self, reasons: Iterable[str]) -> None:
        self.rejected: Dict[str, int] = {r: 0 for r in reasons}
        self.last_rejected = ''
        self.superseded = 0
        self.used: Dict[str, int] = {}
        self._mark: Dict[str, int] = {}

    def reject(self, reason: str, where: str, text: str) -> str:
        """Count a rejected sample of ``where`` (a topic); returns the line to log."""
        self.rejected[reason] += 1
        self.last_rejected = f'{where}: {text}'
        return (f'sample rejected ({reason}): {self.last_rejected} '
                f'(rejected so far: {sum(self.rejected.values())})')

    def use(self, name: str, stamp_ns: Optional[int] = None) -> None:
        """A sample of ``name`` used; with ``stamp_ns``, only a stamp newer than the last."""
        if stamp_ns is not None:
            if stamp_ns <= self._mark.get(name, -1):
                return
            self._mark[name] = stamp_ns
        self.used[name] = self.used.get(name, 0) + 1


def run_summary(frames: int, missed: int, counts: SampleCounts, used: Dict[str, int],
                topics: Dict[str, str], starved: Dict[str, Dict[str, Any]],
                extra_rejected: Optional[Dict[str, int]] = None,
                resets: Optional[int] = None) -> Dict[str, Any]:
    """The run summary of a node (logged as JSON at its last frame; ``adcs run`` prints it):
    frames, missed frames, samples used per topic, rejected by reason (the timing reasons and
    the component's own ``extra_rejected``), superseded, filter resets, starved inputs."""
    rejected = {r: n for r, n in counts.rejected.items() if n}
    for r, n in (extra_rejected or {}).items():
        if n:
            rejected[r] = rejected.get(r, 0) + int(n)
    return {'frames': int(frames), 'missed_frames': int(missed),
            'samples_used': {topics.get(n, n): int(v) for n, v in sorted(used.items())},
            'rejected': rejected, 'superseded': int(counts.superseded),
            'resets': None if resets is None else int(resets),
            'starved': {topics.get(n, n): {'since_s': e['since_s'], 'frames': int(e['frames'])}
                        for n, e in sorted(starved.items())}}


def timing_values(mode: str, frames: int, missed: int, last_missed: str, dead: List[str],
                  counts: SampleCounts, starved: Dict[str, Dict[str, Any]],
                  topics: Dict[str, str]) -> Dict[str, str]:
    """Key-value timing health for ``/diagnostics``."""
    out = {'timing_mode': mode, 'frames': str(frames), 'missed_frames': str(missed),
           'last_missed_input': last_missed, 'dead_inputs': ', '.join(dead),
           'rejected_samples': str(sum(counts.rejected.values())),
           'last_rejected_sample': counts.last_rejected}
    out.update({f'rejected_{r}': str(v) for r, v in counts.rejected.items()})
    out['superseded_samples'] = str(counts.superseded)
    out['starved_inputs'] = ', '.join(topics.get(n, n) for n, e in starved.items()
                                      if not e.get('over', False))
    return out


class StatusPacer:
    """When ``lockstep/progress`` and ``lockstep/status`` are due.

    Progress: every :data:`PROGRESS_EVERY` base frames of sim time seen, and at the last
    frame (the clock master's flow control). Status: once per ``status_period_ns`` of sim
    time and at the last frame; a periodic one is held back while the launcher's monitor is
    the only reader and the last one is less than :data:`MONITOR_STATUS_WALL_S` old, and not
    sent at all to nobody or to a monitor whose filter drops it (:meth:`wanted`).
    """

    def __init__(self, name: str, frame_ns: int, status_period_ns: int, now_s: float) -> None:
        self.name, self.frame_ns, self.status_period_ns = name, frame_ns, status_period_ns
        self.progress_mark = self.status_mark = -1
        self.last_wall = now_s
        self.final_sent = False
        self.readers_n, self.readers_known, self.monitor_only = -1, False, False
        self.recheck_at = 0.0

    def progress_due(self, seen_ns: int, final: bool) -> bool:
        """Whether a progress report for sim time ``seen_ns`` is due (and mark it sent)."""
        mark = seen_ns // (PROGRESS_EVERY * self.frame_ns)
        if mark == self.progress_mark and not final:
            return False
        self.progress_mark = mark
        return True

    def status_due(self, t_ns: int, final: bool, missed: int, readers: Callable[[], int],
                   now_s: float) -> bool:
        """Whether the status after frame ``t_ns`` is due (and mark it); ``readers()``: the
        status topic's subscription count."""
        mark = t_ns // self.status_period_ns
        held = (self.monitor_only and not missed and now_s - self.last_wall
                < MONITOR_STATUS_WALL_S and readers() == self.readers_n)
        if final or (mark != self.status_mark and not held):
            self.status_mark = mark
            return True
        return False

    def stalled(self, now_s: float) -> bool:
        """True when no status went out for :data:`STALLED_S` of wall time."""
        return now_s - self.last_wall >= STALLED_S

    def wanted(self, readers: int, names: Callable[[], List[str]], missed: int,
               now_s: float) -> bool:
        """Whether a status now would reach a reader: nobody subscribes (the topic is
        volatile), or only the monitor whose filter drops it (not the node it follows, no
        missed frames): no. ``names()`` gives the readers' node names; it is asked again when
        their count changes, and every 0.2 s while discovery has not named all of them."""
        if not readers:
            return False
        if missed:
            return True
        if readers != self.readers_n or (not self.readers_known and now_s >= self.recheck_at):
            got = names()
            known = len(got) == readers and all(
                n and not n.startswith('_NODE_NAME_UNKNOWN') for n in got)
            self.monitor_only = known and all(n == MONITOR_NODE for n in got)
            self.readers_n, self.readers_known = readers, known
            self.recheck_at = now_s + 0.2
        return not self.monitor_only or self.name == MONITOR_STATUS_OF
