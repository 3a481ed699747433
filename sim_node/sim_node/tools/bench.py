"""``make bench``: lockstep throughput of the world, side by side, in one table.

Rows (DESIGN section 6):

1. transport limit: a bare 2-process ping-pong ring with the hop count of a world frame
   (:mod:`sim_node.tools.bench_ring`);
2. the world graph of ``scenarios/free_tumble.yaml`` (``environment`` + ``dynamics``), one
   process per node, in lockstep, at 1 s frames (10 RK4 substeps) and 0.1 s frames (1 substep),
   so the integration step is 0.1 s in both;
3. the same graph composed in one process (``Launcher(compose=True)``);
4. the same models in a plain Python loop without ROS (environment as the ``environment``
   node computes it, then ``Spacecraft.step``), and the free body + gravity-gradient RK4 rate
   alone, next to Basilisk's (a reference number, not measured here).

Every measurement is repeated (``--repeats``, interleaved); the table gives the median and
the min-max range. Then the design targets are checked, MET / NOT MET, as measured:
(2) >= 0.5 x (1), (3) >= 3 x (2), and (4) "comparable with Basilisk", taken here as within a
factor of 2 (>= 0.5 x its RK4 steps/s). The table goes to stdout and ``out/bench.txt``;
progress goes to stderr. Numbers are wall-clock throughput: other load on the machine
lowers them (the report prints the load average).

Usage::

    python -m sim_node.tools.bench [--frames 3000] [--repeats 3] [--quick]
"""
from __future__ import annotations

import argparse
import copy
import functools
import os
import platform
import shutil
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from sim_node.tools.bench_ring import RingError, RingResult, run_ring

DEFAULT_SCENARIO = 'scenarios/free_tumble.yaml'
#: Free body + gravity gradient RK4 steps per wall second of Basilisk (C++) for this case.
BASILISK_RK4_STEPS_PER_S = 50_000.0
#: (frame [s], RK4 substeps per frame): both integrate with a 0.1 s step.
DEFAULT_CASES = ((1.0, 10), (0.1, 1))
#: Design targets: graph >= 0.5 x ring; composed >= 3 x graph; plain loop >= 0.5 x Basilisk.
TARGET_GRAPH_VS_RING = 0.5
TARGET_COMPOSED_VS_GRAPH = 3.0
TARGET_LOOP_VS_BASILISK = 0.5


class BenchError(RuntimeError):
    """A measurement failed (a run did not finish); the message says which and why."""


@dataclass
class Stat:
    """Median and range of repeated measurements."""

    values: List[float]

    @property
    def median(self) -> float:
        """Median of the values."""
        return statistics.median(self.values)

    @property
    def lo(self) -> float:
        """Smallest value."""
        return min(self.values)

    @property
    def hi(self) -> float:
        """Largest value."""
        return max(self.values)


# ---------------------------------------------------------------------- machine
def machine_info() -> Dict[str, str]:
    """nproc, CPU model, Python and load average of this machine."""
    model = platform.processor() or 'unknown'
    try:
        with open('/proc/cpuinfo', encoding='utf-8') as fh:
            for line in fh:
                if line.startswith('model name'):
                    model = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        load = ' '.join(f'{x:.2f}' for x in os.getloadavg())
    except OSError:
        load = 'unknown'
    return {'nproc': str(os.cpu_count()), 'cpu': model, 'python': platform.python_version(),
            'load': load}


# ---------------------------------------------------------------------- (1) ring
class RingMeasure:
    """Frames/s of one :func:`run_ring` of ``frames`` round trips; keeps the last result."""

    def __init__(self, frames: int) -> None:
        self.frames = frames
        self.last: Optional[RingResult] = None

    def __call__(self) -> float:
        self.last = run_ring(self.frames)
        return self.last.frames_per_s


# ---------------------------------------------------------------------- (2), (3) graph
def scenario_with(sc: dict, frame_s: float, substeps: int) -> dict:
    """Copy of scenario ``sc`` with another frame and substep count."""
    out = copy.deepcopy(sc)
    out['timing']['frame_s'] = float(frame_s)
    out['timing']['substeps'] = int(substeps)
    return out


def graph_fps(sc: dict, frame_s: float, substeps: int, frames: int, compose: bool) -> float:
    """Lockstep frames per wall second of one launcher run, measured by the clock master
    from frame 0 to its end (its final ``lockstep/status``, ``RunResult.frames_per_s``)."""
    from adcs_nodes.tools.launcher import Launcher

    what = f'graph run (frame {frame_s:g} s, compose={compose})'
    run_dir = tempfile.mkdtemp(prefix='adcs-bench-')
    try:
        res = Launcher(scenario_with(sc, frame_s, substeps),
                       duration_s=round(frames * frame_s, 9), compose=compose,
                       progress=False, run_dir=run_dir, log=lambda *a, **k: None).run()
        if res.exit_code != 0:
            raise BenchError(f'{what} failed: exit {res.exit_code}, {res.message}')
        if res.missed_frames:
            raise BenchError(f'{what} missed {res.missed_frames} frames: not lockstep')
        fps = res.frames_per_s
        if not fps > 0.0:
            raise BenchError(f'{what}: no final status from the clock master')
        return fps
    finally:
        shutil.rmtree(run_dir, ignore_errors=True)


