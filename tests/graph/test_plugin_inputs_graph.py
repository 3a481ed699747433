"""A plugin controller that reads the gyro and the star tracker runs in a launched graph (issue
19: inputs are records, so a registered controller may declare any input kind, and the graph
builder wires it with no other change).

The scenario of ``tests/unit/test_frameloop_plugin_inputs.py`` (paper 003's spacecraft with a
gyro, a star tracker and ``tests/plugins/gyro_damper.py`` active from t = 0) runs one process
per node; its bag equals the plain engine's on every data topic, and the damper's torque was
applied (it commands nothing until both inputs have reached it).
"""
import os
import sys

import numpy as np

from adcs_launch import ROOT, data_digest, graph_and_plain_bags
from adcs_nodes.bag import read_messages

sys.path.insert(0, os.path.join(ROOT, 'tests', 'unit'))
from test_frameloop_plugin_inputs import _forget_the_plugin, damper_scenario  # noqa: E402,F401


def test_gyro_and_star_tracker_plugin_runs_in_a_launched_graph(tmp_path):
    graph, plain = graph_and_plain_bags(damper_scenario(tmp_path), tmp_path, 'damper_graph')
    torques = [np.array([m.torque_body.x, m.torque_body.y, m.torque_body.z])
               for _, _, m in read_messages(graph, ['/adcs/actuator_command'])
               if m.source == 'gyro_damper']
    assert len(torques) == 21                       # every 0.1 s frame of 2 s
    assert np.linalg.norm(torques[-1]) > 0.1        # the damper got the gyro and the star
    a, b = data_digest(graph), data_digest(plain)
    assert '/sensors/gyro' in a and '/sensors/star_tracker' in a
    assert a == b
