"""The frame schedule of one lockstep consumer (DESIGN section 6) and its timing mode.

A consumer of period P fires frames t = 0, P, 2P, ... Frame t is considered once the sim time
it has seen (a ``/clock`` tick or an input stamped t or later) reaches t; it fires when every
input due then has arrived (:class:`~adcs_nodes.core.lockstep.FrameSync`, public API only),
or after ``timeout_s`` of wall time without them (a missed frame; ``dead_after`` misses in a
row make the producer dead, FrameSync's rule).

A node that (re)joins a run already going (a lifecycle cleanup and configure) does not start
at t = 0: its first frame is the first one after the sim time it sees once its endpoints are
matched (:meth:`FrameSchedule.arm`) whose awaited inputs are all stamped after that time (and
a margin: :meth:`FrameSchedule.rejoin_frame`), so none was published before it could hear it.

Pure Python, no ROS: the node adapter feeds elapsed sim time [ns] and wall time [s].
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple

from adcs_nodes.core.lockstep import FrameSync

LOCKSTEP, LIVE = 'lockstep', 'live'
#: ``next_ns`` of a stopped schedule: no frame is ever due again.
NEVER = 2 ** 62


def timing_mode(name: str, given: str, simulated_world: bool, launched: bool,
                real_time: bool) -> str:
    """``lockstep`` or ``live`` of node ``name``: ``given`` ('' when not given) if set, else
    lockstep when the launcher's parameters are ``launched`` or in real-time mode, else live
    (a node started alone). The simulated world runs in lockstep only (ValueError)."""
    if given not in ('', LOCKSTEP, LIVE):
        raise ValueError(f'timing_mode must be {LOCKSTEP!r} or {LIVE!r}, got {given!r}')
    if simulated_world:
        if given == LIVE:
            raise ValueError(f'{name} is part of the simulated world: timing_mode live is '
                             'for flight software only')
        return LOCKSTEP
    return given or (LOCKSTEP if launched or real_time else LIVE)


class FrameSchedule:
    """Which frame of a lockstep consumer is next and when it may fire: ``sync`` its inputs,
    ``period_ns`` P > 0, ``timeout_s`` the wall wait for a due input; ``wait_inputs`` False:
    fire with the latest values as soon as time reaches the frame (real-time flight software);
    ``rejoin``: join a run already going, skipping the inputs stamped up to ``margin_ns`` after
    the time seen (a producer may run that far ahead of ``/clock``)."""

    def __init__(self, sync: FrameSync, period_ns: int, timeout_s: float,
                 wait_inputs: bool = True, rejoin: bool = False, margin_ns: int = 0) -> None:
        self.sync, self.period_ns, self.timeout_s = sync, int(period_ns), float(timeout_s)
        self.wait_inputs = wait_inputs
        self.next_ns, self.seen_ns = 0, -1
        self.wait_since: Optional[float] = None       # wall time the next frame waits since
        self.rejoining, self.armed, self.margin_ns = rejoin, not rejoin, int(margin_ns)
        self.rejoined_at: Optional[int] = None        # the first frame of a rejoin

    def arm(self) -> None:
        """The endpoints are matched: a rejoining node takes its first frame from the sim
        time seen (or, if none yet, from the next one it sees)."""
        self.armed = True
        if self.rejoining and self.seen_ns >= 0:
            self._join()

    def see(self, t_ns: int) -> bool:
        """Sim time ``t_ns`` has been reached; True when it is later than any seen before."""
        if t_ns <= self.seen_ns:
            return False
        self.seen_ns = t_ns
        if self.rejoining and self.armed:
            self._join()
        return True

    def _join(self) -> None:
        self.next_ns = self.rejoined_at = self.rejoin_frame(self.seen_ns + self.margin_ns)
        self.rejoining = False

    def rejoin_frame(self, seen_ns: int) -> int:
        """The first frame after ``seen_ns`` whose awaited inputs are all stamped after it."""
        p = self.period_ns
        t = (seen_ns // p + 1) * p
        while any(s is not None and s <= seen_ns
                  for s in (self.sync.required_stamp(n, t) for n in self.sync.names)):
            t += p
        return t

    def next_ready(self, now_s: float) -> Optional[int]:
        """The next frame if it may fire now, else None (and its wait starts at ``now_s``)."""
        if self.rejoining or self.seen_ns < self.next_ns:
            return None
        t = self.next_ns
        if self.wait_inputs and not self.sync.ready(t):
            if self.wait_since is None:
                self.wait_since = now_s
            return None
        return t

    def timed_out(self, now_s: float) -> Optional[Tuple[int, List[str], List[str]]]:
        """``(frame, inputs missing, inputs dead from now on)`` once the next frame has
        waited ``timeout_s``, else None. The misses are recorded (FrameSync)."""
        if self.wait_since is None or now_s - self.wait_since < self.timeout_s:
            return None
        t = self.next_ns
        return t, self.sync.missing(t), self.sync.record_misses(t)

    def stop(self) -> None:
        """No frame is due ever again (a ``node_killed`` fault)."""
        self.next_ns, self.wait_since = NEVER, None

    def take(self, t_ns: int) -> Dict[str, Any]:
        """Fire frame ``t_ns``: the value of each input for it; the next frame is t + P."""
        msgs = {name: self.sync.value(name, t_ns) for name in self.sync.names}
        self.wait_since, self.next_ns = None, t_ns + self.period_ns
        self.sync.prune(t_ns)
        return msgs