# ---------------------------------------------------------------------- (4) plain loop
class PlainWorld:
    """The world's models in a plain loop: what the two nodes compute, without ROS.

    Built from the same node parameters the launcher gives the nodes (``build_graph``).
    """

    def __init__(self, sc: dict, frame_s: float, substeps: int) -> None:
        from adcs_nodes.core.lockstep import derive_seed
        from adcs_nodes.nodes.lockstep_node import parse_epoch
        from adcs_nodes.tools.graph import build_graph
        from adcs_nodes.core.geomag import make_field
        from adcs_nodes.core.orbit import make_orbit
        from sim_node.models.spacecraft_config import DEFAULT_INITIAL, spacecraft_from_config

        nodes = {n.name: n.params for n in build_graph(sc, 1.0)}
        env, dyn = nodes['environment'], nodes['dynamics']
        self.epoch = parse_epoch(sc['epoch'])
        self.orbit = make_orbit(_section(env, 'orbit'), self.epoch)
        self.field = make_field(_section(env, 'field'), self.epoch)
        cfg = _section(dyn, 'spacecraft')
        self.spacecraft = spacecraft_from_config(
            cfg, seed=derive_seed(int(sc['seed']), 'dynamics/disturbance'))
        self.initial = {**DEFAULT_INITIAL, **_section(dyn, 'initial')}
        self.wheel_h0 = cfg.get('wheel_h0_Nms')
        self.frame_ns = int(round(frame_s * 1e9))
        self.substeps = int(substeps)
        self.command = self.spacecraft.zero_command()
        self.state = None

    def frame(self, k: int) -> None:
        """Frame k: environment at t_k (as ``EnvironmentNode.compute``), then integrate."""
        from sim_node.models.dynamics import FrameEnvironment
        from adcs_nodes.core.orbit import q_eci_ecef
        from sim_node.models.spacecraft_config import initial_state

        t = k * self.frame_ns / 1e9
        st = self.orbit.state(t)
        b_eci, b_dot_eci = self.field.field_and_rate(self.orbit, t)
        q_eci_ecef(self.epoch + timedelta(seconds=t))   # published by the node, unused here
        if self.state is None:
            self.state = initial_state(self.initial, st.q_eci_orbit, st.omega_orbit_eci_eci,
                                       self.spacecraft, self.wheel_h0)
        env = FrameEnvironment(r_eci=st.r_eci, v_eci=st.v_eci, b_eci=b_eci, b_dot_eci=b_dot_eci)
        self.state, _ = self.spacecraft.step(self.state, t, self.frame_ns / 1e9, env,
                                             self.command, self.substeps)


def _section(params: dict, prefix: str) -> dict:
    """Node parameters ``prefix.*`` without the prefix (as ``LockstepNode.section``)."""
    n = len(prefix) + 1
    return {k[n:]: v for k, v in params.items() if k.startswith(prefix + '.')}


def plain_fps(sc: dict, frame_s: float, substeps: int, frames: int) -> float:
    """Frames per wall second of :class:`PlainWorld` over ``frames`` frames."""
    world = PlainWorld(sc, frame_s, substeps)
    world.frame(0)   # initial state, imports
    start = time.perf_counter()
    for k in range(1, frames + 1):
        world.frame(k)
    return frames / (time.perf_counter() - start)


def free_body_steps(frames: int, substeps: int) -> float:
    """RK4 steps per wall second of the free body + gravity gradient (no environment).

    ``sim_node.models.dynamics.steps_per_second``: ``Spacecraft.step`` over 0.1 s frames,
    paper-000-like inertia, no disturbances; the frame's validation overhead is included.
    """
    from sim_node.models.dynamics import steps_per_second
    return steps_per_second(frames, substeps)


# ---------------------------------------------------------------------- table
@dataclass
class Row:
    """One line of the table, with the measurement that fills it.

    ``measure()`` returns frames per wall second (``kind='fps'``) or RK4 steps per wall
    second (``kind='rk4'``); each call is one repeat. A row without it is a reference line.
    """

    label: str
    deployment: str
    frame_s: float = 0.0
    substeps: int = 0
    measure: Optional[Callable[[], float]] = None
    kind: str = 'fps'
    note: str = ''
    values: List[float] = field(default_factory=list)

    def stat(self, kind: str) -> Optional[Stat]:
        """Frames/s (``'fps'``) or RK4 steps/s (``'rk4'``) of this row, if it has them."""
        if not self.values:
            return None
        if kind == self.kind:
            return Stat(self.values)
        if kind == 'rk4' and self.substeps:
            return Stat([v * self.substeps for v in self.values])
        return None


