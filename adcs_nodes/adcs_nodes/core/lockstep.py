"""Deterministic lockstep timing: integer-nanosecond frames, ``FrameSync`` and the clock master.

Timing model (DESIGN section 6)
-------------------------------
* Sim time is kept in integer nanoseconds; every period is an integer multiple of the base
  frame ``frame_ns``. Frame k is at ``t_k = k * frame_ns``.
* An input of kind ``frame`` with period ``p`` is *due* at ``t`` when ``t % p == 0``: the node
  fires for ``t_k`` only when it has arrived with exactly that stamp. Between its due frames it
  is taken as the latest value stamped at or before ``t_k``.
* An input of kind ``previous`` (e.g. the actuator command an estimator needs for its
  prediction over ``[t_{k-1}, t_k]``) is due at every frame ``t > 0`` of the node with the stamp
  ``s(t) = p * floor((t - 1 ns) / p)``, the last producer frame strictly before ``t``; its value
  is exactly that message, or ``None`` when it timed out (never "whatever arrived").
* An input of kind ``latest`` (period 0) is never waited for. It must not influence the
  node's output in lockstep (that would make the output depend on arrival order).
* Dead producers: a due input that times out ``dead_after`` frames in a row is *dead*: it is
  no longer awaited until a message of it arrives again. "In a row" and "again" are read
  from the stamps, never from the order of arrival (a consumer does not wait for a dead
  input, so the world may run ahead of it: the controllers stop waiting for a dead estimate,
  and the star tracker's return reaches the estimator before its own third miss): a miss
  follows the previous one when no message is stamped between them, and the producer
  returns with its first message stamped after the frame it died at (whether that message
  came before the death was counted, or after). It is then re-admitted after a hold: its
  messages stamped up to ``REVIVE_HOLD_FRAMES`` base frames after the returning one are not
  used, and it is awaited again only from the frames after that (the re-admission hold of a
  sensor FDIR). The hold makes the return deterministic: the clock master never runs more
  than ``MAX_LAG_FRAMES`` (+ one ``PROGRESS_EVERY`` report) ahead of any node, so within the
  hold the node's frames are the same whenever the returning message arrived. The plain
  engine uses the same :class:`FrameSync` (``sim_node.engine``).
* Seeds: one scenario seed; each node derives its own stream with :func:`derive_seed`, so
  adding a node never changes another node's random numbers.

Clock master (frame k, :class:`ClockMaster`)::

    THROTTLED -- a node lags > max lag --> wait for its progress
    PACED     -- paced (``pace_s``) and ahead of the wall schedule --> wait for it
    WAIT_ENV:  /clock(t_k) published, wait sim/environment(t_k)  -> publish sim/state(t_k)
    WAIT_CMD:  wait the actuator command stamped t_k (when due)  -> step t_k -> t_k+1
    WAIT_FINAL (t_k = duration): wait every node's final progress -> DONE

Pure Python (no rclpy): the nodes feed it stamps converted at the edge and execute the
returned actions. No equations of motion here; the reference is DESIGN section 6.
"""
from __future__ import annotations

import bisect
import enum
import hashlib
from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, List, Mapping, Optional, Tuple, Union

NS_PER_S = 1_000_000_000
#: A node reports its progress (``lockstep/progress``) every this many base frames.
PROGRESS_EVERY = 10
#: The clock master waits when a node is more than this many frames behind (the data QoS
#: keeps 100 messages per topic, so nothing a lagging node has not read yet is dropped).
MAX_LAG_FRAMES = 40
#: Base frames after a revived input's reviving message during which it is neither stored nor
#: awaited (see the module docstring): the farthest the world can run ahead of its producer.
REVIVE_HOLD_FRAMES = MAX_LAG_FRAMES + PROGRESS_EVERY


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


