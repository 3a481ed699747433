"""``adcs montecarlo`` execution: one BLAS thread per worker process, ``--dask-local``.

Short: the worker processes here are stand-ins or 20 s plain-engine runs. The full campaigns
(``--scheduler``, resume, Ctrl-C; the graph engine in ``make test-long``) are in
tests/graph/test_montecarlo.py. Processes, no ROS graph: graph tier, marked ``parallel``
(was ``tests/unit``).
"""
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from adcs_nodes.tools import campaigns as mc
from adcs_nodes.tools.campaigns import runner

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENARIO = os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')
pytestmark = pytest.mark.parallel

#: Stand-in worker process: each run reports the thread counts its BLAS libraries really use.
PROBE = r'''
import json, os, sys
from adcs_nodes.tools.campaigns.runner import serve


def run(run_dir):
    import numpy, scipy.linalg
    from threadpoolctl import threadpool_info
    info = [{'api': i['internal_api'], 'threads': i['num_threads']} for i in threadpool_info()]
    open(os.path.join(run_dir, 'series.npz'), 'wb').close()
    with open(os.path.join(run_dir, 'result.json'), 'w') as fh:
        env = {k: os.environ.get(k) for k in ('OPENBLAS_NUM_THREADS', 'NUMBA_NUM_THREADS')}
        json.dump({'index': 0, 'status': 'captured', 'pools': info, 'env': env}, fh)
    return 0


raise SystemExit(serve(sys.argv[1], run))
'''


def test_run_process_gets_one_blas_thread(tmp_path, monkeypatch):
    pytest.importorskip('threadpoolctl')
    monkeypatch.setenv('OPENBLAS_NUM_THREADS', '4')    # the campaign's own setting loses
    monkeypatch.setenv('OMP_NUM_THREADS', '4')
    monkeypatch.setattr(runner, 'SERVER_COMMAND', ['-c', PROBE])
    job = {'index': 0, 'run_dir': str(tmp_path / 'run'), 'stop_file': str(tmp_path / 'stop'),
           'engine': 'plain'}
    os.makedirs(job['run_dir'])
    result = mc.execute_run(job)
    assert mc.close_servers(job['stop_file']) == 1
    assert result['status'] == 'captured', result
    assert result['env'] == {'OPENBLAS_NUM_THREADS': '1', 'NUMBA_NUM_THREADS': '1'}
    assert result['pools'], 'numpy loaded no BLAS library?'
    assert all(p['threads'] == 1 for p in result['pools']), result['pools']


def test_local_cluster_has_one_single_thread_process_per_job():
    distributed = pytest.importorskip('distributed')
    backend = mc.DaskBackend(None, 'test', local_workers=2)
    try:
        workers = backend.client.scheduler_info()['workers'].values()
        assert sorted(w['nthreads'] for w in workers) == [1, 1]
        pids = set(backend.client.run(os.getpid).values())
        assert len(pids) == 2 and os.getpid() not in pids     # processes, not threads
    finally:
        backend.close()
    assert backend.cluster is None
    assert backend.client.status == 'closed'
    assert isinstance(backend.client, distributed.Client)


def test_bad_local_cluster_size_is_refused():
    pytest.importorskip('distributed')
    with pytest.raises(ValueError, match='>= 1 worker'):
        mc.DaskBackend(None, 'test', local_workers=0)


def campaign(out, *args, timeout=180):
    """Run the command to its end; returns ``(exit code, stdout, stderr, pid)``."""
    with subprocess.Popen([sys.executable, '-m', 'adcs_nodes.tools.campaigns', SCENARIO,
                           '--duration', '20', '--engine', 'plain', '--out', str(out), *args],
                          cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True) as proc:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    return proc.returncode, out, err, proc.pid


