"""The parameter file ``adcs run`` gives the node processes (``graph.params_file_text``) for
every shipped scenario holds no empty list: rclpy cannot type one and refuses to declare a
typed array from it (``PARAMETER_NOT_SET``). The mpi controller's unset
``model_inertia_kgm2`` failed every one-process-per-node run of demo_mission that way (found by
``adcs soak``); the composed engine, which passes parameters in process, did not show it."""
import glob
import os

import pytest
import yaml

from adcs_nodes.graph import build_graph, params_file_text
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENARIOS = sorted(glob.glob(os.path.join(ROOT, 'scenarios', '*.yaml')))


def _empty_lists(tree, path=''):
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield from _empty_lists(value, f'{path}/{key}')
    elif isinstance(tree, list) and not tree:
        yield path


@pytest.mark.parametrize('path', SCENARIOS, ids=os.path.basename)
def test_no_empty_list_reaches_a_node_process(path):
    nodes = build_graph(load_scenario(path), 10.0)
    doc = yaml.safe_load(params_file_text(nodes))
    assert sorted(doc) == sorted(f'/{n.name}' for n in nodes)
    assert list(_empty_lists(doc)) == []


def test_an_empty_list_is_left_out_and_the_rest_kept():
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'demo_mission.yaml'))
    nodes = build_graph(sc, 10.0)
    mpi = next(n for n in nodes if n.name == 'mpi_controller')
    assert mpi.params['model_inertia_kgm2'] == []         # the scenario leaves it unset
    params = yaml.safe_load(params_file_text(nodes))['/mpi_controller']['ros__parameters']
    assert 'model_inertia_kgm2' not in params
    assert params['inertia_kgm2'] == mpi.params['inertia_kgm2']
