"""A node interrupted (SIGINT) while it is being built exits cleanly: exit 0 and one line, no
``KeyboardInterrupt`` traceback (seen in a clean-clone run: the graph listed the node's name
before its constructor had created its subscriptions, and the test's Ctrl-C landed there)."""
import subprocess
import sys

CHILD = r'''
from adcs_nodes.nodes import runtime
def magnetometer():
    raise KeyboardInterrupt        # what SIGINT raises inside the constructor
raise SystemExit(runtime.run(magnetometer))
'''


def test_sigint_during_construction_exits_0_without_a_traceback():
    proc = subprocess.run([sys.executable, '-c', CHILD], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert 'interrupted during start-up' in proc.stderr
    assert 'Traceback' not in proc.stderr
