"""Sample timing: the one rule for inputs that are not awaited frame by frame.

A real driver's samples (an ``external: true`` sensor), every sensor of a ``--real-time`` run
and every input of a node in live mode arrive when they arrive, stamped off the frame grid.
Each sample is checked once on arrival (:func:`admit`) and, in sample timing, kept by stamp
until the frame that covers it takes it (:class:`ExternalInputs`): used once, at its own
stamp, in stamp order; refused and counted by reason otherwise (:data:`REASONS`), never used.

Pure Python, no ROS: the lockstep node (``nodes.lockstep_node``) feeds it stamps in
nanoseconds; times here are absolute stamps (the ROS clock) where said, else elapsed sim
time since the run's epoch.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple

from adcs_nodes.core.run_status import SampleCounts

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


class LiveSamples:
    """The inputs of a node in live mode: the newest sample of each, and the tick's choice.

    Every period of the ROS clock the node fires once (:meth:`choose`, then :meth:`take`)
    with the newest sample of each input, at the newest new stamp of its ``triggers`` (its
    ``frame`` inputs), or at the clock's time minus ``latency_ns`` when none is new: the true
    time difference, no replay of missed frames. A trigger sample stamped at or before the
    last frame is late: never used. Stamps here are absolute [ns]; frame times elapsed since
    ``epoch_ns``.
    """

    def __init__(self, names: Iterable[str], triggers: Iterable[str], epoch_ns: int,
                 max_future_ns: int, max_age_ns: int, latency_ns: int,
                 counts: SampleCounts) -> None:
        self.names, self.triggers = list(names), list(triggers)
        self.epoch_ns, self.latency_ns = int(epoch_ns), int(latency_ns)
        self.max_future_ns, self.max_age_ns = int(max_future_ns), int(max_age_ns)
        self.latest: Dict[str, Tuple[int, Any]] = {}
        self._used: Dict[str, int] = {}       # the newest trigger stamp a tick considered
        self._taken: Dict[str, Tuple[int, Any]] = {}   # the trigger sample last taken
        self._read: Dict[str, int] = {}       # the stamp each input's last frame read
        self._prev: Dict[str, int] = {}       # the stamps of the frame before
        self._this: Dict[str, int] = {}       # the stamps of the last frame taken
        self.last_t: Optional[int] = None
        self.counts = counts

    def offer(self, name: str, stamp_ns: int, now_ns: int, msg: Any) -> Optional[Refusal]:
        """A sample arriving at clock time ``now_ns``: kept as the newest, or refused."""
        cur = self.latest.get(name)
        why = admit(stamp_ns, now_ns, None if cur is None else cur[0], self.max_future_ns,
                    self.max_age_ns)
        if why is None:
            if cur is not None and cur[0] > self._read.get(name, -1):
                self.counts.superseded += 1   # no frame read it
            self.latest[name] = (stamp_ns, msg)
        return why

    def choose(self, now_ns: int) -> Tuple[Optional[int], List[str]]:
        """The tick at clock time ``now_ns``: ``(frame time or None, late triggers)``."""
        if now_ns <= 0:
            return None, []                   # use_sim_time and no /clock yet
        new, late = [], []
        for n in self.triggers:
            ent = self.latest.get(n)
            if ent is None or ent[0] <= self._used.get(n, -1):
                continue
            self._used[n] = ent[0]
            if self.last_t is not None and ent[0] - self.epoch_ns <= self.last_t:
                late.append(n)                # the frame reads the sample taken before it
                if n in self._taken:
                    self.latest[n] = self._taken[n]
                else:
                    del self.latest[n]
                continue
            self._taken[n] = ent
            new.append(ent[0])
        # nothing new: the clock's time minus the transport latency, so a sample taken just
        # before now and still on its way is not made late
        t = (max(new) if new else now_ns - self.latency_ns) - self.epoch_ns
        return (None if self.last_t is not None and t <= self.last_t else t), late

    def take(self, t_ns: int, now_ns: int) -> Dict[str, Any]:
        """Fire frame ``t_ns``: the newest sample of each input (None: none, or too old)."""
        msgs: Dict[str, Any] = {}
        self._prev, self._this = self._this, {}
        for n in self.names:
            ent = self.latest.get(n)
            msgs[n] = None if ent is None or now_ns - ent[0] > self.max_age_ns else ent[1]
            if ent is not None:
                self._read[n] = ent[0]
                if msgs[n] is not None:
                    self._this[n] = ent[0]
        self.last_t = t_ns
        return msgs

    def fresh(self, name: str, stamp_ns: int) -> bool:
        """True when a sample stamped ``stamp_ns`` is newer than the frame before's."""
        prev = self._prev.get(name)
        return prev is None or stamp_ns > prev


