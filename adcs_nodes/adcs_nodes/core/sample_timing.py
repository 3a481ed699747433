"""Sample timing: the one rule for inputs that are not awaited frame by frame.

A real driver's samples (an ``external: true`` sensor), every sensor of a ``--real-time`` run
and every input of a node in live mode arrive when they arrive, stamped off the frame grid.
Each sample is checked once on arrival (:func:`admit`) and, in sample timing, kept by stamp
until the frame that covers it takes it (:class:`SampleQueue`): used once, at its own stamp,
in stamp order; refused and counted by reason otherwise (:data:`REASONS`), never used.

Pure Python, no ROS: the lockstep node (``nodes.lockstep_node``) feeds it stamps in
nanoseconds; times here are absolute stamps (the ROS clock) where said, else elapsed sim
time since the run's epoch.
"""
from __future__ import annotations

from typing import Any, Dict, Iterable, List, Optional, Tuple

NS_PER_S = 1_000_000_000
#: Why a sample is refused, in the order the checks run.
REASONS = ('zero_stamp', 'future', 'too_old', 'out_of_order', 'late')

Refusal = Tuple[str, str]          # (reason, text)


def admit(stamp_ns: int, now_ns: int, newest_ns: Optional[int], max_future_ns: int,
          max_age_ns: int) -> Optional[Refusal]:
    """Why a sample stamped ``stamp_ns`` that arrives at clock time ``now_ns`` is refused
    (absolute ns; ``now_ns <= 0``: no clock yet, the clock checks are skipped), or None.

    ``newest_ns``: the stamp of the newest sample of that input accepted before (None: none).
    Refused: a zero stamp; a stamp more than ``max_future_ns`` ahead of the clock; one more
    than ``max_age_ns`` behind it; one not newer than ``newest_ns`` (a duplicate or out of
    order).
    """
    if stamp_ns == 0:
        return 'zero_stamp', 'stamped zero'
    if now_ns > 0 and stamp_ns > now_ns + max_future_ns:
        return 'future', (f'stamped {(stamp_ns - now_ns) / NS_PER_S:.3f} s ahead of the clock '
                          f'(limit {max_future_ns / NS_PER_S:g} s)')
    if now_ns > 0 and now_ns - stamp_ns > max_age_ns:
        return 'too_old', (f'{(now_ns - stamp_ns) / NS_PER_S:.3f} s old '
                           f'(limit {max_age_ns / NS_PER_S:g} s)')
    if newest_ns is not None and stamp_ns <= newest_ns:
        return 'out_of_order', ('not newer than the sample before '
                                f'({(newest_ns - stamp_ns) / NS_PER_S:.3f} s older)')
    return None


class SampleQueue:
    """The samples of the sample-timing inputs of one node, kept by stamp until a frame
    covers them.

    Frame ``t`` takes the samples stamped up to one own period before it (``t - P``): a
    sample on its way while its frame fires (a real-time clock tick comes before the samples
    of that instant) is taken by the next frame, at its own stamp, instead of being late. A
    sample that arrives after the frame that covered its stamp is late: refused, never used.

    Parameters
    ----------
    names : iterable of str
        The inputs in sample timing.
    own_period_ns : int
        The node's period [ns] (P above).
    max_future_ns, max_age_ns : int
        The arrival limits of :func:`admit` (the future limit is widened by one own period:
        a producer may be one frame ahead of this node's view of the clock).
    """

    def __init__(self, names: Iterable[str], own_period_ns: int, max_future_ns: int,
                 max_age_ns: int) -> None:
        self.names = set(names)
        self.own_period_ns = int(own_period_ns)
        self.max_future_ns = int(max_future_ns) + self.own_period_ns
        self.max_age_ns = int(max_age_ns)
        self._queue: Dict[str, List[Tuple[int, Any]]] = {n: [] for n in self.names}
        self._newest: Dict[str, int] = {}        # absolute stamp of the newest accepted
        self._usable: Dict[str, int] = {}        # elapsed stamp of the last usable sample
        self.done_t = -1                         # the last frame time [ns] samples were taken for

    def offer(self, name: str, stamp_ns: int, t_ns: int, now_ns: int,
              msg: Any) -> Optional[Refusal]:
        """A sample of ``name`` stamped ``stamp_ns`` (absolute; ``t_ns`` the same as elapsed
        sim time), arriving at clock time ``now_ns`` (absolute): kept for the frame that will
        cover it, or the reason it is refused."""
        why = admit(stamp_ns, now_ns, self._newest.get(name), self.max_future_ns,
                    self.max_age_ns)
        if why is not None:
            return why
        self._newest[name] = stamp_ns
        if t_ns <= self.done_t:
            return 'late', 'arrived after the frame that covers its stamp was processed'
        self._queue[name].append((t_ns, msg))
        self._usable[name] = t_ns
        return None

    def take(self, t_ns: int) -> List[Tuple[int, str, Any]]:
        """The samples frame ``t_ns`` takes, in stamp order: ``(elapsed stamp, input name,
        message)``, each returned once."""
        cover = t_ns - self.own_period_ns
        out = []
        for name, queue in self._queue.items():
            keep = []
            for t, msg in queue:
                (out if t <= cover else keep).append((t, name, msg))
            self._queue[name] = [(t, m) for t, _, m in keep]
        self.done_t = max(self.done_t, cover)
        return sorted(out, key=lambda e: e[0])

    def last_usable(self, name: str) -> Optional[int]:
        """Elapsed stamp of the last sample of ``name`` that passed the checks, or None."""
        return self._usable.get(name)
