"""Issue 8's proof: a controller defined in a test plugin runs in a launched graph.

The plugin (``tests/plugins/toy_controller.py``: one class, one registry entry) is named in
the scenario's ``plugins`` list; validation, the graph, the node parameters and the switch
all come from its entry, with no other file touched.
"""
import os

import numpy as np
import pytest
import yaml

from adcs_launch import ROOT, SCENARIOS, adcs
from adcs_nodes.bag import header_stamp_ns, read_messages

EPOCH_NS = 1767225600 * 10**9
TOY = os.path.join(ROOT, 'tests', 'plugins', 'toy_controller.py')


def toy_scenario(tmp_path, **toy):
    with open(os.path.join(SCENARIOS, 'paper000_control.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['sensors']['magnetometer']['period_s'] = 2.0
    sc['timing']['timeout_s'] = 1.0
    sc['plugins'] = [TOY]
    sc['controllers']['toy'] = toy
    sc['manager']['schedule'] = [{'t_s': 10.0, 'controller': 'toy'}]
    path = tmp_path / 'toy.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


@pytest.mark.long   # a plugin in a launched graph: test_plugin_inputs_graph; a live switch:
#                    test_control_graph, both in make test
def test_toy_controller_from_a_plugin_runs_and_is_switched_to(tmp_path):
    bag = str(tmp_path / 'toy')
    adcs('run', toy_scenario(tmp_path, dipole_Am2=[1.0, -2.0, 3.0]), '--record', bag,
         '--duration', '20', '--quiet')
    cmds = {}
    for _, _, m in read_messages(bag, ['/adcs/actuator_command']):
        t = (header_stamp_ns(m) - EPOCH_NS) / 1e9
        cmds[t] = (m.source, np.array([m.dipole_body.x, m.dipole_body.y, m.dipole_body.z]))
    assert all(cmds[t][0] == 'magnetic' for t in range(0, 10, 2))
    assert cmds[10.0][0] == 'zero'                          # one zero frame at the switch
    for t in range(12, 21, 2):
        assert cmds[float(t)][0] == 'toy'
        assert np.array_equal(cmds[float(t)][1], [1.0, -2.0, 3.0])
    toy_cmds = list(read_messages(bag, ['/adcs/controllers/toy/command']))
    assert len(toy_cmds) == 11                               # shadow mode: every frame


def test_a_bad_toy_parameter_is_refused_with_its_range(tmp_path):
    out = adcs('validate', toy_scenario(tmp_path, dipole_Am2=[1.0, -2.0, 300.0]), check=False)
    assert out.returncode == 2
    assert 'controllers.toy.dipole_Am2' in out.stderr and '<= 40' in out.stderr


def test_a_misspelt_toy_parameter_gets_a_did_you_mean(tmp_path):
    out = adcs('validate', toy_scenario(tmp_path, dipole_am2=[1.0, 2.0, 3.0]), check=False)
    assert out.returncode == 2
    assert "did you mean 'dipole_Am2'" in out.stderr


@pytest.fixture(autouse=True)
def _forget_plugin():
    yield   # the plugin registers into this process's registry too (validation in-process)
