"""``make bench``: a fair throughput bench of the paper-000 closed loop, in one table.

Every row is measured in the same run, on the same machine, at the same time (issue 13):

1. ``ring``: a bare 2-process rclpy relay (:mod:`perf.bench_ring`) that makes the
   graph's own number of message deliveries in each frame (:func:`delivery_pattern`: every
   message a frame publishes times the nodes subscribed to its topic; paper000_control at 1 s
   frames: 22 on magnetometer frames, 19 on the other command frames, 10 on the rest, 14.8 a
   frame), one after the other; ``1h``: the same ring with the hops of the graph's critical
   path only (:func:`hop_pattern`: 7, 4 or 2, 3.3 a frame; the earlier target's ring, shown
   for comparison);
2. ``graph``: ``scenarios/paper000_control.yaml`` (environment, dynamics, magnetometer,
   estimator, two controllers, controller manager), one process per node, in lockstep, at
   1 s frames with 10 RK4 substeps (0.1 s truth step);
3. ``composed``: the same graph in one process (``Launcher(compose=True)``), all messages
   over DDS as in the graph (``ADCS_COMPOSE_INPROC=0``, the runner's ``--dds``); ``3i``: the
   same with the composed runner's in-process path (its default since issue 13;
   ``ADCS_COMPOSE_INPROC=1``: DDS only where an outside subscriber is matched; the
   launcher's progress monitor reads only ``lockstep/status``, which no node of the graph
   reads, so every topic between the nodes goes in process);
4. ``plain engine``: the FrameLoop (:class:`sim_node.engine.FrameLoop`: the same components
   as the nodes, built from the same node parameters, stepped in the lockstep order, no ROS)
   at the bench's 1 s frames; ``4p``: the same at the scenario's own frames (paper000_control:
   2 s frames, 20 substeps), the issue's 10,000 x real-time target printed with the factor
   it misses by;
5. ``free body``: free rigid body + gravity gradient with this project's RK4
   (``Spacecraft.step``, paper 000 inertia diag(118, 118, 19.6) kg m^2, 0.1 s step);
6. ``Basilisk``: the same model set in Basilisk (``bsk`` from PyPI: ``Spacecraft`` hub with
   ``GravityGradientEffector``, same inertia, same 0.1 s RK4 step; Basilisk also integrates
   the orbit with point-mass gravity). Bench-only dependency: installed on demand into its own
   virtual environment (``~/.cache/adcs/bsk-venv``, or ``$ADCS_BSK_VENV``) so its pins never
   touch the workspace's; the row is skipped with the reason if that fails;
7. ``start-up`` (issue 35): the CPU of all node processes from ``adcs run`` of the scenario as
   shipped to their first frame (each lockstep node logs its process CPU then, and before its
   ``main`` ran: the interpreter start and imports), one process per node (``7g``: the run's
   zygote, which logs its own CPU, plus its forked children) and composed (``7c``); below the
   table, each process's figures;
8. ``campaign``: ``adcs montecarlo`` of 100 dispersed runs of 6 orbits of the scenario on the
   plain engine, ``--jobs 2`` (:class:`CampaignMeasure`; measured once, not repeated).

Each row gives frames (or RK4 steps) per wall second, sim seconds per wall second and per
CPU second, the wall time and the CPU seconds of all its processes (``resource.getrusage``
of this process and of its children, start-up included), the CPU per frame over the timed
frames only (graph rows: the difference to a short run of the same graph, which removes the
start-up), and the 1-minute load average when the row started. Repeats are interleaved; the
table gives medians (rate: min-max). On a loaded machine the CPU columns are the steadier
measure: a process waiting for a core counts wall time, not CPU time.

Targets, as ratios of this run (a target not met prints NOT MET with its ratio):
(a) graph >= 0.8 x the ring of the graph's own deliveries per frame (issue 19; it replaces
"graph >= 0.5 x the critical-path ring", which compared 14.8 deliveries a frame with 3.3);
(b) composed >= 3 x graph; (c) composed paper000 at 1 s frames >= 2000 x real time ((b) and
(c) for both composed rows); (d) free-body plain loop >= 0.5 x Basilisk; (e) the plain
engine >= 10,000 x real time (rows 4 and 4p; issue 19), by wall time and by CPU time. Also
printed: the plain engine (4) against Basilisk (6) in sim seconds per wall and per CPU
second (Basilisk integrates the free body alone, the FrameLoop the whole closed loop).
(f) start-up CPU to frame 0, one process per node <= 2.0 x composed (row 7; issue 35).
(g) the campaign's CPU (all its processes) <= 1.05 x the sum of its runs' FrameLoop CPU
(row 8; issue 35; its wall time and CPU split beside it).

Usage::

    PYTHONPATH=tests python -m perf.bench [--frames 2000] [--repeats 2] [--quick]
                                   [--basilisk auto|skip] [--out out/bench.txt]
                                   [--rows 1,1h,2,3,3i,4,4p,5,6,7g,7c,8]
                                   [--campaign-runs 100] [--campaign-orbits 6]
"""
from __future__ import annotations

import argparse
import copy
import glob
import json
import math
import os
import platform
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from perf.bench_ring import RingError, run_ring