class InputKind(str, enum.Enum):
    """How a lockstep input is synchronised (see the module docstring)."""

    FRAME = 'frame'          #: awaited with the stamp of the frame when due
    PREVIOUS = 'previous'    #: awaited with the stamp of the producer frame before t
    LATEST = 'latest'        #: never awaited (period 0)


def input_kind(kind: Union[str, InputKind]) -> InputKind:
    """Parse an input kind; ``ValueError`` naming the known ones."""
    try:
        return InputKind(kind)
    except ValueError:
        raise ValueError(f'unknown input kind {kind!r}; known: '
                         f'{", ".join(k.value for k in InputKind)}') from None


@dataclass
class _Input:
    period_ns: int
    kind: InputKind = InputKind.FRAME
    by_stamp: Dict[int, Any] = field(default_factory=dict)
    stamps: List[int] = field(default_factory=list)   # keys of by_stamp, ascending
    latest: Optional[Tuple[int, Any]] = None
    misses: int = 0           # due frames missed in a row
    last_miss: int = -1       # the stamp the last miss lacked
    dead: bool = False
    died_at: int = -1         # the stamp its last miss lacked
    revived_at: int = -1      # end of the hold after the message that last revived it
    held: bool = False        # revived once: messages stamped up to revived_at are dropped


