"""The same bag replayed in lockstep gives the recorded estimates bit for bit.

A paper000_control run is recorded (the estimator there takes the magnetorquer command of the
previous frame into its prediction, so the closed loop's commands are part of its input). The
estimator then runs alone, ``timing_mode: lockstep`` with the parameters the launcher gave it
(``adcs replay BAG --lockstep --write-params``), and ``adcs replay BAG --lockstep`` feeds it
the recorded ``/clock``, ``/tf_static``, magnetometer samples and commands frame by frame.
Truth: the recorded ``adcs/attitude_estimate`` messages, compared as serialized CDR bytes (every
field of every message, floats exact), in order, none missing or extra.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time

import pytest
import yaml

from adcs_launch import ROOT, SCENARIOS, adcs

rclpy = pytest.importorskip('rclpy')
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from adcs_msgs.msg import AttitudeState  # noqa: E402

from adcs_nodes.tools import replay  # noqa: E402
from adcs_nodes.bag import open_bag, read_messages  # noqa: E402
from adcs_nodes.tools.run.launcher import child_env, use_dds_env  # noqa: E402
from domains import worker_domain  # noqa: E402

SCENARIO = os.path.join(SCENARIOS, 'paper000_control.yaml')
DURATION_S = 120.0
TOPIC = '/adcs/attitude_estimate'


def _env(k):
    """An isolated DDS domain for this test (and for rclpy in this process)."""
    env = child_env(worker_domain(150, 50, k))
    use_dds_env(env)
    return env


def _cli(*args, env, timeout=60):
    return subprocess.run([sys.executable, '-m', 'adcs_nodes.tools.cli', *args], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    out = str(tmp_path_factory.mktemp('lockstep') / 'bag')
    adcs('run', SCENARIO, '--record', out, '--duration', str(DURATION_S), '--quiet')
    return out


def _recorded(bag, topic):
    with open_bag(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [bytes(raw) for _, _, raw in reader.messages(connections=conns)]


def test_lockstep_replay_gives_the_recorded_estimates_bit_for_bit(bag, tmp_path):
    env = _env(0)
    recorded = _recorded(bag, TOPIC)
    assert len(recorded) == DURATION_S / 2.0 + 1          # one per 2 s frame, t = 0 ... 120 s
    dipoles = [abs(m.dipole_body.x) + abs(m.dipole_body.y) + abs(m.dipole_body.z)
               for _, _, m in read_messages(bag, ['/adcs/actuator_command'])]
    assert sum(d > 0 for d in dipoles) > 30      # the previous-frame command input matters

    params = str(tmp_path / 'estimator.yaml')
    replay.write_params(bag, ['estimator'], params, log=lambda text: None)  # as the CLI does
    with open(params, encoding='utf-8') as fh:
        doc = yaml.safe_load(fh)
    est_params = doc['/estimator']['ros__parameters']
    assert est_params['timing_mode'] == 'lockstep' and est_params['duration_s'] == DURATION_S
    # ready only once our probe reads its estimates (no estimate published before that match)
    est_params['expected_matches'].append('pub:adcs/attitude_estimate=1')
    with open(params, 'w', encoding='utf-8') as fh:
        yaml.safe_dump(doc, fh)

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    probe = rclpy.create_node('probe', context=ctx)
    got = []
    probe.create_subscription(AttitudeState, TOPIC, got.append,
                              QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE),
                              raw=True)
    executor = rclpy.executors.SingleThreadedExecutor(context=ctx)
    executor.add_node(probe)
    est_log = open(tmp_path / 'estimator.log', 'w')
    est = subprocess.Popen([sys.executable, '-m', 'adcs_nodes.nodes.estimator', '--ros-args',
                            '-r', '__node:=estimator', '--params-file', params],
                           cwd=ROOT, env=env, stdout=est_log, stderr=subprocess.STDOUT)
    proc = None
    try:
        proc = subprocess.Popen(
            [sys.executable, '-m', 'adcs_nodes.tools.cli', 'replay', bag, '--lockstep',
             '--wait', '120'],
            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + 180.0     # the estimator's start (--wait), 61 frames
        while proc.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        if proc.poll() is None:
            proc.kill()
        text = proc.communicate(timeout=10)[0]
        assert proc.returncode == 0, text + open(est_log.name).read()[-3000:]
        deadline = time.monotonic() + 10.0     # the last estimates may still be on their way
        while len(got) < len(recorded) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
        est.terminate()
        try:
            est.wait(timeout=10)
        except subprocess.TimeoutExpired:
            est.kill()
            est.wait(timeout=10)
        est_log.close()
        executor.shutdown()
        probe.destroy_node()
        rclpy.shutdown(context=ctx)
    log = open(est_log.name).read()
    assert '[estimator]: lockstep: fires each frame' in log and ': live: fires' not in log, \
        log[-2000:]
    assert '[replay] done:' in text and 'estimator processed its last frame' in text, text
    assert '61 frames' in text and '/adcs/actuator_command' in text, text
    assert len(got) == len(recorded), (len(got), len(recorded), log[-3000:])
    differ = [i for i, (a, b) in enumerate(zip(got, recorded)) if a != b]
    if differ:
        from rclpy.serialization import deserialize_message
        i = differ[0]
        pytest.fail(f'{len(differ)} of {len(recorded)} estimates differ, first #{i}:\n'
                    f'replayed {deserialize_message(got[i], AttitudeState)}\n'
                    f'recorded {deserialize_message(recorded[i], AttitudeState)}')
    # no missed frame: no lockstep warning, and the node's run summary counts none
    assert 'missed frame' not in log.lower(), log[-3000:]
    summaries = re.findall(r'run summary (\{.*\})', log)
    assert summaries and json.loads(summaries[-1])['missed_frames'] == 0, log[-3000:]


def _clock_only_bag(path):
    """A bag with /clock ticks only, beside a valid scenario: the estimator's inputs miss."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_KILTED)
    w = Writer(path, version=8, storage_plugin=StoragePlugin.MCAP)
    w.open()
    conn = w.add_connection('/clock', 'rosgraph_msgs/msg/Clock', typestore=store)
    Time = store.types['builtin_interfaces/msg/Time']
    for k in range(3):
        t = 1767225600 * 10**9 + k * 2 * 10**9
        c = store.types['rosgraph_msgs/msg/Clock'](clock=Time(sec=t // 10**9, nanosec=0))
        w.write(conn, t, store.serialize_cdr(c, 'rosgraph_msgs/msg/Clock'))
    w.close()
    shutil.copy(SCENARIO, os.path.join(path, 'scenario.yaml'))
    return str(path)


def test_lockstep_bad_input_exit_2_without_traceback(tmp_path, capsys):
    clock_only = _clock_only_bag(tmp_path / 'clock_only')
    cases = [
        ((clock_only, '--lockstep'), 'no topic /tf_static (needed by estimator)'),
        ((clock_only, '--lockstep'), '/sensors/magnetometer (needed by estimator)'),
        ((clock_only, '--lockstep'), '/adcs/actuator_command (needed by estimator)'),
        ((clock_only, '--lockstep', '--nodes', 'nosuch'), 'no node nosuch in the graph'),
        ((clock_only, '--lockstep', '--rate', '2'), '--rate cannot be used with it'),
        ((str(tmp_path / 'nothing'), '--lockstep'), 'not found'),
    ]
    os.makedirs(tmp_path / 'no_scenario')
    shutil.copy(os.path.join(clock_only, 'metadata.yaml'), tmp_path / 'no_scenario')
    for name in os.listdir(clock_only):
        if name.endswith('.mcap'):
            shutil.copy(os.path.join(clock_only, name), tmp_path / 'no_scenario')
    cases.append(((str(tmp_path / 'no_scenario'), '--lockstep'), 'no scenario.yaml'))
    parser = argparse.ArgumentParser()
    replay.add_arguments(parser)
    for args, text in cases[1:]:              # in process (fast): the exit code and message
        assert replay.run_from_args(parser.parse_args(args)) == 2, args
        err = capsys.readouterr().err
        assert err.startswith('adcs replay: ') and text in err, (args, err)
    args, text = cases[0]                     # the command itself: no traceback
    out = _cli('replay', *args, env=_env(1))
    assert out.returncode == 2, (args, out.stdout, out.stderr)
    assert out.stderr.startswith('adcs replay: ') and text in out.stderr, (args, out.stderr)
    assert 'Traceback' not in out.stderr + out.stdout


def test_lockstep_without_the_node_exits_1_after_the_wait(bag, tmp_path):
    """No estimator running: a clear message after --wait, no traceback."""
    out = _cli('replay', bag, '--lockstep', '--wait', '1', env=_env(2))
    assert out.returncode == 1, (out.stdout, out.stderr)
    assert 'estimator not ready' in out.stderr and '--write-params' in out.stderr, out.stderr
    assert 'Traceback' not in out.stderr + out.stdout
