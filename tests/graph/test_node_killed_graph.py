"""The node fault in a launched graph (issue 21): a scenario's ``node_killed`` fault makes the
launcher SIGKILL the node's process once the run's clock reaches its time; the node went silent
at exactly that frame, so the graph gives the plain engine's series on every data topic and
the same degraded summary (exit 3, the node named, the manager's fallback frames counted).

paper000_control (magnetic law, B-dot safe) with a 1 s input timeout; 30 s of sim time, the
magnetic controller killed at 20 s (each frame after it waits the timeout for the dead
node's command: 1 s of wall time a frame). The plain engine's side is in
tests/unit/test_node_killed.py.
"""
import re

import yaml

from adcs_launch import adcs, control_scenario, data_digest, plain_run
from adcs_nodes.bag import read_messages


def test_killed_controller_process_and_the_graph_goes_on_as_the_plain_engine(tmp_path):
    path = control_scenario(tmp_path, faults=[
        {'at_s': 20.0, 'kind': 'node_killed', 'target': 'magnetic_controller'}])
    graph, plain = str(tmp_path / 'graph'), str(tmp_path / 'plain')
    run = adcs('run', path, '--record', graph, '--duration', '30', '--quiet', timeout=600,
               check=False)
    text = run.stdout + run.stderr
    assert run.returncode == 3, text
    assert "[adcs] magnetic_controller: killed (SIGKILL) by the scenario's faults[0] at sim " \
        't = 20 s' in text, text
    assert 'node magnetic_controller exited with code -9' in text, text   # a real kill
    assert "DEGRADED: lost magnetic_controller (killed at sim t = 20 s: the scenario's " \
        'faults[0]); the controller manager could not forward the active controller in 6 ' \
        'frames (last fault: magnetic: stale' in text, text
    with open(f'{graph}/scenario.yaml') as fh:
        assert yaml.safe_load(fh)['faults'][0]['kind'] == 'node_killed'

    def seconds(topic):
        return [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
                for _, _, m in read_messages(graph, [topic])]
    mag, bdot = seconds('/adcs/controllers/magnetic/command'), \
        seconds('/adcs/controllers/bdot/command')
    assert max(mag) - min(mag) == 18.0 and max(bdot) - min(bdot) == 30.0   # silent from 20 s
    faults = [st.message for _, _, m in read_messages(graph, ['/sim/faults']) for st in m.status]
    assert faults == ['active: node_killed magnetic_controller']

    run_p = plain_run(path, 30, plain)
    assert run_p.exit_code == 3, run_p.message
    frames = re.findall(r'forward the active controller in (\d+) frames', text + run_p.message)
    assert len(frames) == 2 and len(set(frames)) == 1, frames   # the same count from either
    assert data_digest(graph) == data_digest(plain)
