"""Tests that need a fresh Python interpreter (a process each), no ROS graph: the compiled
kernels against the same functions as plain Python (``NUMBA_DISABLE_JIT=1`` at start-up), the
compile cache serving a second process, and ``ros2_ws/run.sh`` run from another directory.

Moved from the unit tier (which starts no process): ``tests/unit/test_kernels.py`` and
``test_control_kernels.py`` keep the functions compared here (``scenario``, ``sample``) and
their in-process tests; ``tests/unit/test_scenario_input.py`` the in-process validation.
Marked ``parallel``: not serialized with the launched-graph tests (``tests/conftest.py``).
"""
import json
import os
import runpy
import subprocess
import sys

import numpy as np
import pytest

pytestmark = pytest.mark.parallel

TESTS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROOT = os.path.dirname(TESTS)
WORLD = os.path.join(TESTS, 'unit', 'test_kernels.py')
CONTROL = os.path.join(TESTS, 'unit', 'test_control_kernels.py')


def _run(code, env_extra, timeout=600):
    env = dict(os.environ, **env_extra)
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          env=env, timeout=timeout)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_compiled_and_python_world_kernels_agree():
    """``tests/unit/test_kernels.py``'s ``scenario()`` (every world kernel path) compiled here
    and as plain Python there: identical, or within 1e-12 relative."""
    from sim_node.models import kernels
    compiled = runpy.run_path(WORLD)['scenario']()
    assert type(kernels.frame_step).__name__ == 'CPUDispatcher'      # compiled here
    code = ('import json, runpy; from sim_node.models import kernels; '
            f'm = runpy.run_path({WORLD!r}); out = m["scenario"](); '
            'print(json.dumps([type(kernels.frame_step).__name__, out]))')
    kind, python = _run(code, {'NUMBA_DISABLE_JIT': '1'})
    assert kind == 'function'                                       # plain Python there
    a = np.array([float.fromhex(v) for v in compiled])
    b = np.array([float.fromhex(v) for v in python])
    assert a.shape == b.shape and a.size > 100
    identical = np.count_nonzero(a == b)
    print(f'compiled vs Python: {identical} of {a.size} values bit-identical, largest '
          f'relative difference {np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-300)):.1e}')
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-300)


def test_compile_cache_serves_a_second_process(tmp_path):
    """First process compiles into an empty cache; a second one loads it without compiling."""
    code = ('import json, time; t0 = time.perf_counter(); '
            'from sim_node.models import kernels; '
            'import numpy as np; from sim_node.models.dynamics import Spacecraft; '
            'Spacecraft(np.eye(3)); '
            'st = kernels.frame_step.stats; '
            'print(json.dumps([sum(st.cache_hits.values()), sum(st.cache_misses.values()), '
            'time.perf_counter() - t0]))')
    env = {'NUMBA_CACHE_DIR': str(tmp_path)}
    hits1, misses1, t1 = _run(code, env)
    hits2, misses2, t2 = _run(code, env)
    print(f'start-up to the first frame: compiling {t1:.2f} s, from the cache {t2:.2f} s')
    assert misses1 >= 1 and hits1 == 0
    assert hits2 >= 1 and misses2 == 0


def test_compiled_and_uncompiled_control_kernels_give_the_same_bits():
    """``tests/unit/test_control_kernels.py``'s ``sample()`` (the magnetic law, the manager's
    checks, the dipole field, the onboard reference, the shared kernels) compiled here,
    uncompiled there (``NUMBA_DISABLE_JIT=1``), and as a node process that calls no kernel
    which loads numba runs them: plain Python, numba never imported."""
    kinds, compiled = runpy.run_path(CONTROL)['sample']()
    assert set(kinds) == {'CPUDispatcher'}                      # numba-compiled here
    code = ('import json, runpy, sys; m = runpy.run_path(%r); '
            'kinds, out = m["sample"](%s); print(json.dumps([kinds, "numba" in sys.modules, '
            'out]))')
    kinds_py, loaded, python = _run(code % (CONTROL, 'True'), {'NUMBA_DISABLE_JIT': '1'},
                                    timeout=300)
    assert set(kinds_py) == {'function'}                        # plain Python there
    kinds_lazy, loaded, lazy = _run(code % (CONTROL, 'False'), {'NUMBA_DISABLE_JIT': '0'},
                                    timeout=300)
    assert set(kinds_lazy) == {'Lazy'} and not loaded           # not compiled, no numba
    assert len(compiled) == len(python) == len(lazy) > 3000
    assert compiled == python
    assert compiled == lazy


#: Every node executable's module (``setup.py`` entry points) and the composed runner.
NODE_MODULES = ('adcs_nodes.nodes.recorder', 'adcs_nodes.nodes.estimator',
                'adcs_nodes.nodes.controller', 'adcs_nodes.nodes.guidance',
                'adcs_nodes.nodes.controller_manager', 'adcs_nodes.nodes.tf',
                'adcs_nodes.nodes.slew_action', 'sim_node.nodes.dynamics',
                'sim_node.nodes.environment', 'sim_node.nodes.sensor_node')


def test_node_modules_import_no_numba_scipy_or_plotting():
    """A node process pays for numba (~0.5 s CPU) only when it calls a kernel that loads it,
    never for an import; scipy, plotting and analysis modules are not imported at all."""
    heavy = ('numba', 'scipy', 'matplotlib', 'pandas', 'adcs_nodes.tools')
    code = ('import importlib, json, sys; importlib.import_module(sys.argv[1]); '
            f'print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)))')
    for module in NODE_MODULES:
        proc = subprocess.run([sys.executable, '-c', code, module], capture_output=True,
                              text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        assert json.loads(proc.stdout.strip().splitlines()[-1]) == [], module


def test_run_sh_resolves_paths_against_the_callers_directory():
    """``ros2_ws/run.sh adcs validate free_tumble.yaml`` from inside scenarios/ finds it."""
    proc = subprocess.run([os.path.join(ROOT, 'ros2_ws', 'run.sh'), 'adcs', 'validate',
                           'free_tumble.yaml'], cwd=os.path.join(ROOT, 'scenarios'),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'free_tumble.yaml: OK' in proc.stdout
