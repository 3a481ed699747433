"""Deterministic lockstep timing: integer-nanosecond frames and the exact-stamp ``FrameSync``.

Timing model (DESIGN section 6)
-------------------------------
* Sim time is kept in integer nanoseconds; every period is an integer multiple of the base
  frame ``frame_ns``. Frame k is at ``t_k = k * frame_ns``.
* An input with period ``p`` is *due* at ``t`` when ``t % p == 0``. A node fires for ``t_k`` when
  every due input has arrived with exactly that stamp; inputs that are not due are taken as the
  latest value stamped at or before ``t_k``.
* Seeds: one scenario seed; each node derives its own stream with :func:`derive_seed`, so
  adding a node never changes another node's random numbers.

Pure Python (no rclpy): the nodes feed it stamps converted at the edge.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

NS_PER_S = 1_000_000_000


def seconds_to_ns(t_s: float) -> int:
    """Round seconds to integer nanoseconds (periods in scenarios are given in seconds)."""
    return int(round(float(t_s) * NS_PER_S))


def ns_to_seconds(t_ns: int) -> float:
    """Integer nanoseconds to float seconds (for the core, which takes ``t`` in seconds)."""
    return t_ns / NS_PER_S


def period_to_frames(period_s: float, frame_ns: int, name: str = 'period') -> int:
    """Number of base frames in ``period_s``; ``ValueError`` if it is not an exact multiple."""
    p_ns = seconds_to_ns(period_s)
    if p_ns <= 0:
        raise ValueError(f'{name} must be positive, got {period_s} s')
    if frame_ns <= 0:
        raise ValueError(f'base frame must be positive, got {frame_ns} ns')
    if p_ns % frame_ns != 0:
        raise ValueError(f'{name} = {period_s} s is not an integer multiple of the base frame '
                         f'{frame_ns / NS_PER_S} s')
    return p_ns // frame_ns


def derive_seed(scenario_seed: int, name: str) -> int:
    """Per-node seed from the scenario seed and the node (or stream) name, stable across runs."""
    digest = hashlib.sha256(f'{int(scenario_seed)}:{name}'.encode()).digest()
    return int.from_bytes(digest[:8], 'little')


@dataclass
class _Input:
    period_ns: int
    by_stamp: Dict[int, Any] = field(default_factory=dict)
    latest: Optional[Tuple[int, Any]] = None


class FrameSync:
    """Exact-stamp synchroniser of a node's inputs (a small ``message_filters`` substitute).

    Parameters
    ----------
    inputs : dict
        ``{name: period_ns}``. ``period_ns = 0`` marks an input that is never waited for (always
        taken as latest).
    history : int
        Frames of early-arrived messages kept per input (messages may arrive for ``t_{k+1}``
        before frame ``t_k`` fired).

    Examples
    --------
    >>> s = FrameSync({'env': 10, 'cmd': 20})
    >>> s.add('env', 0, 'e0'); s.ready(0)
    False
    >>> s.add('cmd', 0, 'c0'); s.ready(0)
    True
    >>> s.add('env', 10, 'e1'); s.ready(10), s.value('cmd', 10)
    (True, 'c0')
    """

    def __init__(self, inputs: Dict[str, int], history: int = 64) -> None:
        self._inputs: Dict[str, _Input] = {}
        for name, period in inputs.items():
            if int(period) < 0:
                raise ValueError(f'input {name!r}: period must be >= 0, got {period}')
            self._inputs[name] = _Input(int(period))
        self._history = int(history)

    @property
    def names(self) -> List[str]:
        """Names of the declared inputs."""
        return list(self._inputs)

    def set_period(self, name: str, period_ns: int) -> None:
        """Change the period of input ``name`` (0: stop waiting for it, e.g. a dead producer)."""
        if int(period_ns) < 0:
            raise ValueError(f'input {name!r}: period must be >= 0, got {period_ns}')
        self._inputs[name].period_ns = int(period_ns)

    def period(self, name: str) -> int:
        """Current period of input ``name`` [ns]."""
        return self._inputs[name].period_ns

    def due(self, name: str, t_ns: int) -> bool:
        """True when input ``name`` must have a message stamped exactly ``t_ns``."""
        p = self._inputs[name].period_ns
        return p > 0 and t_ns % p == 0

    def add(self, name: str, stamp_ns: int, value: Any) -> None:
        """Store a message of input ``name`` with stamp ``stamp_ns``.

        Raises
        ------
        KeyError
            If ``name`` was not declared.
        """
        inp = self._inputs[name]
        stamp_ns = int(stamp_ns)
        inp.by_stamp[stamp_ns] = value
        if len(inp.by_stamp) > self._history:
            del inp.by_stamp[min(inp.by_stamp)]
        if inp.latest is None or stamp_ns >= inp.latest[0]:
            inp.latest = (stamp_ns, value)

    def has(self, name: str, t_ns: int) -> bool:
        """True when input ``name`` has a message stamped exactly ``t_ns``."""
        return int(t_ns) in self._inputs[name].by_stamp

    def missing(self, t_ns: int) -> List[str]:
        """Inputs due at ``t_ns`` whose message with that stamp has not arrived."""
        return [n for n in self._inputs if self.due(n, t_ns) and not self.has(n, t_ns)]

    def ready(self, t_ns: int) -> bool:
        """True when every input due at ``t_ns`` has arrived with exactly that stamp."""
        return not self.missing(t_ns)

    def value(self, name: str, t_ns: Optional[int] = None) -> Any:
        """Message of ``name`` stamped ``t_ns`` if present, else the latest one at or before it.

        Returns ``None`` when nothing usable has arrived.
        """
        inp = self._inputs[name]
        if t_ns is None:
            return None if inp.latest is None else inp.latest[1]
        t_ns = int(t_ns)
        if t_ns in inp.by_stamp:
            return inp.by_stamp[t_ns]
        older = [s for s in inp.by_stamp if s <= t_ns]
        if older:
            return inp.by_stamp[max(older)]
        if inp.latest is not None and inp.latest[0] <= t_ns:
            return inp.latest[1]
        return None

    def prune(self, t_ns: int) -> None:
        """Forget messages stamped before ``t_ns`` except the newest such one of each input."""
        for inp in self._inputs.values():
            old = sorted(s for s in inp.by_stamp if s < t_ns)
            for s in old[:-1]:
                del inp.by_stamp[s]