DEFAULT_SCENARIO = 'scenarios/paper000_control.yaml'
#: Bench frame [s] and RK4 substeps: the target (c) is stated at 1 s frames, 0.1 s step.
FRAME_S, SUBSTEPS = 1.0, 10
#: Frames of the short graph run whose CPU is subtracted (start-up) for the CPU per frame.
SHORT_FRAMES = 20
#: Paper 000 inertia [kg m^2] of the free-body rows (the scenario's).
INERTIA_DIAG = (118.0, 118.0, 19.6)
TARGET_GRAPH_VS_RING = 0.8
TARGET_COMPOSED_VS_GRAPH = 3.0
TARGET_REAL_TIME = 2000.0
TARGET_LOOP_VS_BASILISK = 0.5
TARGET_PLAIN_REAL_TIME = 10_000.0
TARGET_START_GRAPH_VS_COMPOSED = 2.0
TARGET_CAMPAIGN_CPU = 1.05
BSK_VENV = os.environ.get('ADCS_BSK_VENV',
                          os.path.join(os.path.expanduser('~'), '.cache', 'adcs', 'bsk-venv'))


class BenchError(RuntimeError):
    """A measurement failed (a run did not finish); the message says which and why."""


@dataclass
class Sample:
    """One measurement: ``n`` frames (or RK4 steps) at ``rate`` per wall second.

    ``wall_s`` and ``cpu_s``: the whole measurement, start-up included, all processes;
    ``cpu_per_unit_s``: CPU per frame over the timed frames only (``None``: not known).
    """

    n: int
    rate: float
    wall_s: float
    cpu_s: float
    cpu_per_unit_s: Optional[float] = None


@dataclass
class Row:
    """One line of the table and the measurement that fills it (one call per repeat)."""

    key: str
    label: str
    unit: str = 'frames'
    step_s: float = FRAME_S
    measure: Optional[Callable[[], Sample]] = None
    note: str = ''
    samples: List[Sample] = field(default_factory=list)
    loads: List[float] = field(default_factory=list)
    skipped: str = ''

    def median(self, attr: str) -> Optional[float]:
        """Median of a :class:`Sample` attribute over the repeats (``None`` if unknown)."""
        vals = [getattr(s, attr) for s in self.samples if getattr(s, attr) is not None]
        return statistics.median(vals) if vals else None

    @property
    def rate(self) -> Optional[float]:
        """Median rate [1/s] (frames or RK4 steps per wall second)."""
        return self.median('rate')

    @property
    def cpu_real_time(self) -> Optional[float]:
        """Sim seconds per CPU second over the timed units (``None``: not known)."""
        cpu = self.median('cpu_per_unit_s')
        return self.step_s / cpu if cpu else None


def _cpu_now() -> float:
    """CPU seconds of this process plus its waited-for children."""
    total = 0.0
    for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN):
        ru = resource.getrusage(who)
        total += ru.ru_utime + ru.ru_stime
    return total


def load1() -> float:
    """1-minute load average (NaN if unknown)."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return float('nan')


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


# ---------------------------------------------------------------------- scenario
def bench_scenario(sc: dict, frame_s: float = FRAME_S, substeps: int = SUBSTEPS) -> dict:
    """Copy of scenario ``sc`` with the bench's frame and substep count."""
    out = copy.deepcopy(sc)
    out['timing']['frame_s'] = float(frame_s)
    out['timing']['substeps'] = int(substeps)
    return out


def _periods(sc: dict) -> Dict[str, float]:
    mag = (sc.get('sensors') or {}).get('magnetometer') or {}
    ctrl = sc.get('controllers') or {}
    return {'mag': float(mag.get('period_s', 0.0)) if mag else 0.0,
            'cmd': float(ctrl.get('period_s', 0.0)) if ctrl else 0.0}


def hop_pattern(sc: dict, frame_s: float) -> List[int]:
    """Messages on the critical path of each frame of one cycle of the graph.

    The clock master starts frame k+1 when it has the environment and, when a command is due,
    the command stamped t_k: ``/clock -> environment -> dynamics`` (2 hops); with a command
    due, ``/clock -> estimator -> controller -> manager -> dynamics`` (4); when the
    magnetometer also samples, ``/clock -> environment -> dynamics -> sim/state ->
    magnetometer -> estimator -> controller -> manager -> dynamics`` (7, the estimator
    waits for the sample). Periods not a multiple of the frame count as every frame.
    """
    per = _periods(sc)
    steps = {k: max(1, int(round(v / frame_s))) if v > 0 else 0 for k, v in per.items()}
    cycle = math.lcm(*(s for s in steps.values() if s)) if any(steps.values()) else 1
    out = []
    for k in range(cycle):
        cmd = steps['cmd'] and k % steps['cmd'] == 0
        mag = steps['mag'] and k % steps['mag'] == 0
        out.append(7 if (cmd and mag) else 4 if cmd else 2)
    return out


def delivery_pattern(sc: dict, frame_s: float) -> List[int]:
    """Messages delivered between the graph's nodes in each frame of one cycle of
    :func:`hop_pattern`: every message the frame publishes (the FrameLoop's outputs: the
    graph's data topics and ``/clock``) times the nodes that subscribe to its topic
    (``build_graph``'s wiring). Frames 1 to ``cycle`` (frame 0 is the start-up), in the order
    of :func:`hop_pattern` (frame ``cycle`` first: the same phase as frame 0)."""
    from collections import Counter

    from adcs_nodes.graph import build_graph
    from sim_node.engine import FrameLoop

    cycle = len(hop_pattern(sc, frame_s))
    duration = (cycle + 1) * frame_s
    specs = build_graph(sc, duration)
    subs = Counter(t.lstrip('/') for s in specs for t in s.subscribes)
    counts = [sum(subs[topic.lstrip('/')] for topic, _ in frame.outputs)
              for frame in FrameLoop(specs, duration).run()]
    return [counts[cycle]] + counts[1:cycle]