def _num(x: float) -> str:
    return f'{x:,.0f}' if x >= 100 else f'{x:,.1f}'


def _stat(s: Optional[Stat], scale: float = 1.0) -> str:
    if s is None:
        return '-'
    if len(s.values) == 1:
        return _num(s.median * scale)
    return f'{_num(s.median * scale)} ({_num(s.lo * scale)}-{_num(s.hi * scale)})'


def _cells(r: Row) -> List[str]:
    """Table cells of a row: the range only on the measured quantity, medians elsewhere."""
    fps, rk4 = r.stat('fps'), r.stat('rk4')
    frame = f'{r.frame_s:g} s' if r.frame_s else '-'
    step = f'{r.frame_s / r.substeps:g} s x {r.substeps}' if r.substeps else '-'
    us = f'{1e6 / fps.median:,.0f}' if fps is not None else '-'
    sim = _num(fps.median * r.frame_s) if fps is not None and r.frame_s else '-'
    steps = _stat(rk4) if r.kind == 'rk4' else (_num(rk4.median) if rk4 is not None else '-')
    return [r.label, r.deployment, frame, step, _stat(fps), us, sim, steps, r.note]


HEADER = ['', 'measurement', 'frame', 'RK4 step x n', 'frames/s', 'us/frame', 'sim s/wall s',
          'RK4 steps/wall s', '']


def format_table(rows: Sequence[Row]) -> str:
    """Aligned plain-text table of ``rows`` (numbers right-aligned)."""
    cells = [HEADER] + [_cells(r) for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(HEADER))]
    right = {4, 5, 6, 7}
    lines = []
    for n, c in enumerate(cells):
        parts = [c[i].rjust(widths[i]) if i in right else c[i].ljust(widths[i])
                 for i in range(len(c))]
        lines.append('  '.join(parts).rstrip())
        if n == 0:
            lines.append('-' * len(lines[0]))
    return '\n'.join(lines)


def verdict(name: str, ratio: float, target: float, detail: str) -> str:
    """One MET / NOT MET line."""
    ok = 'MET' if ratio >= target else 'NOT MET'
    return f'  {name:<44} {ratio:5.2f} x  (target >= {target:3.1f} x)  {ok:<7}  {detail}'


