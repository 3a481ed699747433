"""A Monte Carlo run is owned by one worker (issue 38 item 6): the run process of a lost
worker ends with it (the parent-death signal), and a run given to another worker while a
previous run process of it still lives on this host ends that process before it starts
again. Stand-in run processes (a sleeper that names its pid), no ROS: graph tier, marked
``parallel``.
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

#: A run process that never ends by itself: writes its pid, then sleeps.
SLEEPER = r'''
import os, sys, time
open(os.path.join(sys.argv[1], 'sleeper.pid'), 'w').write(str(os.getpid()))
time.sleep(600)
'''
#: A run process that finishes: records whether the sleeper was still alive at its start.
FINISHER = r'''
import json, os, sys
run_dir = sys.argv[1]
pid = int(os.environ['SLEEPER_PID'])
try:
    os.kill(pid, 0)
    alive = True
except ProcessLookupError:
    alive = False
open(os.path.join(run_dir, 'series.npz'), 'wb').close()
json.dump({'index': 0, 'status': 'captured', 'sleeper_alive': alive},
          open(os.path.join(run_dir, 'result.json'), 'w'))
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
            f'runner.WORKER_COMMANDS["plain"] = ["-c", {SLEEPER!r}]; '
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
    monkeypatch.setitem(runner.WORKER_COMMANDS, 'plain', ['-c', SLEEPER])
    first = {}
    lost = threading.Thread(target=lambda: first.update(runner.execute_run(job)))
    lost.start()                                       # a worker that no longer answers
    pid = _wait_pid(run_dir)
    monkeypatch.setenv('SLEEPER_PID', str(pid))
    monkeypatch.setitem(runner.WORKER_COMMANDS, 'plain', ['-c', FINISHER])
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