@pytest.mark.long   # the Dask backend: test_local_cluster_has_one_single_thread_process_per_job
#                    in make test
def test_dask_local_campaign_gives_the_local_campaigns_results(tmp_path):
    pytest.importorskip('distributed')
    psutil = pytest.importorskip('psutil')
    code, out, err, _ = campaign(tmp_path / 'local', '--runs', '3', '--jobs', '2')
    assert code == 0, out + err
    code, out, err, pid = campaign(tmp_path / 'dask', '--runs', '3', '--jobs', '2',
                                   '--dask-local')
    assert code == 0, out + err
    assert 'on a Dask LocalCluster of 2 worker process(es), 1 thread each' in out
    assert 'executed 3 run(s)' in out, out
    rows = mc.read_table(os.path.join(str(tmp_path / 'dask'), 'campaign.csv'))
    ref = mc.read_table(os.path.join(str(tmp_path / 'local'), 'campaign.csv'))
    assert [int(r['index']) for r in rows] == [0, 1, 2]
    supervisors = set()
    for row, want in zip(rows, ref):
        assert row['status'] in ('captured', 'not_captured'), row
        assert row['final_angle_deg'] == want['final_angle_deg']    # same draws, same run
        with open(os.path.join(mc.run_dir_of(str(tmp_path / 'dask'), int(row['index'])),
                               'result.json')) as fh:
            supervisors.add(json.load(fh)['supervisor_pid'])
    # supervised in the cluster's worker processes, which the command stopped at its end
    assert pid not in supervisors
    assert not any(psutil.pid_exists(pid) and psutil.Process(pid).status() != 'zombie'
                   for pid in supervisors), supervisors


def test_dask_local_and_scheduler_exclude_each_other(tmp_path):
    code, _, err, _ = campaign(tmp_path / 'x', '--runs', '1', '--dask-local', '--scheduler',
                               'tcp://127.0.0.1:1', timeout=60)
    assert code == 2 and 'not allowed with argument' in err, err


@pytest.mark.long   # the compile cache in a second process: test_fresh_interpreters in make test
def test_plain_run_process_loads_the_compiled_kernels_from_the_cache(tmp_path):
    """A second run process compiles nothing: numba reports every kernel loaded from its
    on-disk cache (``NUMBA_DEBUG_CACHE``), none saved (a save follows a compilation)."""
    env = {**os.environ, 'NUMBA_DEBUG_CACHE': '1'}
    for name in ('first', 'second'):      # the first one may fill a stale cache
        proc = subprocess.run([sys.executable, '-m', 'adcs_nodes.tools.campaigns', SCENARIO,
                               '--duration', '2', '--engine', 'plain', '--runs', '1',
                               '--out', str(tmp_path / name)], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stdout + proc.stderr
    with open(os.path.join(mc.run_dir_of(str(tmp_path / 'second'), 0), 'worker.log')) as fh:
        log = fh.read()
    assert log.count('[cache] data loaded') >= 3, log
    assert '[cache] data saved' not in log, log


def _run_processes(out):
    psutil = pytest.importorskip('psutil')
    found = []
    for p in psutil.process_iter(['cmdline']):
        cmd = p.info['cmdline'] or []
        if runner.SERVER_COMMAND[-1] in cmd and any(str(out) in c for c in cmd):
            found.append(p)
    return found


@pytest.mark.long   # Ctrl-C's race: tests/unit/test_frameloop_montecarlo.py; the cluster's
#                    stop: test-long
def test_ctrl_c_on_a_dask_local_campaign_stops_runs_and_cluster(tmp_path):
    """Ctrl-C reaches the whole foreground process group: the campaign stops its runs
    through the stop file, the cluster's workers do not die under the runs."""
    pytest.importorskip('distributed')
    out = tmp_path / 'ctrlc'
    proc = subprocess.Popen([sys.executable, '-m', 'adcs_nodes.tools.campaigns', SCENARIO,
                             '--engine', 'plain', '--runs', '4', '--jobs', '2', '--dask-local',
                             '--out', str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 90.0
        while len(_run_processes(out)) < 2 and time.monotonic() < deadline:
            time.sleep(0.2)
        assert len(_run_processes(out)) == 2, 'the two runs never started'
        os.killpg(proc.pid, signal.SIGINT)              # what a terminal's Ctrl-C does
        text, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, text
    assert text.count('interrupted (Ctrl-C)') == 2, text
    assert 'Traceback' not in text and 'KeyboardInterrupt' not in text, text
    assert _run_processes(out) == []
    assert not (out / 'runs' / 'run_0000' / 'result.json').exists()
