"""A command on a running graph (``adcs status``, ``adcs switch``) never hangs: its ROS
session gives up after ``live.SESSION_DEADLINE_S`` with exit 1 and a message (a status call
was once seen never to return beside a graph running flat out)."""
import subprocess
import sys
import time

CHILD = r'''
import threading
from adcs_nodes.tools import live
live.SESSION_DEADLINE_S = 1.0
session = live._Session({'domain': 229})
threading.Event().wait()   # stands for a call that never returns
'''


def test_a_stuck_session_exits_1_with_a_message():
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, '-c', CHILD], capture_output=True, text=True,
                          timeout=60)
    assert time.monotonic() - t0 < 30.0
    assert proc.returncode == 1, proc.stderr
    assert 'no answer from ROS within 1 s' in proc.stderr and 'Traceback' not in proc.stderr