# ---------------------------------------------------------------------- (1) ring
def ring_sample(hops: Sequence[int], frames: int) -> Sample:
    """Timed ring of ``frames`` frames with ``hops`` per frame."""
    t0 = time.monotonic()
    r = run_ring(frames, hops)
    wall = time.monotonic() - t0
    return Sample(frames, r.frames_per_s, wall, r.cpu_total_s, r.cpu_s / frames)


# ---------------------------------------------------------------------- (2), (3) graph
def graph_run(sc: dict, frames: int, compose: bool, inproc: bool = False) -> Sample:
    """One launcher run of ``frames`` frames: the clock master's frames/s, wall, CPU.

    ``inproc``: the composed runner's in-process path (``ADCS_COMPOSE_INPROC=1`` for the
    children)."""
    from adcs_nodes.tools.run.launcher import Launcher

    what = f'graph run ({frames} frames, compose={compose}, inproc={inproc})'
    run_dir = tempfile.mkdtemp(prefix='adcs-bench-')
    frame_s = float(sc['timing']['frame_s'])
    old = os.environ.get('ADCS_COMPOSE_INPROC')
    os.environ['ADCS_COMPOSE_INPROC'] = '1' if inproc else '0'
    cpu0, t0 = _cpu_now(), time.monotonic()
    try:
        res = Launcher(sc, duration_s=round(frames * frame_s, 9), compose=compose,
                       progress=False, run_dir=run_dir, log=lambda *a, **k: None).run()
        if res.exit_code != 0:
            raise BenchError(f'{what} failed: exit {res.exit_code}, {res.message}')
        if res.missed_frames:
            raise BenchError(f'{what} missed {res.missed_frames} frames: not lockstep')
        if not res.frames_per_s > 0.0:
            raise BenchError(f'{what}: no final status from the clock master')
        return Sample(frames, res.frames_per_s, time.monotonic() - t0, _cpu_now() - cpu0)
    finally:
        if old is None:
            os.environ.pop('ADCS_COMPOSE_INPROC', None)
        else:
            os.environ['ADCS_COMPOSE_INPROC'] = old
        shutil.rmtree(run_dir, ignore_errors=True)


class GraphMeasure:
    """Repeated graph runs; the first call also times a short run (start-up CPU)."""

    def __init__(self, sc: dict, frames: int, compose: bool, inproc: bool = False) -> None:
        self.sc, self.frames, self.compose, self.inproc = sc, frames, compose, inproc
        self.short: Optional[Sample] = None

    def __call__(self) -> Sample:
        if self.short is None:
            self.short = graph_run(self.sc, SHORT_FRAMES, self.compose, self.inproc)
        s = graph_run(self.sc, self.frames, self.compose, self.inproc)
        if self.frames > SHORT_FRAMES:
            extra = self.frames - SHORT_FRAMES
            s.cpu_per_unit_s = max(0.0, s.cpu_s - self.short.cpu_s) / extra
        return s


# ---------------------------------------------------------------------- (7) start-up
#: The line every lockstep node logs at its first frame (``LockstepNode.frame_done``), and the
#: zygote after its imports and each fork (``adcs_nodes.tools.run.zygote``).
START_COST = re.compile(r'\[([A-Za-z0-9_./]+)\]: start cost (\{.*\})\s*$', re.M)
#: Frames of a start-up run (the nodes log their CPU at the first).
START_FRAMES = 2


def start_costs(run_dir: str) -> Dict[str, dict]:
    """Per node process (log file) of a finished run: CPU seconds at the first frame (the
    largest of its nodes' lines: a composed process logs one per node), the CPU before its
    ``main`` ran (interpreter start and imports; one process per node only) and its nodes."""
    out: Dict[str, dict] = {}
    for path in sorted(glob.glob(os.path.join(run_dir, 'logs', '*.log'))):
        with open(path, encoding='utf-8', errors='replace') as fh:
            lines = [(m.group(1).rsplit('.', 1)[-1], json.loads(m.group(2)))
                     for m in START_COST.finditer(fh.read())]
        if lines:
            out[os.path.basename(path)[:-4]] = {
                'cpu_s': max(c['cpu_s'] for _, c in lines),
                'import_cpu_s': max(c.get('import_cpu_s', 0.0) for _, c in lines),
                'nodes': sorted(n for n, _ in lines)}
    return out


class StartupMeasure:
    """A run of :data:`START_FRAMES` frames; its sample's ``cpu_s``: the CPU of all node
    processes from their start to their first frame (from their logs); ``rate``: not a rate
    (NaN). ``details``: the per-process costs of each repeat."""

    def __init__(self, sc: dict, compose: bool) -> None:
        self.sc, self.compose = sc, compose
        self.details: List[Dict[str, dict]] = []

    def __call__(self) -> Sample:
        from adcs_nodes.tools.run.launcher import Launcher

        run_dir = tempfile.mkdtemp(prefix='adcs-bench-start-')
        t0 = time.monotonic()
        try:
            res = Launcher(self.sc, duration_s=START_FRAMES * float(self.sc['timing']['frame_s']),
                           compose=self.compose, progress=False, run_dir=run_dir,
                           log=lambda *a, **k: None).run()
            costs = start_costs(run_dir)
        finally:
            shutil.rmtree(run_dir, ignore_errors=True)
        if res.exit_code != 0 or not costs:
            raise BenchError(f'start-up run (compose={self.compose}) failed: exit '
                             f'{res.exit_code}, {res.message}; start costs logged: {costs}')
        self.details.append(costs)
        return Sample(len(costs), math.nan, time.monotonic() - t0,
                      sum(c['cpu_s'] for c in costs.values()))


