"""A command on a running graph (``adcs status``, ``adcs switch``) never hangs: its ROS
session gives up after ``live.SESSION_DEADLINE_S`` with exit 1 and a message (a status call
was once seen never to return beside a graph running flat out)."""
import subprocess
import sys
import time

CHILD = r'''
import threading, time
from adcs_nodes.tools.run import live
live.SESSION_DEADLINE_S = 1.0
print(f'SESSION {time.monotonic()!r}', flush=True)   # the deadline runs from here
session = live._Session({'domain': 229})
threading.Event().wait()   # stands for a call that never returns
'''


def test_a_stuck_session_exits_1_with_a_message():
    # measured from the session's start (CLOCK_MONOTONIC is the same in both processes), not
    # from the interpreter's: its start and imports took up to 9 s beside CPU burners
    proc = subprocess.run([sys.executable, '-c', CHILD], capture_output=True, text=True,
                          timeout=120)
    end = time.monotonic()
    assert proc.returncode == 1, proc.stderr
    start = [ln for ln in proc.stdout.splitlines() if ln.startswith('SESSION ')]
    assert start and end - float(start[0].split()[1]) < 30.0, proc.stdout
    assert 'no answer from ROS within 1 s' in proc.stderr and 'Traceback' not in proc.stderr
