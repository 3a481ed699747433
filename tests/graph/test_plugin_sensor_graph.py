"""A plugin sensor feeding a new input kind runs in a launched graph (issue 34): the scenario of
``tests/unit/test_frameloop_plugin_sensor.py`` (``tests/plugins/zenith_sensor.py``: its record,
model, entry and controller, nothing else) one process per node, the sensor in the generic
sensor node. Its bag equals the plain engine's on every data topic, the new topic included,
and the plugin controller's torque was applied."""
import os
import sys

import numpy as np

from adcs_launch import ROOT, data_digest, graph_and_plain_bags
from adcs_nodes.bag import read_messages

sys.path.insert(0, os.path.join(ROOT, 'tests', 'unit'))
from test_frameloop_plugin_sensor import _forget_the_plugin, zenith_scenario  # noqa: E402,F401


def test_zenith_plugin_sensor_runs_in_a_launched_graph(tmp_path):
    graph, plain = graph_and_plain_bags(zenith_scenario(tmp_path), tmp_path, 'zenith_graph')
    torques = [np.array([m.torque_body.x, m.torque_body.y, m.torque_body.z])
               for _, _, m in read_messages(graph, ['/adcs/actuator_command'])
               if m.source == 'zenith_pointer']
    assert len(torques) == 21                       # every 0.1 s frame of 2 s
    assert sum(bool(np.any(t)) for t in torques) == 11      # the frames with a zenith sample
    a, b = data_digest(graph), data_digest(plain)
    assert a['/sensors/zenith'][0] == 11
    assert a == b