# ---------------------------------------------------------------------- main
def plan(sc: dict, frames: int, cases: Sequence[Tuple[float, int]]) -> List[Row]:
    """The table's rows, each with the measurement that fills it (not run yet)."""
    rows = [Row('(1)', 'transport ring, 2 processes', note='2 hops per frame',
                measure=RingMeasure(3 * frames))]
    for compose, tag, what in ((False, '(2)', 'world graph, 1 process/node'),
                               (True, '(3)', 'world graph, composed')):
        for frame_s, sub in cases:
            rows.append(Row(tag, what, frame_s, sub, measure=functools.partial(
                graph_fps, sc, frame_s, sub, frames, compose)))
    for frame_s, sub in cases:
        rows.append(Row('(4)', 'plain Python loop, no ROS', frame_s, sub,
                        measure=functools.partial(plain_fps, sc, frame_s, sub, frames)))
    rows.append(Row('(4)', 'free body + grav. gradient', 0.1, 10, kind='rk4',
                    note='Spacecraft.step only',
                    measure=functools.partial(free_body_steps, max(1, frames // 2), 10)))
    rows.append(Row('ref', 'Basilisk (C++), same case', kind='rk4',
                    values=[BASILISK_RK4_STEPS_PER_S], note='reference, not measured here'))
    return rows


def _find(rows: Sequence[Row], label: str, frame_s: float = 0.0, kind: str = 'fps') -> Stat:
    row = next(r for r in rows if r.label == label and r.frame_s == frame_s and r.kind == kind)
    return row.stat(kind)


def run_bench(scenario: str, frames: int, repeats: int, cases: Sequence[Tuple[float, int]],
              log: Callable[[str], None]) -> str:
    """Run every measurement and return the report text (table, breakdown, targets).

    The repeats are interleaved (every row once, then again), so a change of machine load
    during the bench spreads over all rows instead of biasing one.
    """
    from adcs_nodes.tools.scenario import load_scenario

    sc = load_scenario(scenario)
    info = machine_info()
    t_start = time.monotonic()
    rows = plan(sc, frames, cases)
    for rep in range(repeats):
        for r in rows:
            if r.measure is None:
                continue
            frame = f', {r.frame_s:g} s frames' if r.frame_s else ''
            log(f'[bench] repeat {rep + 1}/{repeats}: {r.label} {r.deployment}{frame} ...')
            r.values.append(float(r.measure()))
    elapsed = time.monotonic() - t_start
    load_end = machine_info()['load']
    ring_meta = rows[0].measure.last

    out = [
        f'ADCS lockstep throughput bench, {datetime.now().strftime("%Y-%m-%d %H:%M")}, '
        f'scenario {os.path.basename(scenario)}',
        f'machine: nproc {info["nproc"]}, {info["cpu"]}, Python {info["python"]}, '
        f'rclpy executor {ring_meta.executor}, RMW {ring_meta.rmw}',
        f'load average (1/5/15 min): {info["load"]} at start, {load_end} at end',
        f'sizes: {frames} frames per graph/loop run, {3 * frames} round trips per ring run; '
        f'{repeats} interleaved repeats per row: median (min-max); took {elapsed:.0f} s',
        '',
        format_table(rows),
        '',
        'Per frame (medians; lockstep is sequential, so the parts add up):',
    ]
    ring = _find(rows, '(1)')
    ring_us = 1e6 / ring.median
    for frame_s, _ in cases:
        g_us = 1e6 / _find(rows, '(2)', frame_s).median
        c_us = 1e6 / _find(rows, '(3)', frame_s).median
        p_us = 1e6 / _find(rows, '(4)', frame_s).median
        out.append(f'  {frame_s:g} s frames: graph {g_us:,.0f} us = transport {ring_us:,.0f} '
                   f'+ models {p_us:,.0f} + node/message overhead {g_us - ring_us - p_us:,.0f}'
                   f'; composed {c_us:,.0f} us = models {p_us:,.0f} + rest {c_us - p_us:,.0f}')
    out += ['', 'Design targets, as measured:']
    for frame_s, _ in cases:
        g = _find(rows, '(2)', frame_s).median
        c = _find(rows, '(3)', frame_s).median
        out.append(verdict(f'(2) graph >= 0.5 x (1) ring, {frame_s:g} s frames', g / ring.median,
                           TARGET_GRAPH_VS_RING, f'{_num(g)} vs {_num(ring.median)} frames/s'))
        out.append(verdict(f'(3) composed >= 3 x (2) graph, {frame_s:g} s frames', c / g,
                           TARGET_COMPOSED_VS_GRAPH, f'{_num(c)} vs {_num(g)} frames/s'))
    free = _find(rows, '(4)', 0.1, kind='rk4')
    out.append(verdict('(4) RK4 comparable with Basilisk (>= 0.5 x)',
                       free.median / BASILISK_RK4_STEPS_PER_S, TARGET_LOOP_VS_BASILISK,
                       f'{_num(free.median)} vs {_num(BASILISK_RK4_STEPS_PER_S)} RK4 steps/s'))
    out += ['', f'Noise: {info["nproc"]} cores and other work may be running (load average '
            'above): compare the ranges, not the last digits.']
    return '\n'.join(out) + '\n'


def parse_cases(text: str) -> List[Tuple[float, int]]:
    """``"1.0:10,0.1:1"`` -> ``[(1.0, 10), (0.1, 1)]`` (frame [s] : RK4 substeps)."""
    cases = []
    for item in text.split(','):
        frame, _, sub = item.partition(':')
        cases.append((float(frame), int(sub or 1)))
    if not cases or any(f <= 0 or s < 1 for f, s in cases):
        raise argparse.ArgumentTypeError(f'bad --cases {text!r} (want e.g. 1.0:10,0.1:1)')
    return cases


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of ``make bench``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--frames', type=int, default=3000,
                    help='lockstep frames per graph and loop run (the ring runs 3x as many)')
    ap.add_argument('--repeats', type=int, default=3, help='runs per row (median, min-max)')
    ap.add_argument('--quick', action='store_true', help='500 frames, 2 repeats')
    ap.add_argument('--cases', type=parse_cases, default=list(DEFAULT_CASES),
                    help='frame_s:substeps list (default 1.0:10,0.1:1)')
    ap.add_argument('--scenario', default=DEFAULT_SCENARIO)
    ap.add_argument('--out', default='out/bench.txt', help='also write the report here')
    args = ap.parse_args(argv)
    if args.quick:
        args.frames, args.repeats = 500, 2
    if args.frames < 1 or args.repeats < 1:
        ap.error('--frames and --repeats must be >= 1')

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    try:
        text = run_bench(args.scenario, args.frames, args.repeats, args.cases, log)
    except (BenchError, RingError) as exc:
        print(f'[bench] failed: {exc}', file=sys.stderr)
        return 1
    sys.stdout.write(text)
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, 'w', encoding='utf-8') as fh:
            fh.write(text)
        log(f'[bench] written to {args.out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