def startup_lines(graph: Row, comp: Row) -> List[str]:
    """Row (7)'s target line and, per node process of the graph, its CPU to the first frame
    and before ``main`` (imports), medians over the repeats."""
    ratio = _ratio(graph.median('cpu_s'), comp.median('cpu_s'))
    if ratio is None:
        return ['  (f) start-up CPU graph / composed <= 2.0: NOT MEASURED']
    ok = 'MET' if ratio <= TARGET_START_GRAPH_VS_COMPOSED else 'NOT MET'
    out = [f'  {"(f) start-up CPU to frame 0, graph (7g) / composed (7c)":<50} {ratio:7.2f} x  '
           f'(target <= {TARGET_START_GRAPH_VS_COMPOSED:g} x)  {ok:<7}  '
           f'{_num(graph.median("cpu_s"))} vs {_num(comp.median("cpu_s"))} CPU s',
           '  (7g) per node process, CPU s to its first frame (of it before main: imports):']
    for name in sorted(graph.measure.details[0]):
        runs = [d[name] for d in graph.measure.details if name in d]
        out.append(f'       {name:<22} {statistics.median(r["cpu_s"] for r in runs):6.2f}  '
                   f'({statistics.median(r["import_cpu_s"] for r in runs):.2f})')
    return out


# ---------------------------------------------------------------------- (4) plain engine
def plain_sample(sc: dict, frames: int) -> Sample:
    """The plain engine (:class:`sim_node.engine.FrameLoop`), ``frames`` frames, no sink.

    The same components as the nodes, built from the same node parameters (``build_graph``),
    stepped in the lockstep order. Construction (and kernel compilation/cache load) is in the
    wall and CPU columns, not in the rate.
    """
    from sim_node.engine import FrameLoop

    cpu0, w0 = _cpu_now(), time.monotonic()
    loop = FrameLoop.from_scenario(sc, duration_s=frames * float(sc['timing']['frame_s']))
    c1, t1 = time.process_time(), time.perf_counter()
    for _ in loop.run():
        pass
    dt, dc = time.perf_counter() - t1, time.process_time() - c1
    n = loop.k + 1                                  # frames 0 .. frames
    return Sample(n, n / dt, time.monotonic() - w0, _cpu_now() - cpu0, dc / n)


