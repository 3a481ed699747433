"""One BLAS thread in every node process and in the composed runner (issue 13).

Each node of ``paper000_control`` is started as the launcher starts it (``python -m MODULE
--ros-args -r __node:=NAME --params-file ...``, and the composed runner with every node), with
no ``*_NUM_THREADS`` in the environment; instead of spinning, the process prints
``threadpoolctl.threadpool_info()`` once its nodes are built, after importing ``scipy.linalg``
(a library loaded late must get one thread too). The control case shows the check can fail:
a bare interpreter on this machine reports more than one thread when it has more than one core.
"""
import json
import os
import subprocess
import sys

import pytest

pytest.importorskip('threadpoolctl')
pytest.importorskip('rclpy')

from domains import worker_domain  # noqa: E402
from adcs_nodes.tools.run.launcher import child_env  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
THREAD_ENV = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'BLIS_NUM_THREADS',
              'VECLIB_MAXIMUM_THREADS', 'NUMEXPR_NUM_THREADS')

#: Runs ``python -m MODULE ARGS...`` with the runtime's spin replaced by a report.
WRAPPER = r'''
import json, runpy, sys
from adcs_nodes.nodes import runtime
import adcs_nodes.tools.run.compose as compose

def report(nodes, *args, **kwargs):
    import scipy.linalg  # noqa: F401  (loaded after the node start: must get one thread too)
    from threadpoolctl import threadpool_info
    info = [(i['internal_api'], i['num_threads']) for i in threadpool_info()]
    print('BLAS ' + json.dumps({'nodes': [n.get_name() for n in nodes], 'info': info}),
          flush=True)
    for node in nodes:
        node.destroy_node()

runtime.spin_nodes = report
compose.spin_nodes = report
module = sys.argv[1]
sys.argv = [module] + sys.argv[2:]
runpy.run_module(module, run_name='__main__', alter_sys=True)
'''


def _env(domain: int) -> dict:
    return {k: v for k, v in child_env(domain).items() if k not in THREAD_ENV}


def _commands(tmp_path):
    from adcs_nodes.tools.run.launcher import Launcher
    from adcs_nodes.graph import params_file_text
    from adcs_nodes.scenario import load_scenario

    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper000_control.yaml'))
    cmds = {}
    for compose in (False, True):
        launcher = Launcher(sc, duration_s=10.0, compose=compose, progress=False,
                            run_dir=str(tmp_path), log=lambda *a, **k: None)
        params = tmp_path / f'params-{compose}.yaml'
        params.write_text(params_file_text(launcher.nodes))
        cmds.update(launcher._commands(str(params)))
    return cmds


def test_every_node_process_has_one_blas_thread(tmp_path):
    cmds = _commands(tmp_path)
    assert 'composed' in cmds and 'estimator' in cmds and 'dynamics' in cmds
    for n, (name, cmd) in enumerate(sorted(cmds.items())):
        assert cmd[1] == '-m'
        proc = subprocess.run([sys.executable, '-c', WRAPPER] + cmd[2:], cwd=ROOT,
                              env=_env(worker_domain(140, 10, n)), capture_output=True,
                              text=True, timeout=120)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith('BLAS ')]
        assert proc.returncode == 0 and lines, f'{name}: {proc.stderr[-2000:]}'
        data = json.loads(lines[-1][5:])
        assert data['nodes'], name
        assert data['info'], f'{name}: no BLAS library loaded?'
        assert all(t == 1 for _, t in data['info']), f'{name}: {data["info"]}'
        if name == 'composed':
            assert len(data['nodes']) == len(cmds) - 1


def test_control_without_runtime_reports_the_default_threads():
    if (os.cpu_count() or 1) < 2:
        pytest.skip('one core: the default is one thread anyway')
    code = ('import numpy, scipy.linalg, json\nfrom threadpoolctl import threadpool_info\n'
            'print(json.dumps([i["num_threads"] for i in threadpool_info()]))')
    out = subprocess.run([sys.executable, '-c', code], env=_env(0), capture_output=True,
                         text=True, timeout=60, check=True).stdout
    assert max(json.loads(out)) > 1
