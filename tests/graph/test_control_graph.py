"""The closed-loop graph: run-time switching through the manager's service, unknown names, a
killed controller.

Runs go through the real ``adcs`` command; switches through ``adcs switch`` on the running
graph (a long lockstep run, stopped with Ctrl-C once the checks are done).

The behaviour tests that were here run on the FrameLoop now, with the same assertions:
the estimator converging, paper 004's yaw reproduction, the scheduled switch and the
automatic sequence (``tests/unit/test_frameloop_control.py``); the graph gives the
FrameLoop's series on every data topic (``tests/graph/test_engine_parity.py``).
"""
import os
import re
import signal
import time

import numpy as np
import pytest

from adcs_launch import StatusWatch, adcs, control_scenario, start_adcs, wait_manifest
from adcs_nodes.bag import header_stamp_ns, read_messages
from bag_digest import topic_summary

EPOCH_NS = 1767225600 * 10**9


def commands(bag):
    out = []
    for _, _, m in read_messages(bag, ['/adcs/actuator_command']):
        out.append(((header_stamp_ns(m) - EPOCH_NS) / 1e9, m.source,
                    np.array([m.dipole_body.x, m.dipole_body.y, m.dipole_body.z])))
    return out


def running(status_text, sim_s=20.0):
    """True once the controller manager has run past ``sim_s`` (the lockstep is going)."""
    m = re.search(r'sim time: ([0-9.]+) s', status_text)
    return m is not None and float(m.group(1)) >= sim_s


def sim_time(status_text):
    """Sim time [s] an ``adcs status`` text reports."""
    return float(re.search(r'sim time: ([0-9.]+) s', status_text).group(1))


def wait_status(pid, predicate, timeout=120.0):
    """The first ``adcs status`` text that satisfies ``predicate``. One poll takes 3 s of
    listening plus the start of a Python process with rclpy (10-13 s in all at load 18), so
    the deadline is generous; it costs nothing when the condition comes early."""
    deadline = time.monotonic() + timeout
    out = None
    while time.monotonic() < deadline:
        out = adcs('status', '--run', str(pid), check=False)
        if out.returncode == 0 and predicate(out.stdout):
            return out.stdout
        time.sleep(0.5)
    raise AssertionError(f'status condition not reached; last: {out.stdout} {out.stderr}')


def wait_log_stamp(run_dir, name, text, after, timeout=60.0):
    """Wall-clock stamp [s since the epoch] of the first line of node ``name``'s log that
    holds ``text`` and is stamped after ``after`` (ROS log format ``[LEVEL] [stamp] [node]:
    message``)."""
    path = os.path.join(run_dir, 'logs', f'{name}.log')
    pattern = re.compile(r'^\[\w+\] \[(\d+\.\d+)\] \[' + re.escape(name) + r'\]: .*'
                         + re.escape(text), re.M)
    deadline = time.monotonic() + timeout
    while True:
        with open(path) as fh:
            stamps = [float(m.group(1)) for m in pattern.finditer(fh.read())]
        stamps = [t for t in stamps if t > after]
        if stamps:
            return stamps[0]
        if time.monotonic() > deadline:
            raise AssertionError(f'no {text!r} in {path} within {timeout} s')
        time.sleep(0.1)


