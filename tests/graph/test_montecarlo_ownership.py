"""A Monte Carlo run is owned by one worker (issue 38 item 6): the worker process of a lost
supervisor ends with it (the parent-death signal), and a run given to another worker while a
previous worker process still runs it on this host ends that process before it starts again.
Stand-in runs in the real worker loop (a sleeper that names its pid), no ROS: graph tier,
marked ``parallel``.
"""
import json
import os
import subprocess
import sys
import threading
import time

import pytest

from adcs_nodes.tools.campaigns import runner

pytestmark = pytest.mark.parallel

#: A worker whose run never ends by itself: writes the worker's pid, then sleeps.
SLEEPER = r'''
import os, sys, time
from adcs_nodes.tools.campaigns.runner import serve


def run(run_dir):
    open(os.path.join(run_dir, 'sleeper.pid'), 'w').write(str(os.getpid()))
    time.sleep(600)


raise SystemExit(serve(sys.argv[1], run))
'''
#: A worker whose run finishes: records whether the sleeper was still alive at its start.
FINISHER = r'''
import json, os, sys
from adcs_nodes.tools.campaigns.runner import serve


def run(run_dir):
    try:
        os.kill(int(os.environ['SLEEPER_PID']), 0)
        alive = True
    except ProcessLookupError:
        alive = False
    open(os.path.join(run_dir, 'series.npz'), 'wb').close()
    json.dump({'index': 0, 'status': 'captured', 'sleeper_alive': alive},
              open(os.path.join(run_dir, 'result.json'), 'w'))
    return 0


raise SystemExit(serve(sys.argv[1], run))
'''


def _job(run_dir):
    os.makedirs(run_dir, exist_ok=True)
    return {'index': 0, 'run_dir': str(run_dir), 'stop_file': str(run_dir) + '.stop',
            'engine': 'plain'}


def _wait_pid(run_dir, deadline_s=60.0):
    path = os.path.join(run_dir, 'sleeper.pid')
    deadline = time.monotonic() + deadline_s
    while not os.path.isfile(path) or not open(path).read():
        assert time.monotonic() < deadline, 'the run process did not start'
        time.sleep(0.05)
    return int(open(path).read())


def _gone(pid, deadline_s):
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def test_a_lost_workers_run_process_ends_with_it(tmp_path):
    run_dir = str(tmp_path / 'run_0000')
    job = _job(run_dir)
    code = ('import sys; from adcs_nodes.tools.campaigns import runner; '
            f'runner.SERVER_COMMAND = ["-c", {SLEEPER!r}]; '
            f'runner.execute_run({job!r})')
    worker = subprocess.Popen([sys.executable, '-c', code], env={**os.environ,
                              'PYTHONPATH': os.pathsep.join(sys.path)})
    try:
        pid = _wait_pid(run_dir)
        worker.kill()                                  # the worker is lost
        worker.wait()
        assert _gone(pid, 30.0), 'the run process outlived its worker'
    finally:
        worker.kill()


def test_a_run_given_to_another_worker_ends_the_previous_run_process(tmp_path, monkeypatch):
    run_dir = str(tmp_path / 'run_0000')
    job = _job(run_dir)
    monkeypatch.setattr(runner, 'SERVER_COMMAND', ['-c', SLEEPER])
    first = {}
    lost = threading.Thread(target=lambda: first.update(runner.execute_run(job)))
    lost.start()                                       # a worker that no longer answers
    pid = _wait_pid(run_dir)
    monkeypatch.setenv('SLEEPER_PID', str(pid))
    monkeypatch.setattr(runner, 'SERVER_COMMAND', ['-c', FINISHER])
    t0 = time.monotonic()
    result = runner.execute_run(job)                   # the scheduler gave it to another
    assert result['status'] == 'captured', result
    assert result['sleeper_alive'] is False            # ended before the run started again
    assert time.monotonic() - t0 < runner.STOP_GRACE_S
    lost.join(30.0)
    assert not lost.is_alive() and first['status'] == 'error', first
    assert sorted(os.listdir(run_dir)) == ['result.json', 'series.npz', 'worker.log']
    with open(run_dir + '.owner') as fh:
        assert json.load(fh)['pid'] != pid
    assert runner.close_servers(job['stop_file']) == 1     # the finisher's worker, reused