# ---------------------------------------------------------------------- (5) free body
def free_body_sample(steps: int, step_s: float = 0.1, per_frame: int = 10) -> Sample:
    """Free rigid body + gravity gradient, this project's RK4: ``Spacecraft.step`` frames of
    ``per_frame`` RK4 steps of ``step_s``, circular 690 km orbit from the orbit model."""
    import numpy as np

    from adcs_nodes.core.orbit import make_orbit
    from sim_node.models.dynamics import FrameEnvironment, Spacecraft, SpacecraftState

    orbit = make_orbit({'type': 'circular', 'altitude_km': 690.0, 'inclination_deg': 98.0},
                       datetime(2026, 1, 1, tzinfo=timezone.utc))
    sc = Spacecraft(np.diag(INERTIA_DIAG))
    state = SpacecraftState(np.array([0.48, -0.48, 0.64, 0.36]), np.radians([-3.0, 3.0, 3.0]))
    command = sc.zero_command()
    frames = max(1, steps // per_frame)
    frame_s = step_s * per_frame
    cpu0, w0 = _cpu_now(), time.monotonic()
    c1, t1 = time.process_time(), time.perf_counter()
    for k in range(frames):
        st = orbit.state(k * frame_s)
        env = FrameEnvironment(r_eci=st.r_eci, v_eci=st.v_eci)
        state, _ = sc.step(state, k * frame_s, frame_s, env, command, per_frame)
    dt, dc = time.perf_counter() - t1, time.process_time() - c1
    n = frames * per_frame
    return Sample(n, n / dt, time.monotonic() - w0, _cpu_now() - cpu0, dc / n)


# ---------------------------------------------------------------------- (6) Basilisk
#: Runs in the Basilisk environment: free body + gravity gradient, RK4 at ``step`` seconds.
BSK_SCRIPT = r'''
import json, sys, time
from Basilisk.simulation import spacecraft, GravityGradientEffector
from Basilisk.utilities import SimulationBaseClass, macros, orbitalMotion, simIncludeGravBody
steps, step_s, ixx, iyy, izz = int(sys.argv[1]), float(sys.argv[2]), *map(float, sys.argv[3:6])
sim = SimulationBaseClass.SimBaseClass()
proc = sim.CreateNewProcess('p')
proc.addTask(sim.CreateNewTask('t', macros.sec2nano(step_s)))
sc = spacecraft.Spacecraft()
sc.ModelTag = 'sc'
sc.hub.mHub = 100.0
sc.hub.IHubPntBc_B = [[ixx, 0.0, 0.0], [0.0, iyy, 0.0], [0.0, 0.0, izz]]
sim.AddModelToTask('t', sc)
grav = simIncludeGravBody.gravBodyFactory()
earth = grav.createEarth()
earth.isCentralBody = True
grav.addBodiesTo(sc)
gg = GravityGradientEffector.GravityGradientEffector()
gg.ModelTag = 'gg'
gg.addPlanetName(earth.planetName)
sc.addDynamicEffector(gg)
sim.AddModelToTask('t', gg)
oe = orbitalMotion.ClassicElements()
oe.a, oe.e, oe.i = (6378.137 + 690.0) * 1e3, 0.0, 98.0 * macros.D2R
oe.Omega, oe.omega, oe.f = 0.0, 0.0, 0.0
r, v = orbitalMotion.elem2rv(earth.mu, oe)
sc.hub.r_CN_NInit, sc.hub.v_CN_NInit = r, v
sc.hub.sigma_BNInit = [[0.1], [0.2], [-0.3]]
sc.hub.omega_BN_BInit = [[-3.0 * macros.D2R], [3.0 * macros.D2R], [3.0 * macros.D2R]]
sim.InitializeSimulation()
sim.ConfigureStopTime(macros.sec2nano(10 * step_s))
sim.ExecuteSimulation()
c0, t0 = time.process_time(), time.perf_counter()
sim.ConfigureStopTime(macros.sec2nano((10 + steps) * step_s))
sim.ExecuteSimulation()
dt, dc = time.perf_counter() - t0, time.process_time() - c0
w = sc.scStateOutMsg.read().omega_BN_B
import Basilisk
print(json.dumps({'steps': steps, 'seconds': dt, 'cpu_s': dc, 'omega': list(w),
                  'version': getattr(Basilisk, '__version__', '?')}))
'''


def basilisk_python(mode: str, log: Callable[[str], None]) -> tuple[Optional[str], str]:
    """Interpreter with Basilisk importable, installing ``bsk`` on demand; or (None, why)."""
    if mode == 'skip':
        return None, 'skipped (--basilisk skip)'
    py = os.path.join(BSK_VENV, 'bin', 'python')
    probe = [py, '-c', 'import Basilisk.simulation.spacecraft']
    try:
        if os.path.exists(py) and subprocess.run(probe, capture_output=True,
                                                 timeout=120).returncode == 0:
            return py, ''
        log(f'[bench] installing Basilisk (pip install bsk) into {BSK_VENV} (once, ~20 s) ...')
        if not os.path.exists(py):
            subprocess.run([sys.executable, '-m', 'venv', BSK_VENV], check=True,
                           capture_output=True, timeout=120)
        pip = subprocess.run([py, '-m', 'pip', 'install', '-q', 'bsk'], capture_output=True,
                             text=True, timeout=600)
        if pip.returncode != 0:
            return None, ('not measured: pip install bsk failed: '
                          + (pip.stderr.strip().splitlines() or ['?'])[-1][:200])
        if subprocess.run(probe, capture_output=True, timeout=120).returncode != 0:
            return None, 'not measured: Basilisk installed but does not import'
        return py, ''
    except (OSError, subprocess.SubprocessError) as exc:
        return None, f'not measured: Basilisk could not be installed ({exc})'


class BasiliskMeasure:
    """Basilisk steps/s of :data:`BSK_SCRIPT` in its own interpreter."""

    def __init__(self, python: str, steps: int) -> None:
        self.python, self.steps = python, steps
        self.version = '?'

    def __call__(self) -> Sample:
        cpu0, w0 = _cpu_now(), time.monotonic()
        proc = subprocess.run([self.python, '-c', BSK_SCRIPT, str(self.steps), '0.1',
                               *map(str, INERTIA_DIAG)], capture_output=True, text=True,
                              timeout=600)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith('{')]
        if proc.returncode != 0 or not lines:
            raise BenchError(f'Basilisk run failed: {proc.stderr.strip()[-1500:]}')
        d = json.loads(lines[-1])
        if not all(math.isfinite(x) for x in d['omega']):
            raise BenchError(f'Basilisk run diverged: omega {d["omega"]}')
        self.version = str(d.get('version', '?'))
        return Sample(d['steps'], d['steps'] / d['seconds'], time.monotonic() - w0,
                      _cpu_now() - cpu0, d['cpu_s'] / d['steps'])


# ---------------------------------------------------------------------- table
def _num(x: Optional[float]) -> str:
    if x is None or not math.isfinite(x):
        return '-'
    return f'{x:,.0f}' if abs(x) >= 100 else f'{x:,.1f}' if abs(x) >= 1 else f'{x:.3f}'


HEADER = ['', 'measurement', 'rate /wall s (min-max)', 'unit', 'sim s/wall s', 'sim s/CPU s',
          'wall s', 'CPU s', 'CPU ms/unit', 'load', 'note']


def _cells(r: Row) -> List[str]:
    if not r.samples:
        return [r.key, r.label, '-', r.unit, '-', '-', '-', '-', '-', '-', r.skipped or r.note]
    rates = [s.rate for s in r.samples if math.isfinite(s.rate)]
    rate = _num(r.rate) + (f' ({_num(min(rates))}-{_num(max(rates))})' if len(rates) > 1
                           else '')
    cpu_unit = r.median('cpu_per_unit_s')
    return [r.key, r.label, rate, r.unit, _num(r.rate * r.step_s), _num(r.cpu_real_time),
            _num(r.median('wall_s')), _num(r.median('cpu_s')),
            '-' if cpu_unit is None else f'{cpu_unit * 1e3:.3f}',
            f'{statistics.median(r.loads):.2f}', r.note]


