"""``adcs status --watch`` in a pseudo-terminal, as a person runs it beside a composed run of
the demo mission (cut to 2400 s, with a horizon-sensor noise burst from 50 s to the end): it
redraws the screen about once a second with the active controller, the mode, the attitude
error, the rates, the wheel momentum, the faults and the missed frames, and ends by itself
when the run ends. Everything waits on what it reads, with a deadline (no fixed sleeps).
"""
import os
import pty
import re
import select
import subprocess
import sys
import time

import yaml

from adcs_launch import ROOT, SCENARIOS, start_adcs, wait_manifest

CLEAR = '\x1b[H\x1b[2J'


def _scenario(tmp_path):
    with open(os.path.join(SCENARIOS, 'demo_mission.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['duration_s'] = 2400.0
    sc['faults'] = [{'at_s': 50.0, 'kind': 'noise_burst', 'target': 'horizon_sensor',
                     'params': {'std': [0.001, 0.001, 0.0]}}]
    path = tmp_path / 'watch.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


def _read_until(fd, proc, done, deadline_s):
    """Everything the terminal shows until ``done(text)`` or the process ends (then what is
    left), with a deadline."""
    text = ''
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.2)
        if ready:
            try:
                chunk = os.read(fd, 65536)
            except OSError:          # the slave side closed: the process ended
                chunk = b''
            if not chunk and proc.poll() is not None:
                return text
            text += chunk.decode('utf-8', 'replace')
            if done(text):
                return text
        elif proc.poll() is not None:
            return text
    raise AssertionError(f'no such screen within {deadline_s} s; last: {text[-2000:]}')


def test_watch_redraws_the_live_view_in_a_terminal_and_ends_with_the_run(tmp_path):
    run = start_adcs('run', _scenario(tmp_path), '--compose', '--quiet')
    master, slave = pty.openpty()
    watch = None
    try:
        wait_manifest(run)
        watch = subprocess.Popen([sys.executable, '-m', 'adcs_nodes.tools.cli', 'status',
                                  '--watch', '--run', str(run.pid)], cwd=ROOT, stdin=slave,
                                 stdout=slave, stderr=slave, close_fds=True)
        os.close(slave)

        # every line filled: each topic's first message comes when discovery has matched it,
        # in any order (CI run 28: a screen had everything but the latched controller status,
        # '(no adcs/controller_status yet)', which came on a later screen)
        def full_view(text):
            screens = text.split(CLEAR)
            return len(screens) > 2 and 'wheel momentum:  wheel_x' in screens[-1] \
                and 'controller:      (no ' not in screens[-1] \
                and re.search(r'attitude error:  [0-9.]+ deg', screens[-1]) is not None \
                and 'noise_burst horizon_sensor' in screens[-1] \
                and '\n' in screens[-1].split('missed frames:')[-1]
        text = _read_until(master, watch, full_view, 90.0)
        screen = text.split(CLEAR)[-1]
        assert re.search(r'controller:      (bdot|magnetic|mpi)   mode: (detumble|acquire|point)'
                         r'   commanding: \w+', screen), screen
        assert re.search(r'sim time:        [0-9.]+ s', screen)
        assert re.search(r'rates:           [0-9.]+ deg/s inertial, [0-9.]+ deg/s', screen)
        assert re.search(r'wheel momentum:  wheel_x [+-][0-9.]+  wheel_y [+-][0-9.]+  '
                         r'wheel_z [+-][0-9.]+ N m s', screen)
        assert 'faults:          noise_burst horizon_sensor (since 50 s)' in screen
        assert re.search(r'missed frames:   0 in \d+ nodes', screen)
        # refreshed about once a second: the screens carry increasing wall-clock stamps
        stamps = re.findall(r'\), (\d\d:\d\d:\d\d); Ctrl-C ends', text)
        assert len(set(stamps)) >= 2
        # it ends by itself when the run ends
        rest = _read_until(master, watch, lambda t: 'ended' in t, 120.0)
        assert f'run {run.pid} ended' in rest
        assert watch.wait(timeout=30) == 0
        assert run.wait(timeout=60) == 0
    finally:
        for proc in (watch, run):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait(timeout=30)
        os.close(master)