class FrameSync:
    """Exact-stamp synchroniser of a node's inputs (a small ``message_filters`` substitute).

    Each input keeps its messages by stamp with the stamps in an ascending list (in order of
    arrival, the usual case, a message is appended), so the latest message at or before a
    frame is a bisection and pruning a slice: no scan or sort per call (issue 13).

    Parameters
    ----------
    inputs : dict
        ``{name: period_ns}`` or ``{name: (period_ns, kind)}`` with ``kind`` one of
        :class:`InputKind` (default ``frame``). ``period_ns = 0`` marks an input that is never
        waited for (always taken as latest).
    history : int
        Frames of early-arrived messages kept per input (messages may arrive for ``t_{k+1}``
        before frame ``t_k`` fired).
    dead_after : int
        A due input missed (:meth:`record_misses`) this many frames in a row is dead: no
        longer awaited until it publishes again. 0: never.
    revive_hold_ns : int
        After the message that revives a dead input, its messages stamped up to this much
        later are dropped and it is not awaited (a node passes ``REVIVE_HOLD_FRAMES`` frames).

    Examples
    --------
    >>> s = FrameSync({'env': 10, 'cmd': 20})
    >>> _ = s.add('env', 0, 'e0'); s.ready(0)
    False
    >>> _ = s.add('cmd', 0, 'c0'); s.ready(0)
    True
    >>> _ = s.add('env', 10, 'e1'); s.ready(10), s.value('cmd', 10)
    (True, 'c0')
    >>> p = FrameSync({'cmd': (20, 'previous')})
    >>> p.ready(0), p.missing(20), p.required_stamp('cmd', 30)
    (True, ['cmd'], 20)
    """

    def __init__(self, inputs: Mapping[str, Any], history: int = 64,
                 dead_after: int = 0, revive_hold_ns: int = 0) -> None:
        self._inputs: Dict[str, _Input] = {}
        for name, spec in inputs.items():
            period, kind = spec if isinstance(spec, tuple) else (spec, InputKind.FRAME)
            if int(period) < 0:
                raise ValueError(f'input {name!r}: period must be >= 0, got {period}')
            kind = input_kind(kind)
            if int(period) == 0:
                kind = InputKind.LATEST
            elif kind is InputKind.LATEST:
                raise ValueError(f'input {name!r}: kind latest needs period 0, got {period}')
            self._inputs[name] = _Input(int(period), kind)
        if int(history) < 1:
            raise ValueError(f'history must be >= 1, got {history}')
        self._history = int(history)
        if isinstance(dead_after, bool) or int(dead_after) != dead_after or dead_after < 0:
            raise ValueError(f'dead_after must be an integer >= 0, got {dead_after!r}')
        self.dead_after = int(dead_after)
        if int(revive_hold_ns) < 0:
            raise ValueError(f'revive_hold_ns must be >= 0, got {revive_hold_ns}')
        self.revive_hold_ns = int(revive_hold_ns)

    @property
    def names(self) -> List[str]:
        """Names of the declared inputs."""
        return list(self._inputs)

    def kind(self, name: str) -> InputKind:
        """Kind of input ``name``."""
        return self._inputs[name].kind

    def required_stamp(self, name: str, t_ns: int) -> Optional[int]:
        """Stamp input ``name`` must have for frame ``t_ns`` (None: nothing required then)."""
        inp = self._inputs[name]
        p, t_ns = inp.period_ns, int(t_ns)
        if p <= 0:
            return None
        if inp.kind is InputKind.PREVIOUS:
            return None if t_ns <= 0 else ((t_ns - 1) // p) * p
        return t_ns if t_ns % p == 0 else None

    def due(self, name: str, t_ns: int) -> bool:
        """True when input ``name`` must have arrived (with its required stamp) for ``t_ns``."""
        inp = self._inputs[name]
        return not inp.dead and int(t_ns) > inp.revived_at and \
            self.required_stamp(name, t_ns) is not None

    def add(self, name: str, stamp_ns: int, value: Any) -> bool:
        """Store a message of input ``name`` with stamp ``stamp_ns``.

        Returns
        -------
        bool
            True when the input was dead and this message, stamped after its death, revives
            it: awaited again from the frames after ``stamp_ns + revive_hold_ns``; that
            message, and those of the hold, are not stored (see the module docstring). A
            dead input's message stamped at or before its death is dropped.

        Raises
        ------
        KeyError
            If ``name`` was not declared.
        """
        inp = self._inputs[name]
        stamp_ns = int(stamp_ns)
        if inp.dead:
            if stamp_ns <= inp.died_at:
                return False              # stale: the frames it was due for are done
            self._revive(inp, stamp_ns)
            return True
        if inp.held and stamp_ns <= inp.revived_at:
            return False                  # within the re-admission hold
        by, stamps = inp.by_stamp, inp.stamps
        if stamp_ns not in by:
            if not stamps or stamp_ns > stamps[-1]:
                stamps.append(stamp_ns)
            else:
                bisect.insort(stamps, stamp_ns)
        by[stamp_ns] = value
        if len(stamps) > self._history:
            del by[stamps.pop(0)]          # the oldest stamp (may be the one just added)
        if inp.latest is None or stamp_ns >= inp.latest[0]:
            inp.latest = (stamp_ns, value)
        return False

    def _revive(self, inp: _Input, stamp_ns: int) -> None:
        """``inp`` returns with a message stamped ``stamp_ns``: the hold starts; what is
        stored in it is dropped."""
        inp.dead, inp.held, inp.misses, inp.last_miss = False, True, 0, -1
        inp.revived_at = stamp_ns + self.revive_hold_ns
        lo = bisect.bisect_right(inp.stamps, inp.died_at)
        hi = bisect.bisect_right(inp.stamps, inp.revived_at)
        for s in inp.stamps[lo:hi]:
            del inp.by_stamp[s]
        del inp.stamps[lo:hi]
        if inp.latest is not None and inp.died_at < inp.latest[0] <= inp.revived_at:
            inp.latest = (inp.stamps[-1], inp.by_stamp[inp.stamps[-1]]) if inp.stamps else None

    def has(self, name: str, t_ns: int) -> bool:
        """True when input ``name`` has a message stamped exactly ``t_ns``."""
        return int(t_ns) in self._inputs[name].by_stamp

    def _lacks(self, inp: _Input, t_ns: int) -> bool:
        """True when ``inp`` is due at ``t_ns`` and its required message has not arrived
        (:meth:`due` and :meth:`required_stamp` in one, for the per-message path)."""
        p = inp.period_ns
        if p <= 0 or inp.dead or t_ns <= inp.revived_at:
            return False
        if inp.kind is InputKind.PREVIOUS:
            return t_ns > 0 and ((t_ns - 1) // p) * p not in inp.by_stamp
        return t_ns % p == 0 and t_ns not in inp.by_stamp

    def missing(self, t_ns: int) -> List[str]:
        """Inputs due at ``t_ns`` whose message with the required stamp has not arrived."""
        t_ns = int(t_ns)
        return [n for n, inp in self._inputs.items() if self._lacks(inp, t_ns)]

    def ready(self, t_ns: int) -> bool:
        """True when every input due at ``t_ns`` has arrived with its required stamp."""
        t_ns = int(t_ns)
        for inp in self._inputs.values():
            if self._lacks(inp, t_ns):
                return False
        return True

    def record_misses(self, t_ns: int) -> List[str]:
        """Count a timed-out frame ``t_ns`` against every input missing then (in a row with
        the previous miss when no message is stamped between the two stamps they lacked).

        Returns the inputs that died with this miss (``dead_after`` in a row); one with a
        message stamped after the one it lacked here already returns at once (:meth:`add`).
        """
        newly = []
        for name in self.missing(t_ns):
            inp = self._inputs[name]
            s = self.required_stamp(name, t_ns)
            i = bisect.bisect_left(inp.stamps, s)           # stamps[:i] are < s
            between = i > 0 and inp.stamps[i - 1] > inp.last_miss
            inp.misses = 1 if between else inp.misses + 1
            inp.last_miss = s
            if self.dead_after and inp.misses >= self.dead_after:
                inp.dead, inp.died_at = True, s
                newly.append(name)
                later = bisect.bisect_right(inp.stamps, s)
                if later < len(inp.stamps):                # it came back already
                    self._revive(inp, inp.stamps[later])
        return newly

    def is_dead(self, name: str) -> bool:
        """True when input ``name`` is treated as dead (not awaited)."""
        return self._inputs[name].dead

    def dead(self) -> List[str]:
        """Names of the dead inputs."""
        return [n for n, inp in self._inputs.items() if inp.dead]

    def value(self, name: str, t_ns: Optional[int] = None) -> Any:
        """The message of ``name`` for frame ``t_ns``.

        ``frame`` and ``latest`` inputs: the one stamped ``t_ns`` if present, else the latest
        at or before it (``t_ns = None``: the latest). ``previous`` inputs: exactly the one
        stamped :meth:`required_stamp`. ``None`` when nothing usable has arrived.
        """
        inp = self._inputs[name]
        if t_ns is None:
            return None if inp.latest is None else inp.latest[1]
        t_ns = int(t_ns)
        if inp.kind is InputKind.PREVIOUS:
            s = self.required_stamp(name, t_ns)
            return None if s is None else inp.by_stamp.get(s)
        if t_ns in inp.by_stamp:
            return inp.by_stamp[t_ns]
        i = bisect.bisect_right(inp.stamps, t_ns)     # stamps[:i] are <= t_ns
        if i:
            return inp.by_stamp[inp.stamps[i - 1]]
        if inp.latest is not None and inp.latest[0] <= t_ns:
            return inp.latest[1]
        return None

    def take(self, t_ns: int) -> Tuple[Dict[str, Any], List[str]]:
        """Frame ``t_ns`` of a consumer that never waits (the FrameLoop), in one pass: the
        inputs missing then (their misses recorded), each input's :meth:`value`, then
        :meth:`prune`. Returns ``(values, missing)``."""
        missing = self.missing(t_ns)
        if missing:
            self.record_misses(t_ns)
        values = {}
        for name, inp in self._inputs.items():
            by = inp.by_stamp
            if t_ns in by and inp.kind is not InputKind.PREVIOUS:
                values[name] = by[t_ns]           # the usual case: stamped with the frame
            else:
                values[name] = self.value(name, t_ns)
        self.prune(t_ns)
        return values, missing

    def prune(self, t_ns: int) -> None:
        """Forget messages stamped before ``t_ns`` except the newest such one of each input."""
        t_ns = int(t_ns)
        for inp in self._inputs.values():
            stamps = inp.stamps
            if len(stamps) < 2 or stamps[1] >= t_ns:
                continue                          # at most one stamp before t_ns
            n = bisect.bisect_left(stamps, t_ns) - 1     # stamps[:n + 1] are < t_ns
            for s in stamps[:n]:
                del inp.by_stamp[s]
            del stamps[:n]


# ---------------------------------------------------------------------------- clock master
class MasterPhase(enum.Enum):
    """States of the clock master (see the module docstring)."""

    IDLE = 'idle'                 #: not started (handshake) or real-time mode
    THROTTLED = 'throttled'       #: a node lags more than the allowed frames: wait for it
    PACED = 'paced'               #: ahead of the wall schedule of a paced run: wait for it
    WAIT_ENV = 'wait_env'         #: /clock(t_k) published, waiting for sim/environment(t_k)
    WAIT_CMD = 'wait_cmd'         #: sim/state(t_k) published, waiting for the command
    WAIT_FINAL = 'wait_final'     #: last frame published, waiting for every node's final
    DONE = 'done'                 #: run finished


class Act(enum.Enum):
    """What the node has to do (the master itself never touches ROS)."""

    CLOCK = 'clock'               #: publish /clock = t_ns
    STATE = 'state'               #: publish sim/state(t_ns) from ``value`` (environment)
    STEP = 'step'                 #: integrate t_ns -> t_ns + frame; ``value`` = (env, cmd)
    MISSED = 'missed'             #: a missed frame: ``value`` = inputs, ``text`` = applied
    LOG = 'log'                   #: log ``text`` at level ``value`` ('info', 'warning', ...)
    FINISH = 'finish'             #: the run is over


#: Command value of a STEP that applies a zero command (timeout or dead producer).
ZERO = 'zero'
#: Command value of a STEP that holds the previous command (no command due this frame).
HOLD = None


@dataclass(frozen=True)
class Action:
    """One step for the node to execute, in order."""

    kind: Act
    t_ns: int
    value: Any = None
    text: str = ''


class ClockMaster:
    """The clock master's frame state machine (pure; wall time is passed in as ``now``).

    Parameters
    ----------
    frame_ns, duration_ns, command_period_ns : int
        Base frame [ns] (> 0); run length [ns] (0: endless); period of
        ``adcs/actuator_command`` [ns] (0: no command, free body).
    wait_for_nodes : iterable of str
        Nodes whose progress gates the clock and whose final frame ends the run.
    timeout_s : float
        Wall-clock wait [s] for a missing input before going on (> 0).
    max_lag_frames : int, lag_frames : mapping str -> int
        How many frames a node may lag behind the clock (per-node overrides).
    dead_after : int
        Command frames missed in a row after which a zero command is applied without waiting
        until the producer publishes again (>= 1).
    no_final : iterable of str
        Nodes not waited for at the end (no final frame, e.g. the recorder).
    always_wait : iterable of str, patience : int
        Nodes waited for ``patience`` (>= 1) timeouts in a row, not one (the recorder), with a
        warning every ``timeout_s``, then an error saying the bag misses messages.
    pace_s : float
        Frame k starts no earlier than ``k * pace_s`` wall seconds after frame 0 (0: as fast as
        the chain goes); it changes no number of the run.
    """

    def __init__(self, frame_ns: int, duration_ns: int = 0, command_period_ns: int = 0,
                 wait_for_nodes: Iterable[str] = (), timeout_s: float = 5.0,
                 max_lag_frames: int = 40, lag_frames: Optional[Mapping[str, int]] = None,
                 dead_after: int = 3, no_final: Iterable[str] = (),
                 always_wait: Iterable[str] = (), patience: int = 6,
                 pace_s: float = 0.0) -> None:
        self.frame_ns = int(frame_ns)
        if self.frame_ns <= 0:
            raise ValueError(f'frame must be positive, got {frame_ns} ns')
        self.duration_ns = int(duration_ns)
        if self.duration_ns < 0:
            raise ValueError(f'duration must be >= 0, got {duration_ns} ns')
        cmd = int(command_period_ns)
        if cmd < 0 or cmd % self.frame_ns:
            raise ValueError(f'command period {cmd} ns must be a non-negative multiple of the '
                             f'frame {self.frame_ns} ns')
        if not float(timeout_s) > 0:
            raise ValueError(f'timeout_s must be positive, got {timeout_s}')
        if int(dead_after) < 1:
            raise ValueError(f'dead_after must be >= 1, got {dead_after}')
        self.timeout_s = float(timeout_s)
        if not (float(pace_s) >= 0.0 and float(pace_s) < float('inf')):
            raise ValueError(f'pace_s must be a finite number >= 0, got {pace_s}')
        self.pace_s = float(pace_s)
        self._pace_t0: Optional[float] = None     # wall time of frame 0 of a paced run
        self.wait_for_nodes = [n for n in wait_for_nodes if n]
        self.max_lag_frames = int(max_lag_frames)
        self.lag_frames = dict(lag_frames or {})
        self.no_final = set(no_final)
        self.always_wait = set(always_wait)
        self.patience = max(1, int(patience))
        self._waited = 0                  # timeouts in a row spent waiting for always_wait
        self.sync = FrameSync({'env': self.frame_ns, 'cmd': cmd}, dead_after=int(dead_after))
        self.phase = MasterPhase.IDLE
        self.k = 0
        self.wait_since = 0.0
        self.progress: Dict[str, int] = {}
        self.final_nodes: set = set()
        #: nodes that lagged past the timeout: not waited for until they report again
        self.gone: set = set()
        self.missed_frames = 0
        self.throttled_frames = 0

    # ------------------------------------------------------------------ queries
    @property
    def t_ns(self) -> int:
        """Elapsed sim time of the current frame [ns]."""
        return self.k * self.frame_ns

    def lagging(self) -> Optional[str]:
        """Name of a node too far behind frame k, or None."""
        for node in self.wait_for_nodes:
            if node in self.gone:
                continue
            lag = self.lag_frames.get(node, self.max_lag_frames)
            if self.t_ns - self.progress.get(node, 0) > lag * self.frame_ns:
                return node
        return None

    def all_final(self) -> bool:
        """True when every awaited node reported its final frame, and every ``always_wait``
        node (the recorder) has read up to it: the master's process must not end while a
        recorder that lags by up to its ``lag_frames`` has not received the last frames yet
        (they would be lost with the publishers' history)."""
        return all(n in self.final_nodes for n in self.wait_for_nodes
                   if n not in self.no_final and n not in self.gone) and \
            not self._unread_end()

    def _unread_end(self) -> List[str]:
        """``always_wait`` nodes (awaited, not gone) that have not read the current frame."""
        return [n for n in self.wait_for_nodes if n in self.always_wait
                and n not in self.gone and self.progress.get(n, -1) < self.t_ns]

    # ------------------------------------------------------------------ events
    def start(self, now: float) -> List[Action]:
        """Start frame 0 (after the handshake)."""
        if self.phase is not MasterPhase.IDLE:
            return []
        return self._begin_frame(now)

    def on_environment(self, t_ns: int, env: Any, now: float) -> List[Action]:
        """An environment message stamped ``t_ns`` (elapsed) arrived."""
        self.sync.add('env', t_ns, env)
        return self._advance(now)

    def on_command(self, t_ns: int, cmd: Any, now: float) -> List[Action]:
        """An actuator command stamped ``t_ns`` arrived (``cmd`` already checked)."""
        out = []
        if self.sync.add('cmd', t_ns, cmd):
            out.append(Action(Act.LOG, t_ns, 'info', 'adcs/actuator_command publishes again: '
                              'awaited again'))
        return out + self._advance(now)

    def on_progress(self, node: str, t_ns: int, final: bool, now: float) -> List[Action]:
        """Node ``node`` has read everything up to ``t_ns`` (``final``: its last frame)."""
        self.progress[node] = max(int(t_ns), self.progress.get(node, -1))
        if node in self.always_wait:
            self._waited = 0
        if final:
            self.final_nodes.add(node)
        out: List[Action] = []
        if node in self.gone:
            self.gone.discard(node)
            out.append(Action(Act.LOG, self.t_ns, 'info',
                              f'{node} reports progress again: waited for again'))
        if self.phase is MasterPhase.THROTTLED and not self.lagging():
            return out + self._begin_frame(now)
        if self.phase is MasterPhase.WAIT_FINAL and self.all_final():
            return out + self._finish()
        return out

    def tick(self, now: float) -> List[Action]:
        """Watchdog: act on a wait longer than ``timeout_s`` of wall time."""
        if self.phase in (MasterPhase.IDLE, MasterPhase.DONE):
            return []
        if self.phase is MasterPhase.PACED:
            return self._begin_frame(now) if now >= self._paced_start() else []
        if now - self.wait_since < self.timeout_s:
            return []
        t = self.t_ns
        if self.phase is MasterPhase.THROTTLED:
            node = self.lagging()
            if node in self.always_wait and self._waited + 1 < self.patience:
                self._waited += 1
                self.wait_since = now
                return [Action(Act.LOG, t, 'warning',
                               f'frame t={t / NS_PER_S:g} s: waiting for {node}, more than '
                               f'{self.lag_frames.get(node, self.max_lag_frames)} frames '
                               f'behind for {self._waited * self.timeout_s:g} s (going on '
                               'would lose messages it has not read yet)')]
            if node in self.always_wait:
                self._waited = 0
                self.gone.add(node)
                return [Action(Act.LOG, t, 'error',
                               f'frame t={t / NS_PER_S:g} s: {node} read nothing for '
                               f'{self.patience * self.timeout_s:g} s; going on without '
                               'waiting for it: the bag misses the messages it did not read '
                               '(it is waited for again when it reports progress)')
                        ] + self._begin_frame(now)
            out = [Action(Act.LOG, t, 'warning',
                          f'frame t={t / NS_PER_S:g} s: {node} is more than '
                          f'{self.lag_frames.get(node, self.max_lag_frames)} frames behind '
                          f'for {self.timeout_s:g} s; going on without waiting for it until it '
                          'reports progress again')]
            if node is not None:
                self.gone.add(node)               # a dead node must not stop the world
            return out + self._begin_frame(now)
        if self.phase is MasterPhase.WAIT_FINAL:
            missing = [n for n in self.wait_for_nodes if n not in self.no_final
                       and n not in self.final_nodes and n not in self.gone]
            unread = self._unread_end()
            if not missing and unread and self._waited + 1 < self.patience:
                self._waited += 1
                self.wait_since = now
                return [Action(Act.LOG, t, 'warning',
                               f'end of run: waiting for {", ".join(unread)} to read the '
                               f'last frames ({self._waited * self.timeout_s:g} s)')]
            missing += [n for n in unread if n not in missing]
            return [Action(Act.LOG, t, 'warning',
                           f'end of run: no final frame from {", ".join(missing)} within '
                           f'{self.timeout_s:g} s; finishing')] + self._finish()
        if self.phase is MasterPhase.WAIT_ENV:
            self.missed_frames += 1
            self.wait_since = now
            last = self.sync.value('env', t)
            if last is None:    # nothing to go on with (frame 0): keep waiting, re-send clock
                return [Action(Act.MISSED, t, ['sim/environment'],
                               'still waiting (no environment yet); /clock re-sent'),
                        Action(Act.CLOCK, t)]
            self.sync.add('env', t, last)
            return [Action(Act.MISSED, t, ['sim/environment'],
                           'going on with the last environment, extrapolated by its rates')
                    ] + self._advance(now)
        # WAIT_CMD
        self.missed_frames += 1
        out = [Action(Act.MISSED, t, ['adcs/actuator_command'], 'applying a zero command')]
        for name in self.sync.record_misses(t):
            out.append(Action(Act.LOG, t, 'error',
                              f'adcs/actuator_command missed {self.sync.dead_after} command '
                              'frames in a row: its producer is treated as dead and no longer '
                              'awaited; a zero command is applied until it publishes again'
                              if name == 'cmd' else f'{name} treated as dead'))
        return out + self._step(ZERO, now)

    def free_running_frame(self) -> List[Action]:
        """Real-time mode (paced by a wall timer, never waiting): frame k with the latest
        inputs. Nothing happens (the clock is re-sent) until the first environment."""
        if self.phase is MasterPhase.DONE:
            return []
        t = self.t_ns
        out = [Action(Act.CLOCK, t)]
        env = self.sync.value('env', t)
        if env is None:
            return out
        out.append(Action(Act.STATE, t, env))
        if self.duration_ns and t >= self.duration_ns:
            return out + self._finish()
        out.append(Action(Act.STEP, t, (env, self.sync.value('cmd', t))))
        self.sync.prune(t)
        self.k += 1
        return out

    # ------------------------------------------------------------------ internals
    def _paced_start(self) -> float:
        """Wall time at which frame k of a paced run may start."""
        return self._pace_t0 + self.k * self.pace_s

    def _begin_frame(self, now: float) -> List[Action]:
        self.wait_since = now
        if self.lagging():
            if self.phase is not MasterPhase.THROTTLED:
                self.throttled_frames += 1
            self.phase = MasterPhase.THROTTLED
            return []
        if self.pace_s > 0.0:
            if self._pace_t0 is None:
                self._pace_t0 = now - self.k * self.pace_s
            if now < self._paced_start():
                self.phase = MasterPhase.PACED
                return []
        self.phase = MasterPhase.WAIT_ENV
        return [Action(Act.CLOCK, self.t_ns)] + self._advance(now)

    def _advance(self, now: float) -> List[Action]:
        t = self.t_ns
        out: List[Action] = []
        if self.phase is MasterPhase.WAIT_ENV and self.sync.has('env', t):
            out.append(Action(Act.STATE, t, self.sync.value('env', t)))
            if self.duration_ns and t >= self.duration_ns:
                self.phase = MasterPhase.WAIT_FINAL   # every node processes its last frame
                self.wait_since = now
                if self.all_final():
                    out += self._finish()
                return out
            self.phase = MasterPhase.WAIT_CMD
            self.wait_since = now
        if self.phase is MasterPhase.WAIT_CMD and not self.sync.missing(t):
            out += self._step(self._command(t), now)
        return out

    def _command(self, t: int) -> Any:
        """Command to apply over frame t: the one stamped t, ZERO (dead producer) or HOLD."""
        if self.sync.required_stamp('cmd', t) is None:
            return HOLD                            # not a command frame (or no commands)
        if self.sync.is_dead('cmd') or not self.sync.due('cmd', t):
            return ZERO                            # dead, or revived by this frame's command
        return self.sync.value('cmd', t)

    def _step(self, cmd: Any, now: float) -> List[Action]:
        t = self.t_ns
        out = [Action(Act.STEP, t, (self.sync.value('env', t), cmd))]
        self.sync.prune(t)
        self.k += 1
        return out + self._begin_frame(now)

    def _finish(self) -> List[Action]:
        if self.phase is MasterPhase.DONE:
            return []
        self.phase = MasterPhase.DONE
        return [Action(Act.FINISH, self.t_ns)]
