"""The start handshake of a lockstep node (no fixed sleeps, DESIGN section 6).

The launcher knows the whole graph, so it tells each node how many DDS endpoints must be
matched before it is ready: ``expected_matches`` entries ``"pub:<topic>=<n>"`` (that many
subscriptions matched to our publisher) and ``"sub:<topic>=<n>"`` (that many publishers
matched to our subscription). When all hold (and the node's own ready checks are empty), the
node publishes its name on the latched ``lockstep/ready``; the clock master starts frame 0
when every node it waits for said ready. A node started alone has no expectations.

A consumer of an external driver's topic also waits, at most :data:`EXTERNAL_WAIT_S` of wall
time, for a publisher on it (:class:`DriverWait`); then it starts without it.

Pure Python, no ROS: the node adapter gives matched counts and wall times [s].
"""
from __future__ import annotations

from typing import Callable, Iterable, List, Optional, Tuple

#: Wall seconds a consumer of an external driver's topic waits for its publisher.
EXTERNAL_WAIT_S = 60.0
#: Wall seconds between two "waiting for the driver" lines.
EXTERNAL_WAIT_LOG_S = 10.0
#: Wall seconds between two "still waiting for endpoints" lines.
ENDPOINT_WAIT_LOG_S = 10.0

Expectation = Tuple[str, str, int]      # ('pub' | 'sub', resolved topic, matched count)


def parse_expectations(raw: Iterable[str], resolve: Callable[[str], str]) -> List[Expectation]:
    """``expected_matches`` entries as ``(kind, resolved topic, n)``; ValueError for a bad
    one (empty entries are skipped)."""
    out = []
    for item in raw:
        if not item:
            continue
        try:
            kind, rest = item.split(':', 1)
            topic, n = rest.rsplit('=', 1)
            if kind not in ('pub', 'sub'):
                raise ValueError(kind)
            out.append((kind, resolve(topic), int(n)))
        except ValueError as exc:
            raise ValueError(f'bad expected_matches entry {item!r} '
                             '(want "pub:<topic>=<n>" or "sub:<topic>=<n>")') from exc
    return out


def unmet(expected: List[Expectation], matched: Callable[[str, str], Optional[int]],
          node: str, known: Optional[Callable[[str, str], int]] = None) -> List[str]:
    """The expectations not met, as readable strings. ``matched(kind, topic)``: endpoints
    matched now (None: the node has no such endpoint); with ``known(kind, topic)``, also how
    many peer endpoints discovery knows there (more known than matched: discovered but not
    matched; as few: never discovered)."""
    out = []
    for kind, topic, n in expected:
        have = matched(kind, topic)
        if have is None:
            out.append(f'{kind}:{topic} (no such endpoint in {node})')
        elif have < n:
            out.append(f'{kind}:{topic} {have}/{n}' + (
                '' if known is None else f' (discovery knows {known(kind, topic)})'))
    return out


class DriverWait:
    """The wait of a consumer for the publishers of its external drivers' topics: at most
    :data:`EXTERNAL_WAIT_S` from the first call, a warning every :data:`EXTERNAL_WAIT_LOG_S`,
    then the node starts without them (it will be starved: the run is degraded)."""

    def __init__(self) -> None:
        self.t0: Optional[float] = None
        self.logged: Optional[float] = None
        self.gave_up = False

    def check(self, missing: List[str], now_s: float) -> Tuple[bool, Optional[Tuple[str, str]]]:
        """``(still waiting, (level, line) to log or None)`` with the topics ``missing`` a
        publisher now."""
        if not missing or self.gave_up:
            return False, None
        if self.t0 is None:
            self.t0 = now_s
        waited, topics = now_s - self.t0, ', '.join(missing)
        if waited > EXTERNAL_WAIT_S:
            self.gave_up = True
            return False, ('warning', f'no publisher on {topics} after {EXTERNAL_WAIT_S:g} '
                           's: starting without it (if nothing usable comes, this node is '
                           'starved and the run degraded)')
        if self.logged is not None and now_s - self.logged < EXTERNAL_WAIT_LOG_S:
            return True, None
        self.logged = now_s
        return True, ('warning', f'waiting for a publisher on {topics} (an external driver: '
                      'start it on this run\'s ROS_DOMAIN_ID; any QoS) for '
                      f'{waited:.0f} s; the run starts when it is matched, or without it '
                      f'after {EXTERNAL_WAIT_S:g} s')


def first_line(mode: str, waits: List[str], publishes: List[str], alone: bool,
               period_s: float = 0.0, sim_time: bool = False, world: bool = False) -> str:
    """The line a node logs when it starts: its timing, what it waits for, what it publishes,
    and (``alone``: no launcher expectations) what makes it go."""
    outs = ', '.join(publishes) or 'nothing'
    if mode == 'live':
        return (f'live: fires every {period_s:g} s of the ROS clock ('
                f'{"/clock" if sim_time else "wall time"}) with the newest samples of '
                f'{", ".join(waits) or "no input"}; publishes {outs} (timing_mode:=lockstep '
                'runs it with the simulator)')
    line = (f'lockstep: fires each frame of /clock once its inputs of that frame are in; '
            f'waits for {", ".join(["/clock"] + waits)}; publishes {outs}')
    if alone:
        line += ('; started alone, it stays idle until a simulator publishes /clock (`adcs '
                 'run` starts one)' + ('' if world else '; timing_mode:=live runs it on '
                                       'the ROS clock with real drivers'))
    return line