def format_table(rows: Sequence[Row]) -> str:
    """Aligned plain-text table of ``rows`` (numbers right-aligned)."""
    cells = [HEADER] + [_cells(r) for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(HEADER))]
    right = {2, 4, 5, 6, 7, 8, 9}
    lines = []
    for n, c in enumerate(cells):
        parts = [c[i].rjust(widths[i]) if i in right else c[i].ljust(widths[i])
                 for i in range(len(c))]
        lines.append('  '.join(parts).rstrip())
        if n == 0:
            lines.append('-' * len(lines[0]))
    return '\n'.join(lines)


def verdict(name: str, ratio: Optional[float], target: float, detail: str,
            at_most: bool = False) -> str:
    """One MET / NOT MET line (``ratio`` None: not measured; ``at_most``: target <=)."""
    rel = '<=' if at_most else '>='
    if ratio is None:
        return f'  {name:<50} {"-":>7}    (target {rel} {target:g} x)  NOT MEASURED  {detail}'
    ok = 'MET' if (ratio <= target if at_most else ratio >= target) else 'NOT MET'
    return f'  {name:<50} {ratio:7.2f} x  (target {rel} {target:g} x)  {ok:<7}  {detail}'


# ---------------------------------------------------------------------- (8) campaign
class CampaignMeasure:
    """Row (8): ``adcs montecarlo`` of ``runs`` dispersed runs of ``orbits`` orbits each on the
    plain engine, ``--jobs 2``, as a user starts it (``python -m adcs_nodes.tools.campaigns``).

    ``cpu_s``: the command and every process it started (``resource.getrusage`` of the
    children: process starts, scenario and result files, series, table, summary and plot
    included); against the sum of the runs' own FrameLoop CPU (building it and stepping it,
    ``frameloop_cpu_s`` of each ``result.json``): :attr:`ratio`; :attr:`split`: that sum and
    the rest of the runs' CPU (series, files, metrics).
    """

    def __init__(self, scenario: str, runs: int, orbits: float, jobs: int = 2) -> None:
        from adcs_nodes.scenario import load_scenario
        from adcs_nodes.tools.campaigns import orbit_period_s
        sc = load_scenario(scenario)
        frame_s = float(sc['timing']['frame_s'])       # a whole number of frames
        self.scenario, self.runs, self.orbits, self.jobs = scenario, runs, orbits, jobs
        self.duration_s = frame_s * round(orbits * orbit_period_s(sc) / frame_s)
        self.ratio: Optional[float] = None
        self.split = (math.nan, math.nan)

    def __call__(self) -> Sample:
        from adcs_nodes.tools.campaigns import load_result, run_dir_of
        with tempfile.TemporaryDirectory(prefix='adcs-bench-mc-') as out:
            cpu0, w0 = _cpu_now(), time.monotonic()
            proc = subprocess.run([sys.executable, '-m', 'adcs_nodes.tools.campaigns',
                                   self.scenario, '--engine', 'plain', '--runs', str(self.runs),
                                   '--jobs', str(self.jobs), '--duration', f'{self.duration_s:g}',
                                   '--out', out], capture_output=True, text=True)
            wall, cpu = time.monotonic() - w0, _cpu_now() - cpu0
            if proc.returncode != 0:
                raise BenchError(f'campaign failed ({proc.returncode}): '
                                 f'{(proc.stdout + proc.stderr).strip()[-1500:]}')
            results = [load_result(run_dir_of(out, i)) for i in range(self.runs)]
        loop_cpu = sum(r['frameloop_cpu_s'] for r in results)
        self.ratio = cpu / loop_cpu
        self.split = (loop_cpu, sum(r['cpu_s'] for r in results) - loop_cpu)
        return Sample(self.runs, self.runs / wall, wall, cpu, cpu / self.runs)

    def verdict(self, row: 'Row') -> str:
        """Target (g)'s line."""
        cpu = row.median('cpu_s')
        return verdict('(g) campaign CPU / its runs\' FrameLoop CPU', self.ratio,
                       TARGET_CAMPAIGN_CPU, f'{_num(row.median("wall_s"))} s wall, {_num(cpu)} s '
                       f'CPU for {self.runs} runs: FrameLoop {_num(self.split[0])} s, the runs\' '
                       f'series, files and metrics {_num(self.split[1])} s, the rest (process '
                       f'starts, the campaign) {_num(cpu - sum(self.split))} s'
                       if row.samples else row.skipped, at_most=True)