class ExternalInputs:
    """The sample-timing inputs of a lockstep node (an external driver's, or every sensor in
    ``--real-time``): never awaited; each sample kept by stamp until a frame covers it, used
    once at its own stamp; starvation: nothing usable for ``dead_after`` of an input's periods
    (the larger of its producer's and the node's) starves the node, logged once per episode
    and kept in :attr:`starved` for the run summary.

    Frame ``t`` takes the samples stamped up to one own period before it (``t - P``): a sample
    on its way while its frame fires (a real-time clock tick comes before the samples of that
    instant) is taken by the next frame, at its own stamp, instead of being late. A sample
    that arrives after the frame that covered its stamp is late: refused, never used.

    ``periods_ns`` ``{name: producer period [ns]}``, ``topics`` ``{name: topic}`` (log lines);
    ``own_period_ns`` P, ``dead_after`` misses, ``epoch_ns``; ``max_future_ns`` (widened by P:
    a producer may be a frame ahead) and ``max_age_ns``, the limits of :func:`admit`;
    ``counts`` counts the samples used and superseded.
    """

    def __init__(self, periods_ns: Dict[str, int], topics: Dict[str, str], own_period_ns: int,
                 dead_after: int, epoch_ns: int, max_future_ns: int, max_age_ns: int,
                 counts: SampleCounts) -> None:
        self.periods_ns, self.topics = dict(periods_ns), topics
        self.own_period_ns, self.dead_after = int(own_period_ns), int(dead_after)
        self.epoch_ns, self.counts = int(epoch_ns), counts
        self.max_future_ns = int(max_future_ns) + self.own_period_ns
        self.max_age_ns = int(max_age_ns)
        self._queue: Dict[str, List[Tuple[int, Any]]] = {n: [] for n in self.periods_ns}
        self._newest: Dict[str, int] = {}    # absolute stamp of the newest accepted
        self._usable: Dict[str, int] = {}    # elapsed stamp of the last usable sample
        self.done_t = -1                     # the last frame time [ns] samples were taken for
        self.used: Dict[str, int] = {}       # absolute stamp of the newest sample used
        #: ``{name: {'since_s': last usable stamp [s] (0: none), 'frames': starved frames,
        #: 'episodes': n, 'over': bool}}``
        self.starved: Dict[str, Dict[str, Any]] = {}

    def __contains__(self, name: str) -> bool:
        return name in self.periods_ns

    def __iter__(self):
        return iter(self.periods_ns)

    def __bool__(self) -> bool:
        return bool(self.periods_ns)

    def offer(self, name: str, stamp_ns: int, seen_ns: int, msg: Any) -> Optional[Refusal]:
        """A sample stamped ``stamp_ns`` (absolute), the node having seen sim time
        ``seen_ns``: kept for the frame that will cover it, or the reason it is refused."""
        why = admit(stamp_ns, self.epoch_ns + max(seen_ns, 0), self._newest.get(name),
                    self.max_future_ns, self.max_age_ns)
        if why is not None:
            return why
        self._newest[name] = stamp_ns
        t_ns = stamp_ns - self.epoch_ns
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
            out += [(t, name, msg) for t, msg in queue if t <= cover]
            self._queue[name] = [(t, msg) for t, msg in queue if t > cover]
        self.done_t = max(self.done_t, cover)
        return sorted(out, key=lambda e: e[0])

    def last_usable(self, name: str) -> Optional[int]:
        """Elapsed stamp of the last sample of ``name`` that passed the checks, or None."""
        return self._usable.get(name)

    def fresh(self, name: str, stamp_ns: int) -> bool:
        """True when a sample stamped ``stamp_ns`` (absolute) is newer than the last used."""
        return stamp_ns > self.used.get(name, -1)

    def after_frame(self, t_ns: int, stamps: Dict[str, int]) -> None:
        """After frame ``t_ns``, whose sample-timing inputs had the absolute ``stamps``: the
        samples the frame did not take itself are covered now; the newest is used, the older
        ones never read are superseded (both counted)."""
        left = self.take(t_ns)
        prev = dict(self.used)
        for n, s in stamps.items():
            if s > prev.get(n, -1):
                self.counts.use(n)
            self.used[n] = s
        self.counts.superseded += sum(
            1 for s_el, n, _ in left
            if prev.get(n, -1) < self.epoch_ns + s_el < self.used.get(n, -1))

    def check_starved(self, t_ns: int, last_usable: Optional[Callable[[str], Optional[int]]]
                      = None) -> List[Tuple[str, str]]:
        """The starvation check at frame ``t_ns``: ``(level, text)`` lines to log.
        ``last_usable(name)``: elapsed stamp of the last usable sample (default: the last
        that passed the timing checks; a consumer that checks more tells)."""
        out = []
        for n in sorted(self.periods_ns):
            period = max(self.own_period_ns, self.periods_ns[n])
            since = (last_usable or self.last_usable)(n) or 0
            ent, topic = self.starved.get(n), self.topics.get(n, n)
            if t_ns - since > self.dead_after * period:
                if ent is None or ent['over']:
                    ent = self.starved.setdefault(n, {'frames': 0, 'episodes': 0})
                    ent.update(since_s=since / NS_PER_S, over=False)
                    ent['episodes'] += 1
                    out.append(('error', (
                        f'{topic}: nothing usable for more than {self.dead_after} periods of '
                        f'{period / NS_PER_S:g} s (last usable sample at t={since / NS_PER_S:g}'
                        f' s, now t={t_ns / NS_PER_S:g} s): this node is starved and the run '
                        'is degraded')))
                ent['frames'] += 1
            elif ent is not None and not ent['over']:
                ent['over'] = True
                out.append(('info', f'{topic}: usable samples again at t={t_ns / NS_PER_S:g} s'))
        return out
