"""``adcs status --watch`` (and the other commands on a running graph) end on SIGINT also when
they were started with SIGINT ignored, as bash starts the commands of a script's background
job and pytest-xdist its workers: Python keeps an inherited "ignore", and the watch went on
after ``kill -INT`` until it was killed (30 s in each of the switch and slew tests).

The run the watch joins is a manifest of this test's own, in a runs directory of its own
(its launcher pid is this process), on a domain of the test's own where nothing publishes:
the watch shows "no data yet" views.
"""
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time

from domains import worker_domain

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _ignore_sigint():
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # what bash does for `cmd &` in a script


def _lines(stream, out):
    for line in stream:
        out.put(line)
    out.put(None)


def test_a_watch_started_with_sigint_ignored_ends_on_sigint(tmp_path):
    runs = tmp_path / 'runs'                        # the watch's ADCS_RUNS_DIR
    runs.mkdir()
    manifest = str(runs / f'active-{os.getpid()}.json')
    with open(manifest, 'w') as fh:
        json.dump({'pid': os.getpid(), 'domain': worker_domain(100, 50, 3),
                   'scenario': str(tmp_path / 'none.yaml'), 'epoch': '2026-01-01T00:00:00Z',
                   'pids': {}}, fh)
    proc = subprocess.Popen([sys.executable, '-m', 'adcs_nodes.tools.cli', 'status', '--watch',
                             '--run', str(os.getpid())], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, preexec_fn=_ignore_sigint,
                            env={**os.environ, 'ADCS_RUNS_DIR': str(runs)})
    out = queue.Queue()
    threading.Thread(target=_lines, args=(proc.stdout, out), daemon=True).start()
    seen = []
    try:
        deadline = time.monotonic() + 120.0       # interpreter, rclpy: seconds under load
        while not any('status --watch' in line for line in seen):
            line = out.get(timeout=max(0.01, deadline - time.monotonic()))
            assert line is not None, ''.join(seen)      # the watch ended before its view
            seen.append(line)
        proc.send_signal(signal.SIGINT)
        start = time.monotonic()
        rc = proc.wait(timeout=30)
        took = time.monotonic() - start
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.unlink(manifest)
    while (line := out.get(timeout=10)) is not None:
        seen.append(line)
    assert rc == 0, ''.join(seen)
    assert took < 15.0, took          # was: on until killed (the tests' 30 s grace)
    assert 'Traceback' not in ''.join(seen), ''.join(seen)