# ---------------------------------------------------------------------- main
def plan(sc: dict, frames: int, basilisk: Optional[str], bsk_why: str,
         own: Optional[dict] = None, campaign: Optional[CampaignMeasure] = None) -> List[Row]:
    """The table's rows, each with the measurement that fills it (not run yet); ``own``: the
    scenario at its own frames (row 4p; default ``sc``); ``campaign``: row 8's."""
    own = sc if own is None else own
    own_frame = float(own['timing']['frame_s'])
    hops = hop_pattern(sc, FRAME_S)
    mean_hops = sum(hops) / len(hops)
    deliveries = delivery_pattern(sc, FRAME_S)
    mean_del = sum(deliveries) / len(deliveries)
    rows = [Row('(1)', 'ring, graph\'s deliveries', note=f'{mean_del:.1f} hops/frame '
                f'({"/".join(map(str, deliveries))})',
                measure=lambda: ring_sample(deliveries, frames)),
            Row('(1h)', 'ring, critical path only', note=f'{mean_hops:.2f} hops/frame '
                f'({"/".join(map(str, hops))})', measure=lambda: ring_sample(hops, 3 * frames)),
            Row('(2)', 'graph, 1 process/node', note=f'{sc["name"]}, {FRAME_S:g} s frames',
                measure=GraphMeasure(sc, frames, compose=False)),
            Row('(3)', 'graph, composed, DDS', note='same graph, one process, all over DDS '
                '(--dds)',
                measure=GraphMeasure(sc, frames, compose=True)),
            Row('(3i)', 'composed, in-process path', note='the default: DDS only for '
                'outside subscribers',
                measure=GraphMeasure(sc, frames, compose=True, inproc=True)),
            Row('(4)', 'FrameLoop (plain engine)', note=f'no ROS, {FRAME_S:g} s frames',
                measure=lambda: plain_sample(sc, frames)),
            Row('(4p)', f'FrameLoop (plain engine), {own["name"]} at its frames',
                step_s=own_frame, note=f'{own_frame:g} s frames x '
                f'{own["timing"]["substeps"]} substeps',
                measure=lambda: plain_sample(own, frames)),
            Row('(5)', 'free body + GG, this RK4', unit='RK4 steps', step_s=0.1,
                note='Spacecraft.step, 0.1 s step',
                measure=lambda: free_body_sample(20 * frames))]
    rows += [Row('(7g)', 'start-up to frame 0, 1 process/node', unit='processes',
                 note=f'{START_FRAMES}-frame runs; CPU s: node processes to their first frame',
                 measure=StartupMeasure(own, compose=False)),
             Row('(7c)', 'start-up to frame 0, composed', unit='processes',
                 note='the same, one process', measure=StartupMeasure(own, compose=True))]
    bsk = Row('(6)', 'free body + GG, Basilisk', unit='RK4 steps', step_s=0.1,
              note='bsk, 0.1 s step, + orbit')
    if basilisk:
        bsk.measure = BasiliskMeasure(basilisk, 20 * frames)
    else:
        bsk.skipped = bsk_why
    rows.append(bsk)
    if campaign is not None:
        rows.append(Row('(8)', 'campaign, plain, --jobs 2', unit='runs',
                        step_s=campaign.duration_s, measure=campaign,
                        note=f'{campaign.runs} runs x {campaign.orbits:g} orbits, all '
                        'processes; CPU ms/unit: per run'))
    return rows


def _row(rows: Sequence[Row], key: str) -> Row:
    return next(r for r in rows if r.key == key)


def _ratio(a: Optional[float], b: Optional[float]) -> Optional[float]:
    return a / b if a is not None and b else None


