"""The adcs/slew action on a running graph (issue 10): a goal succeeds at its target; a goal
preempted by a second goal ends at the second target (``make test-long``); bad goals are
refused with a reason before anything is sent.

Behaviour on the FrameLoop, with the same assertions, in ``make test``: a target replaced
mid-slew ends at the new one, and a scheduled switch to the fuzzy law starts a slew within the
torque limit (``tests/unit/test_frameloop_slew.py``; the switch test was here). The action
server's preemption and cancel: ``tests/node/test_slew_action.py``.
"""
import os
import signal

import numpy as np
import pytest
import yaml

from adcs_launch import SCENARIOS, StatusWatch, adcs, start_adcs, wait_manifest
from adcs_nodes.core import attitude as att
from adcs_nodes.bag import read_messages


def _scenario(tmp_path):
    with open(os.path.join(SCENARIOS, 'paper003_slew.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['initial'] = {'q_orbit_body_xyzw': [0.0, 0.0, 0.0, 1.0],
                     'omega_body_orbit_body_deg_s': [0.0, 0.0, 0.0]}
    path = tmp_path / 'slew.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


def _start(tmp_path, bag):
    """The slew scenario's graph, composed and paced at 10 x real time (100 frames a wall
    second): one process per node free-running starved the status and slew clients it talks
    to (CI of stop 29: no ``adcs status`` poll saw the manager in 120 s beside a CPU burner).
    At 50 x the slew (33 s of sim time) lasted 0.66 s of wall time, and in CI run 40 the
    client saw none of its feedback: an action client's ``wait_for_server`` sees the server,
    not whether the server's feedback writer has matched the client's reader yet, and
    feedback is volatile. At 10 x the slew lasts 3.3 s. The action server, its feedback and
    the law are the same node code in any engine and at any pace."""
    return start_adcs('run', _scenario(tmp_path), '--record', bag, '--duration', '100000',
                      '--quiet', '--compose', '--rate', '10')


def _wait_running(proc):
    """Waits until the manager reports the fuzzy law active, with one ``adcs status --watch``
    that stays subscribed (a poll listens 3 s only)."""
    wait_manifest(proc)
    watch = StatusWatch(proc.pid)
    try:
        watch.wait(lambda s: 'controller: fuzzy' in s)
    finally:
        watch.close()


def test_a_slew_goal_succeeds_at_its_target(tmp_path):
    """One goal on a running graph: ``adcs slew`` gets the action's feedback and its success,
    and the recorded attitude ends within 0.5 deg of the goal."""
    bag = str(tmp_path / 'slew')
    proc = _start(tmp_path, bag)
    try:
        _wait_running(proc)
        done = adcs('slew', '--to', '0', '10', '0', '--frame', 'orbit', '--run',
                    str(proc.pid), timeout=300)
        lines = done.stdout.strip().splitlines()
        assert any(line.lstrip().startswith('t ') for line in lines), done.stdout  # feedback
        assert lines[-1].startswith('succeeded'), done.stdout
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    states = list(read_messages(bag, ['/sim/state']))
    q = states[-1][2].q_orbit_body
    target = att.from_euler_321(0.0, np.radians(10.0), 0.0)
    assert np.degrees(att.angle_between([q.x, q.y, q.z, q.w], target)) < 0.5


@pytest.mark.long
def test_a_preempted_slew_ends_at_the_second_target(tmp_path):
    """``make test-long``: the preemption is the action server's (``tests/node/
    test_slew_action.py``), the slew to a replaced target the FrameLoop's (``tests/unit/
    test_frameloop_slew.py``); this is both on a launched graph (about two minutes)."""
    bag = str(tmp_path / 'slew')
    proc = _start(tmp_path, bag)
    first = None
    try:
        _wait_running(proc)
        # The first goal must still run when the second one arrives: the lockstep graph does
        # the 60 deg slew in about 100 s of sim time, a few s of wall time, and the second
        # `adcs slew` process took 8-11 s to start and send its goal at load 8 (the first one
        # was 0.9 deg from done once). With a tolerance it cannot reach (the fuzzy law ends
        # 0.01 deg off) and no sim-time timeout, only the preemption can end it.
        first = start_adcs('slew', '--to', '60', '0', '0', '--frame', 'orbit',
                           '--tolerance-deg', '1e-9', '--timeout-s', '1e9',
                           '--run', str(proc.pid))
        assert first.stdout.readline().lstrip().startswith('t ')   # accepted: feedback
        second = adcs('slew', '--to', '0', '10', '0', '--frame', 'orbit', '--run',
                      str(proc.pid), timeout=300)
        out1, err1 = first.communicate(timeout=60)
        assert first.returncode == 2 and 'preempted' in (out1 + err1)
        assert second.stdout.strip().splitlines()[-1].startswith('succeeded'), second.stdout
    finally:
        if first is not None and first.poll() is None:    # not preempted: it would never end
            first.kill()
            first.communicate()
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    states = list(read_messages(bag, ['/sim/state']))
    q = states[-1][2].q_orbit_body
    target = att.from_euler_321(0.0, np.radians(10.0), 0.0)
    assert np.degrees(att.angle_between([q.x, q.y, q.z, q.w], target)) < 0.5


def test_bad_goals_are_refused_before_sending():
    bad = adcs('slew', '--to', '0', '0', '0', '--controller', 'nope', check=False)
    assert bad.returncode == 2 and 'nope' in bad.stderr
