"""Fill numba's on-disk kernel cache once, in one process (numba #4807).

Command line: ``python -m sim_node.tools.warm_kernels [--scenarios DIR] [--frames N]``.

Why: the compiled kernels of ``adcs_nodes.core`` and ``sim_node.models`` are cached in
``__pycache__/*.nbi`` / ``*.nbc`` next to their sources; two processes that compile and save
signatures of one kernel at the same time can corrupt that cache (numba #4807, #10128: a node
then loads the wrong machine code and may crash). A process writes the cache only when it
compiles, so once every signature the nodes use is there, they only read it.
``ros2_ws/bootstrap.sh`` runs this module once, under its lock, when the core sources change.

What it runs, in this order:

1. every module's ``warm_up()`` and the other kernel entry points with the argument types of
   their callers (node constructors, dynamics, environment, disturbances);
2. for every ``scenarios/*.yaml``: a few frames of the FrameLoop (:class:`sim_node.engine
   .FrameLoop`: every node's component, world and flight software, built from the nodes'
   parameters and stepped in the lockstep order); a scenario the plain engine cannot run (an
   external sensor) gets the same frames with its external sensors simulated.

It prints one line (kernels, signatures compiled / loaded from the cache, wall time, scenarios
skipped because they do not load) and exits 0, or prints one ``warm_kernels: FAILED ...`` line
to stderr and exits 1 (``bootstrap.sh`` then warns and goes on: the nodes compile what they
need themselves, as before).
"""
from __future__ import annotations

import argparse
import glob
import os
import sys
import time
from typing import List, Optional, Sequence, Tuple

import numpy as np

#: Frames per scenario: the first steps of every core class (a kernel that only a later step
#: calls, such as the filter's predict, is in its module's ``warm_up()``).
FRAMES = 3
#: Packages whose numba kernels are warmed (and counted).
PACKAGES = ('adcs_nodes.core', 'sim_node.models')


def warm_entry_points() -> None:
    """Step 1: the modules' ``warm_up()`` and the kernels called from plain Python, every
    kernel compiled (a node process compiles its small kernels once it loads numba)."""
    from adcs_nodes.core import geomag, kernels, manager
    from adcs_nodes.core.control import cross3, magnetic
    from adcs_nodes.core.estimation import magnetic_filter, onboard
    from sim_node.models import disturbances, dynamics

    kernels.compile_all()
    for module in (geomag, manager, magnetic, magnetic_filter):
        module.warm_up()
    z3, q = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
    onboard.to_orbit_axes(q, z3)                                   # OnboardReference()
    cross3(z3, z3)                                                 # control laws
    dynamics._load_kernel()                                        # Spacecraft()
    dynamics.hermite_field_derivatives(z3, z3, z3, z3, 1.0)
    env = dynamics.FrameEnvironment(r_eci=np.array([7e6, 0.0, 0.0]),
                                    v_eci=np.array([0.0, 7.5e3, 0.0]))
    dynamics.propagate_environment(env, 0.5)                       # dynamics node, late env
    disturbances.standard_normal3(1, 2)                            # RandomTorque


def warm_scenario(path: str, frames: int = FRAMES) -> bool:
    """Step 2 for one scenario: ``frames`` frames of its FrameLoop (the nodes' components).

    Returns True when the scenario ran as it is, False when its external sensors had to be
    simulated for the plain engine (their drivers are outside; the nodes' kernels are the
    same)."""
    from adcs_nodes.scenario import apply_overrides, load_scenario
    from sim_node.engine import FrameLoop

    sc = load_scenario(path)
    external = [k for k, cfg in (sc.get('sensors') or {}).items() if cfg.get('external')]
    if external:
        sc = apply_overrides(sc, {f'sensors.{k}.external': False for k in external})
    frame_s = float(sc['timing']['frame_s'])
    for _ in FrameLoop.from_scenario(sc, duration_s=frames * frame_s).run():
        pass
    return not external


def kernel_counts() -> Tuple[int, int, int, int]:
    """``(kernels, signatures, compiled, loaded from the cache)`` of the loaded packages."""
    from numba.core.registry import CPUDispatcher

    seen = {}
    for name, module in list(sys.modules.items()):
        if module is not None and name.startswith(PACKAGES):
            for obj in vars(module).values():
                if isinstance(obj, CPUDispatcher):
                    seen[id(obj)] = obj
    sigs = sum(len(d.signatures) for d in seen.values())
    misses = sum(sum(d.stats.cache_misses.values()) for d in seen.values())
    hits = sum(sum(d.stats.cache_hits.values()) for d in seen.values())
    return len(seen), sigs, misses, hits


def scenario_dir() -> str:
    """The installed scenarios (``share/adcs_nodes/scenarios``), else the repository's."""
    from adcs_nodes.tools.run.launch_graph import installed_scenario_dir

    return installed_scenario_dir() or os.path.abspath(
        os.path.join(os.path.dirname(__file__), '..', '..', '..', 'scenarios'))


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command line; returns the exit status."""
    ap = argparse.ArgumentParser(prog='python -m sim_node.tools.warm_kernels',
                                 description=__doc__.splitlines()[0])
    ap.add_argument('--scenarios', default=None,
                    help='scenario directory (default: the installed scenarios)')
    ap.add_argument('--frames', type=int, default=FRAMES, help='frames per scenario')
    args = ap.parse_args(argv)
    if os.environ.get('NUMBA_DISABLE_JIT', '0') not in ('', '0'):
        print('warm_kernels: NUMBA_DISABLE_JIT is set, nothing to warm')
        return 0
    from adcs_nodes.scenario import ScenarioError

    directory = args.scenarios or scenario_dir()
    start = time.monotonic()
    where = directory
    try:
        paths: List[str] = sorted(glob.glob(os.path.join(directory, '*.yaml')))
        if not paths:
            raise ValueError('no *.yaml scenario there')
        where = 'the entry points'
        warm_entry_points()
        plain, skipped = 0, []
        for path in paths:
            where = os.path.basename(path)
            try:
                plain += warm_scenario(path, max(1, args.frames))
            except ScenarioError:   # a scenario being edited: `adcs validate` says what is wrong
                skipped.append(where)
        n, sigs, compiled, loaded = kernel_counts()
    except Exception as exc:   # one clear line for bootstrap.sh, no traceback
        msg = ' '.join(str(exc).split()) or type(exc).__name__
        print(f'warm_kernels: FAILED at {where}: {type(exc).__name__}: {msg}',
              file=sys.stderr)
        return 1
    print(f'warm_kernels: {n} kernels, {sigs} signatures ({compiled} compiled, {loaded} from '
          f'the cache), {len(paths) - len(skipped)} scenarios on the FrameLoop ({plain} as they '
          'are), '
          f'{time.monotonic() - start:.1f} s'
          + (f'; skipped (invalid): {", ".join(skipped)}' if skipped else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
