"""A node that does not become active in time is asked where it is stuck.

``runtime.run`` registers ``faulthandler`` for SIGUSR1 (every thread's stack to stderr, the
node's log; the process goes on), and the launcher's report of a node not active by its
deadline carries that dump instead of an empty log tail (a clean-clone run once showed an
estimator silent for 120 s with an empty log). Truth: a real process stuck in a known
function; its dump names that function and the process is still alive afterwards.

It starts processes (no graph): graph tier, marked ``parallel`` (was ``tests/unit``).
"""
import os
import subprocess
import sys
import time

import pytest

from adcs_nodes.tools.run.launcher.processes import Processes

pytestmark = pytest.mark.parallel

STUCK = '''
import sys, time
from adcs_nodes.nodes import runtime

def stuck_in_configure():
    print("factory entered", file=sys.stderr, flush=True)
    time.sleep(600)

runtime.run(stuck_in_configure)
'''


def test_a_stuck_node_tells_its_stack_and_lives_on(tmp_path):
    os.makedirs(tmp_path / 'logs')
    log_path = tmp_path / 'logs' / 'stuck.log'
    with open(log_path, 'w') as log:
        proc = subprocess.Popen([sys.executable, '-c', STUCK], stdout=log,
                                stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120.0        # interpreter + rclpy start under load
        while 'factory entered' not in log_path.read_text() and time.monotonic() < deadline:
            assert proc.poll() is None, log_path.read_text()
            time.sleep(0.05)
        assert 'factory entered' in log_path.read_text()
        procs = Processes(str(tmp_path))
        procs.procs['stuck'] = proc
        dump = procs.dump_stack('stuck', wait_s=60.0)
        assert 'asked with SIGUSR1' in dump
        assert 'stuck_in_configure' in dump, dump
        assert proc.poll() is None                   # the dump did not end the process
    finally:
        proc.kill()
        proc.wait()


def test_a_process_already_gone_gives_no_dump(tmp_path):
    proc = subprocess.Popen([sys.executable, '-c', 'pass'])
    proc.wait()
    procs = Processes(str(tmp_path))
    procs.procs['gone'] = proc
    assert procs.dump_stack('gone') == ''
