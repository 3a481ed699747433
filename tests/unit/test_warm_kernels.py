"""numba cache warm-up of the bootstrap (``sim_node.tools.warm_kernels``).

Node processes that compile and save one kernel at the same time can corrupt numba's on-disk
cache (numba #4807, #10128), so ``ros2_ws/bootstrap.sh`` fills it once, serially. That only
helps if the warm-up leaves nothing for a node process to compile: after it, a process that
runs the nodes' components (the FrameLoop builds them from the nodes' parameters,
``sim_node.engine``) must write no file into the cache, and its kernels must count no cache
miss. Both processes use a fresh ``NUMBA_CACHE_DIR``, so no earlier run's cache
entries can hide a kernel the warm-up forgot.
"""
import json
import os
import subprocess
import sys

import pytest

pytest.importorskip('numba')
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENARIO = os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')

# the work of a graph's nodes on one scenario (estimator, controllers, manager, environment,
# dynamics), then the numba dispatchers' counts: (kernels, signatures, compiled, loaded)
NODE_WORK = """
import json, sys
from adcs_nodes.scenario import load_scenario
from sim_node.engine import FrameLoop
from sim_node.tools.warm_kernels import kernel_counts
sc = load_scenario(sys.argv[1])
for _ in FrameLoop.from_scenario(sc, duration_s=3 * float(sc['timing']['frame_s'])).run():
    pass
print(json.dumps(kernel_counts()))
"""


def _run(args, cache_dir, cwd, **env):
    environ = dict(os.environ)
    environ.pop('NUMBA_DISABLE_JIT', None)
    environ.update(NUMBA_CACHE_DIR=str(cache_dir), **env)
    return subprocess.run([sys.executable, *args], cwd=str(cwd), env=environ, text=True,
                          capture_output=True, timeout=300)


def _files(cache_dir):
    return {os.path.join(d, f): os.stat(os.path.join(d, f)).st_mtime_ns
            for d, _, names in os.walk(cache_dir) for f in names}


@pytest.mark.long   # compiles every kernel into an empty cache (20-25 s of CPU); the cache's use
#                    by a second process: tests/graph/test_fresh_interpreters.py in make test
def test_after_the_warm_up_the_nodes_work_compiles_nothing(tmp_path):
    cache = tmp_path / 'numba-cache'
    warm = _run(['-m', 'sim_node.tools.warm_kernels', '--frames', '1'], cache, tmp_path)
    assert warm.returncode == 0, warm.stderr
    line = warm.stdout.strip()
    assert line.startswith('warm_kernels: ') and '\n' not in line, warm.stdout
    before = _files(cache)
    assert any(f.endswith('.nbi') for f in before) and any(f.endswith('.nbc') for f in before)

    work = _run(['-c', NODE_WORK, SCENARIO], cache, tmp_path)
    assert work.returncode == 0, work.stderr
    kernels, signatures, compiled, loaded = json.loads(work.stdout.strip().splitlines()[-1])
    assert kernels > 10 and loaded > 0
    assert compiled == 0, f'{compiled} kernel signature(s) compiled after the warm-up'
    assert _files(cache) == before, 'the cache changed after the warm-up'


def test_a_missing_scenario_directory_fails_in_one_line(tmp_path):
    empty = tmp_path / 'none'
    empty.mkdir()
    out = _run(['-m', 'sim_node.tools.warm_kernels', '--scenarios', str(empty)],
               tmp_path / 'cache', tmp_path)
    assert out.returncode == 1 and out.stdout == ''
    assert out.stderr.count('\n') == 1 and out.stderr.startswith('warm_kernels: FAILED')
    assert 'Traceback' not in out.stderr and str(empty) in out.stderr


def test_nothing_to_warm_without_jit(tmp_path):
    out = _run(['-m', 'sim_node.tools.warm_kernels'], tmp_path / 'cache', tmp_path,
               NUMBA_DISABLE_JIT='1')
    assert out.returncode == 0 and 'NUMBA_DISABLE_JIT' in out.stdout
    assert not (tmp_path / 'cache').exists()


def test_a_scenario_that_does_not_load_is_skipped_not_fatal(tmp_path):
    """A scenario being edited must not block the bootstrap (``adcs validate`` reports it)."""
    scenarios = tmp_path / 'scenarios'
    scenarios.mkdir()
    with open(os.path.join(ROOT, 'scenarios', 'free_tumble.yaml')) as fh:
        (scenarios / 'free_tumble.yaml').write_text(fh.read())
    (scenarios / 'broken.yaml').write_text('timing: {frame_s: -1}\n')
    environ = {k: v for k, v in os.environ.items() if k != 'NUMBA_DISABLE_JIT'}
    out = subprocess.run([sys.executable, '-m', 'sim_node.tools.warm_kernels', '--scenarios',
                          str(scenarios), '--frames', '1'], cwd=str(tmp_path), env=environ,
                         text=True, capture_output=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert '1 scenarios' in out.stdout and 'skipped (invalid): broken.yaml' in out.stdout
