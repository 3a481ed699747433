"""Live faults are in the record and only their target speaks (issue 38 item 5).

``sim/faults`` is recorded also when the scenario scripts no fault (a live one from ``adcs
fault`` lands there); a sensor node ignores an actuator's live fault in silence (it used to
log "live fault refused" for every wheel fault), the dynamics takes it. The graph test
``tests/graph/test_fault_live.py`` shows ``adcs fault --at`` returning once the fault is
scheduled.
"""
import json
import os

from adcs_nodes.graph import build_graph
from adcs_nodes.scenario import load_scenario
from sim_node.faults import injected

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_sim_faults_is_recorded_without_scripted_faults():
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper000_control.yaml'))
    assert not sc.get('faults')
    nodes = {n.name: n for n in build_graph(sc, 10.0, record=True)}
    assert 'sim/faults' in nodes['dynamics'].publishes
    assert any(t.startswith('sim/faults=') for t in nodes['recorder'].params['topics'])
    assert 'pub:sim/faults=1' in nodes['dynamics'].params['expected_matches']


def test_an_actuator_fault_is_the_dynamics_not_a_sensor_nodes():
    text = json.dumps({'index': 1001, 'kind': 'wheel_stuck', 'target': 'wheel_x',
                       'at_s': None, 'params': {}})
    assert injected(text, 0, sensors=['magnetometer']) is None        # silent
    assert injected(text, 0, sensors=None, wheels=['wheel_x']).target == 'wheel_x'
    coil = json.dumps({'index': 1002, 'kind': 'coil_open', 'target': 'x', 'at_s': 3.0,
                       'params': {}})
    assert injected(coil, 0, sensors=['gyro']) is None
    assert injected(coil, 0, sensors=None, magnetorquer=True).start_ns == 3 * 10**9