def test_switch_mid_run_gives_one_zero_frame_each_and_unknown_is_refused(tmp_path):
    bag = str(tmp_path / 'switching')
    # composed and paced (--rate: lockstep at most 100 x real time, 50 frames/s): the run
    # leaves the CPU to the switch and status clients it talks to (free-running, one process
    # per node, it starved them: 58 s instead of 20 in make test); the manager, its service
    # and the one-zero-frame rule are the same node code in any engine and at any pace
    proc = start_adcs('run', control_scenario(tmp_path), '--record', bag,
                      '--duration', '200000', '--quiet', '--compose', '--rate', '100')
    watch = None
    try:
        wait_manifest(proc)
        watch = StatusWatch(proc.pid)
        watch.wait(lambda s: 'controller: magnetic' in s and running(s))
        bad = adcs('switch', 'no_such_law', '--run', str(proc.pid), check=False)
        assert bad.returncode == 2
        assert "unknown controller 'no_such_law'" in bad.stderr and 'magnetic' in bad.stderr
        assert 'switch magnetic -> bdot' in adcs('switch', 'bdot', '--run', str(proc.pid)).stdout
        status = watch.wait(lambda s: 'controller: bdot' in s and 'switches: 1' in s)
        watch.wait(lambda s: running(s, sim_time(status) + 10.0))   # 5 bdot frames
        back = adcs('switch', 'magnetic', '--run', str(proc.pid)).stdout
        assert 'switch bdot -> magnetic' in back
        status = watch.wait(lambda s: 'controller: magnetic' in s and 'switches: 2' in s)
        watch.wait(lambda s: running(s, sim_time(status) + 10.0))
    finally:
        if watch is not None:
            watch.close()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, out + err
    cmds = commands(bag)
    sources = [s for _, s, _ in cmds]
    # runs of sources: magnetic..., zero, bdot..., zero, magnetic...
    runs = [sources[0]] + [s for a, s in zip(sources, sources[1:]) if s != a]
    assert runs == ['magnetic', 'zero', 'bdot', 'zero', 'magnetic'], runs
    zero_idx = [i for i, s in enumerate(sources) if s == 'zero']
    assert len(zero_idx) == 2                                  # exactly one frame each
    for i in zero_idx:
        assert np.all(cmds[i][2] == 0.0)
    # every command is stamped on the 2 s control grid, none missing
    times = [t for t, _, _ in cmds]
    assert np.allclose(np.diff(times), 2.0)
    status = [m for _, _, m in read_messages(bag, ['/adcs/controller_status'])]
    assert status[-1].switch_count == 2 and status[-1].active == 'magnetic'


@pytest.mark.long   # a killed flight-software process: test_node_killed_graph in make test;
#                    the fallback rule: tests/unit/test_frameloop_faults.py
def test_killed_controller_falls_back_to_bdot_and_the_graph_goes_on(tmp_path):
    bag = str(tmp_path / 'killed')
    proc = start_adcs('run', control_scenario(tmp_path), '--record', bag,
                      '--duration', '200000', '--quiet')
    try:
        manifest = wait_manifest(proc)
        wait_status(proc.pid, lambda s: 'controller: magnetic' in s and running(s))
        t_kill = time.time()
        os.kill(manifest['pids']['magnetic_controller'], signal.SIGKILL)
        status = wait_status(proc.pid, lambda s: 'fallback to bdot' in s)
        # the manager fell back within a few input timeouts (3 x 1 s) of wall time after the
        # kill: the wall-clock stamp of its log line, not when a status poll saw it (one
        # poll took 12 s at load 18, and the next one would have come after the old 15 s)
        fallback_wall = wait_log_stamp(manifest['run_dir'], 'controller_manager',
                                       'fallback to bdot', after=t_kill)
        assert fallback_wall - t_kill < 15.0, fallback_wall - t_kill
        t_fallback = sim_time(status)
        # the graph keeps running on the fallback: 20 more sim seconds
        wait_status(proc.pid, lambda s: running(s, t_fallback + 20.0), timeout=120.0)
        assert proc.poll() is None, 'the run stopped when a controller died'
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, out + err
    assert 'magnetic_controller exited with code -9' in out + err
    assert 'stale' in status or 'no command' in status or 'fallback' in status
    cmds = commands(bag)
    sources = [s for _, s, _ in cmds]
    assert sources[0] == 'magnetic' and sources[-1] == 'bdot'
    after = sources[sources.index('bdot'):]
    assert len(after) > 5 and set(after) == {'bdot'}            # fallback holds
    summary = topic_summary(bag)         # the bag is valid (stopped by Ctrl-C: the topics may
    assert summary['/sim/state'][1] > 10  # end a few frames apart, as the recorder's lag)
