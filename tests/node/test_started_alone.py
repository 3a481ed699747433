"""A node started as a ROS 2 user starts one (issue 37, items 9 and 11).

* every node module with a ``main`` has a ``ros2 run`` entry point (the mounts node
  ``adcs_nodes.nodes.tf`` and the slew action server had none);
* ``controller --ros-args -p controller:=bdot`` (the README's own line) is the node
  ``bdot_controller``, not ``magnetic_controller`` publishing B-dot commands; a params file's
  ``/**`` section names it too;
* a node started alone says in its first line what it waits for and what it publishes (a
  magnetometer printed nothing at all).

The processes are started as ``ros2 run`` starts the console scripts (``python -m`` of the
same ``main``); waits are deadlines on the graph or on the output, never sleeps.
"""
import ast
import os
import queue
import signal
import subprocess
import sys
import threading
import time

import rclpy

from domains import worker_domain
from adcs_nodes.nodes.runtime import given_parameter
from adcs_nodes.tools.run.launcher import child_env

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _console_scripts(package):
    with open(os.path.join(ROOT, package, 'setup.py'), encoding='utf-8') as fh:
        tree = ast.parse(fh.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts':
                    return [ast.literal_eval(v).split('=', 1)[1].strip() for v in value.elts]
    return []


def test_every_node_module_with_a_main_has_an_entry_point():
    targets = set(_console_scripts('adcs_nodes')) | set(_console_scripts('sim_node'))
    missing = []
    for package in ('adcs_nodes', 'sim_node'):
        folder = os.path.join(ROOT, package, package, 'nodes')
        for fname in sorted(os.listdir(folder)):
            if not fname.endswith('.py'):
                continue
            with open(os.path.join(folder, fname), encoding='utf-8') as fh:
                tree = ast.parse(fh.read())
            if any(isinstance(n, ast.FunctionDef) and n.name == 'main' for n in tree.body):
                target = f'{package}.nodes.{fname[:-3]}:main'
                if target not in targets:
                    missing.append(target)
    assert missing == [], f'no ros2 run entry point for {missing}'


def test_the_controller_parameter_is_read_from_the_ros_arguments(tmp_path):
    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters:\n    controller: mpi\n')
    assert given_parameter('controller', ['x', '--ros-args', '-p', 'controller:=bdot']) == 'bdot'
    assert given_parameter('controller', ['x', '--ros-args', '--params-file', str(params)]) \
        == 'mpi'
    assert given_parameter('controller', ['x', '--ros-args', '--params-file', str(params),
                                          '-p', 'controller:=bdot']) == 'bdot'
    assert given_parameter('controller', ['x', '--ros-args', '-p', 'period_s:=2.0']) is None


class _Output:
    """A process's stderr lines, read by a thread (so a wait has a deadline)."""

    def __init__(self, stream):
        self.lines, self._q = [], queue.Queue()
        threading.Thread(target=lambda: [self._q.put(ln) for ln in stream], daemon=True).start()

    def first(self, text, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self._q.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                break
            self.lines.append(line)
            if text in line:
                return line
        raise AssertionError(f'no line with {text!r} in {timeout} s: {self.lines}')


def _start(env, *argv):
    proc = subprocess.Popen([sys.executable, '-m', *argv], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    return proc, _Output(proc.stderr)


def _stop(procs):
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in procs:
        try:
            p.wait(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def test_started_alone_each_node_says_what_it_waits_for_and_publishes_and_is_named_right():
    env = child_env(worker_domain(152, 20))
    procs = []
    try:
        mag, mag_out = _start(env, 'sim_node.nodes.sensor_node', '--ros-args', '-p',
                              'sensor:=magnetometer')
        ctl, ctl_out = _start(env, 'adcs_nodes.nodes.controller', '--ros-args', '-p',
                              'controller:=bdot')
        procs = [mag, ctl]
        first = mag_out.first('[magnetometer]', 120.0)
        assert 'waits for /clock' in first and '/sim/state' in first, first
        assert 'publishes /sensors/magnetometer' in first and 'started alone' in first, first
        first = ctl_out.first('_controller]', 120.0)
        assert first.split(']: ', 1)[0].endswith('[bdot_controller'), first
        assert 'live: fires every 2 s' in first and '/sensors/magnetometer' in first, first
        assert 'publishes /adcs/controllers/bdot/command' in first, first
        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=int(env['ROS_DOMAIN_ID']))
        probe = rclpy.create_node('probe_names', context=ctx)
        try:
            deadline = time.monotonic() + 60.0
            while 'bdot_controller' not in probe.get_node_names() and \
                    time.monotonic() < deadline:
                time.sleep(0.05)
            assert 'bdot_controller' in probe.get_node_names()
            assert 'magnetic_controller' not in probe.get_node_names()
        finally:
            probe.destroy_node()
            rclpy.shutdown(context=ctx)
    finally:
        _stop(procs)
