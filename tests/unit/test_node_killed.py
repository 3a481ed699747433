"""The node fault (issue 21): ``node_killed`` on the plain engine (the FrameLoop), what the rest
of the flight software, the world and the run summary say, and its validation. The launched
graph (the launcher's SIGKILL) is tests/graph/test_node_killed_graph.py.

Scenario: paper000_control (magnetic law active, B-dot the safe controller, the magnetometer
filter as estimator; 2 s frames, 10 s magnetometer), 60 s, a node killed at 20 s.
"""
import os

import numpy as np
import pytest
import yaml

from adcs_nodes.msgs.fields import stamp_ns, vec3
from frameloop_run import messages
from adcs_nodes.scenario import ScenarioError, load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
KILL_S = 20.0
DURATION_S = 60.0


def scenario(tmp_path, faults, name='paper000_control'):
    with open(os.path.join(ROOT, 'scenarios', f'{name}.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['faults'] = faults
    path = tmp_path / 'killed.yaml'
    path.write_text(yaml.safe_dump(sc, sort_keys=False))
    return load_scenario(str(path))


def kill(tmp_path, target):
    return scenario(tmp_path, [{'at_s': KILL_S, 'kind': 'node_killed', 'target': target}])


def run(sc):
    """{topic: [(t_s, msg)]} of every frame, and the loop."""
    from sim_node.engine import FrameLoop
    loop = FrameLoop.from_scenario(sc, DURATION_S)
    out = {}
    for frame in loop.run():
        for topic, msg in messages(frame, loop):
            out.setdefault(topic, []).append((frame.t_ns / 1e9, msg))
    return out, loop


def stamps(out, topic):
    return [t for t, _ in out.get(topic, [])]


def no_nan_to_actuators(out):
    for _, m in out['adcs/actuator_command']:
        assert np.all(np.isfinite(vec3(m.dipole_body)))
        assert np.all(np.isfinite(np.asarray(m.wheel_torque, float)))


def sources(out):
    return {t: m.source for t, m in out['adcs/actuator_command']}


def test_a_killed_controller_publishes_nothing_more_and_the_manager_falls_back(tmp_path):
    out, loop = run(kill(tmp_path, 'magnetic_controller'))
    got = stamps(out, 'adcs/controllers/magnetic/command')
    assert got and max(got) < KILL_S            # silent from the kill on
    assert stamps(out, 'adcs/controllers/bdot/command')[-1] == DURATION_S   # the others go on
    src = sources(out)
    assert {src[t] for t in src if t < KILL_S} == {'magnetic'}
    assert {src[t] for t in src if t >= KILL_S} == {'bdot'}    # the safe controller, at once
    st = loop.manager.core.status()
    assert st['missed_frames'] == (DURATION_S - KILL_S) / 2.0 + 1     # every frame from 20 s
    assert st['last_fault'].startswith('magnetic: stale') and 'fallback to bdot' in \
        st['last_fault']
    no_nan_to_actuators(out)
    faults = [(t, st.message) for t, m in out['sim/faults'] for st in m.status]
    assert faults == [(KILL_S, 'active: node_killed magnetic_controller')]


def test_a_killed_estimator_makes_the_manager_fall_back_for_the_stale_estimate(tmp_path):
    out, loop = run(kill(tmp_path, 'estimator'))
    assert max(stamps(out, 'adcs/attitude_estimate')) < KILL_S
    # the magnetic law still computes (on the last estimate) but the manager refuses it
    assert stamps(out, 'adcs/controllers/magnetic/command')[-1] == DURATION_S
    src = sources(out)
    assert {src[t] for t in src if t >= KILL_S} == {'bdot'}
    assert 'estimator stale' in loop.manager.core.status()['last_fault']
    no_nan_to_actuators(out)


def test_a_killed_manager_leaves_the_world_a_zero_command(tmp_path):
    out, loop = run(kill(tmp_path, 'controller_manager'))
    cmds = out['adcs/actuator_command']
    assert max(t for t, _ in cmds) < KILL_S
    assert np.abs(vec3(cmds[-1][1].dipole_body)).max() > 0.0   # it was commanding
    assert not np.any(loop.dynamics.applied['dipole_body'])     # the world applies zero


def test_a_killed_sensor_is_silent_and_the_estimator_counts_it(tmp_path):
    out, loop = run(kill(tmp_path, 'magnetometer'))
    assert max(stamps(out, 'sensors/magnetometer')) < KILL_S
    assert loop.estimator.rejected_count == 3                # 3 misses, then a dead producer
    no_nan_to_actuators(out)


def test_the_plain_run_ends_degraded_and_names_the_killed_node(tmp_path):
    from adcs_nodes.tools.run.plain import run_plain
    res = run_plain(kill(tmp_path, 'magnetic_controller'), DURATION_S, progress=False)
    assert res.exit_code == 3, res.message
    assert res.message.startswith('done, DEGRADED: lost magnetic_controller (killed at sim t '
                                  "= 20 s: the scenario's faults[0]); the controller manager "
                                  'could not forward the active controller in 21 frames'), \
        res.message
    # a manager killed: no missed frames counted (it is gone), the run is degraded all the same
    res = run_plain(kill(tmp_path, 'controller_manager'), DURATION_S, progress=False)
    assert res.exit_code == 3 and 'lost controller_manager (killed at sim t = 20 s' in res.message
    # a kill after the end of the run did not happen
    res = run_plain(kill(tmp_path, 'magnetic_controller'), 10.0, progress=False)
    assert res.exit_code == 0, res.message


def test_the_same_node_kill_is_deterministic(tmp_path):
    a, _ = run(kill(tmp_path, 'estimator'))
    b, _ = run(kill(tmp_path, 'estimator'))
    for topic in ('sim/state', 'adcs/actuator_command'):
        assert [stamp_ns(m.header.stamp) for _, m in a[topic]] == \
            [stamp_ns(m.header.stamp) for _, m in b[topic]]
        assert [str(m) for _, m in a[topic]] == [str(m) for _, m in b[topic]]


@pytest.mark.parametrize('fault, key, why', [
    ({'at_s': 1.0, 'kind': 'node_killed', 'target': 'star_tracker'}, 'faults[0].target',
     "node_killed cannot strike 'star_tracker'; it strikes node: magnetometer, estimator, "
     'guidance, magnetic_controller, bdot_controller, controller_manager'),
    ({'at_s': 1.0, 'kind': 'node_killed', 'target': 'dynamics'}, 'faults[0].target',
     'cannot strike'),
    ({'at_s': 1.0, 'kind': 'node_killed', 'target': 'recorder'}, 'faults[0].target',
     'cannot strike'),
    ({'at_s': 1.0, 'kind': 'node_killed', 'target': 'estimator',
      'params': {'duration_s': 5.0}}, 'faults[0].params', 'duration_s'),
    ({'at_s': 1e9, 'kind': 'node_killed', 'target': 'estimator'}, 'faults[0].at_s',
     'outside the run'),
])
def test_bad_node_kills_are_refused_with_file_line_and_key(tmp_path, fault, key, why):
    with pytest.raises(ScenarioError) as exc:
        scenario(tmp_path, [fault])
    text = str(exc.value)
    path = str(tmp_path / 'killed.yaml')
    with open(path) as fh:
        line = 1 + next(i for i, ln in enumerate(fh) if ln.startswith('faults:'))
    assert f'{path}:{line}' in text and key in text and why in text, text


def test_node_kill_is_refused_live_and_listed_in_the_docs():
    from sim_node.faults import check
    with pytest.raises(ValueError, match='scripted fault only'):
        check('node_killed', 'estimator', {}, ['gyro'], [], True)
    from adcs_nodes.scenario import schema_markdown
    assert '| `node_killed` | node | none |' in schema_markdown()