def run_bench(scenario: str, frames: int, repeats: int, basilisk_mode: str,
              log: Callable[[str], None], only: Sequence[str] = (),
              campaign: Tuple[int, float] = (100, 6.0)) -> str:
    """Run every measurement (or the rows whose keys are in ``only``, e.g. ``2, 3, 3i``) and
    return the report text (table, targets); ``campaign``: row 8's runs and orbits (measured
    once, not repeated)."""
    from adcs_nodes.nodes.runtime import limit_blas_threads
    from adcs_nodes.scenario import load_scenario

    limit_blas_threads()   # this process runs the plain loops: one BLAS thread as the nodes
    own = load_scenario(scenario)
    sc = bench_scenario(own)
    info = machine_info()
    t_start = time.monotonic()
    bsk_py, bsk_why = basilisk_python(basilisk_mode, log)
    mc_row = CampaignMeasure(scenario, *campaign)
    rows = plan(sc, frames, bsk_py, bsk_why, own, mc_row)
    for r in rows:
        if only and r.key.strip('()') not in only:
            r.measure, r.skipped = None, 'not selected (--rows)'
    for rep in range(repeats):
        for r in rows:
            if r.measure is None or (rep and r.key == '(8)'):
                continue
            log(f'[bench] repeat {rep + 1}/{repeats}: {r.key} {r.label} ...')
            r.loads.append(load1())
            try:
                r.samples.append(r.measure())
            except BenchError as exc:
                if r.key != '(6)':
                    raise
                r.skipped, r.measure = f'not measured: {exc}'[:200], None
    elapsed = time.monotonic() - t_start
    end_load = machine_info()['load']
    ring, graph, comp = _row(rows, '(1)'), _row(rows, '(2)'), _row(rows, '(3)')
    ring_hops = _row(rows, '(1h)')
    inproc = _row(rows, '(3i)')
    free, bsk = _row(rows, '(5)'), _row(rows, '(6)')
    plain, plain_own = _row(rows, '(4)'), _row(rows, '(4p)')
    cmd = 'make bench  (= ros2_ws/run.sh PYTHONPATH=tests python -m perf.bench ' + \
        ' '.join(sys.argv[1:]) + ')'
    out = [
        f'ADCS bench, {datetime.now().strftime("%Y-%m-%d %H:%M")}, scenario '
        f'{os.path.basename(scenario)} at {FRAME_S:g} s frames x {SUBSTEPS} RK4 substeps',
        f'command: {cmd.replace(" )", ")")}',
        f'machine: nproc {info["nproc"]}, {info["cpu"]}, Python {info["python"]}',
        f'load average (1/5/15 min): {info["load"]} at start, {end_load} at end',
        f'sizes: {frames} frames per graph/loop run ({SHORT_FRAMES}-frame run subtracted for '
        f'CPU/frame), {frames} ring (1) and {3 * frames} ring (1h) frames, {20 * frames} '
        f'free-body steps; {repeats} '
        f'interleaved repeats: medians; took {elapsed:.0f} s',
        '',
        format_table(rows),
        '',
        'CPU s: all processes of the row, start-up included. CPU ms/unit: timed frames only.',
    ]
    if bsk.samples:
        out.append(f'Basilisk {getattr(bsk.measure, "version", "?")} from {BSK_VENV}.')
    out += ['', 'Targets (ratios of this run):',
            verdict('(a) graph >= 0.8 x ring (same deliveries/frame)',
                    _ratio(graph.rate, ring.rate), TARGET_GRAPH_VS_RING,
                    f'{_num(graph.rate)} vs {_num(ring.rate)} frames/s (critical-path ring '
                    f'(1h): {_num(ring_hops.rate)}, ratio '
                    f'{_num(_ratio(graph.rate, ring_hops.rate))})')]
    for key, row in (('(3)', comp), ('(3i)', inproc)):
        rtf = row.rate * FRAME_S if row.rate else None
        out += [verdict(f'(b) composed {key} >= 3 x graph', _ratio(row.rate, graph.rate),
                        TARGET_COMPOSED_VS_GRAPH, f'{_num(row.rate)} vs {_num(graph.rate)} '
                        'frames/s'),
                verdict(f'(c) composed {key} >= 2000 x real time', _ratio(rtf, 1.0),
                        TARGET_REAL_TIME, f'{_num(rtf)} x real time, {FRAME_S:g} s frames')]
    out.append(verdict('(d) plain loop (5) >= 0.5 x Basilisk (6)', _ratio(free.rate, bsk.rate),
                       TARGET_LOOP_VS_BASILISK,
                       f'{_num(free.rate)} vs {_num(bsk.rate)} RK4 steps/s'
                       if bsk.samples else bsk.skipped))
    for key, row in (('(4)', plain), ('(4p)', plain_own)):
        for clock, rtf in (('wall', row.rate * row.step_s if row.rate else None),
                           ('CPU', row.cpu_real_time)):
            miss = (f'; misses 10,000 x by a factor {TARGET_PLAIN_REAL_TIME / rtf:.1f}'
                    if rtf and rtf < TARGET_PLAIN_REAL_TIME else '')
            out.append(verdict(f'(e) plain engine {key} >= 10,000 x real time ({clock})',
                               _ratio(rtf, 1.0), TARGET_PLAIN_REAL_TIME,
                               f'{_num(rtf)} sim s per {clock} s at {row.step_s:g} s frames'
                               f'{miss}'))
    if _row(rows, '(7g)').samples:
        out += startup_lines(_row(rows, '(7g)'), _row(rows, '(7c)'))
    out.append(mc_row.verdict(_row(rows, '(8)')))
    if bsk.samples and plain.samples:
        out.append(f'  plain engine (4) vs Basilisk (6): '
                   f'{_num(_ratio(plain.rate * plain.step_s, bsk.rate * bsk.step_s))} x its sim '
                   f's per wall s, {_num(_ratio(plain.cpu_real_time, bsk.cpu_real_time))} x per '
                   'CPU s (the whole closed loop against a free body with gravity gradient)')
    out += ['', f'Noise: {info["nproc"]} cores, other work may be running (load average above).']
    return '\n'.join(out) + '\n'


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of ``make bench``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--frames', type=int, default=2000,
                    help='frames per graph and loop run (ring 3x, free body 20x as many)')
    ap.add_argument('--repeats', type=int, default=2, help='runs per row (median, min-max)')
    ap.add_argument('--quick', action='store_true', help='300 frames, 1 repeat')
    ap.add_argument('--basilisk', choices=['auto', 'skip'], default='auto',
                    help='auto: measure Basilisk, installing bsk on demand in its own venv')
    ap.add_argument('--scenario', default=DEFAULT_SCENARIO)
    ap.add_argument('--out', default='out/bench.txt', help='also write the report here')
    ap.add_argument('--campaign-runs', type=int, default=100, help='row 8: runs')
    ap.add_argument('--campaign-orbits', type=float, default=6.0, help='row 8: orbits a run')
    ap.add_argument('--rows', default='',
                    help='comma-separated row keys to measure (e.g. 2,3,3i); default: all')
    args = ap.parse_args(argv)
    only = [k.strip() for k in args.rows.split(',') if k.strip()]
    known = ('1', '1h', '2', '3', '3i', '4', '4p', '5', '6', '7g', '7c', '8')
    if any(k not in known for k in only):
        ap.error(f'--rows: known keys are {", ".join(known)}')
    if args.quick:
        args.frames, args.repeats = 300, 1
        args.campaign_runs, args.campaign_orbits = 10, 1.0
    if args.frames <= SHORT_FRAMES or args.repeats < 1:
        ap.error(f'--frames must be > {SHORT_FRAMES} and --repeats >= 1')

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    try:
        text = run_bench(args.scenario, args.frames, args.repeats, args.basilisk, log, only,
                         (args.campaign_runs, args.campaign_orbits))
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
