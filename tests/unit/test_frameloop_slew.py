"""Paper 003's slews on the FrameLoop (the plain engine: no ROS, no process): a target replaced
in the middle of a slew (what a preempting ``adcs/slew`` goal does to guidance) ends at the new
target, and a scheduled switch to the fuzzy law mid-run starts a slew within the torque limit.

These were launched-graph tests (``tests/integration/test_slew_action_graph.py``); the
assertions are theirs, with the same numbers and tolerances. The action itself (goal checks,
preemption, cancel) is ``tests/node/test_slew_action.py``; one slew goal on a launched graph
is ``tests/graph/test_slew_action_graph.py`` (the preempted one runs in ``make test-long``).
"""
import numpy as np

from adcs_nodes.core import attitude as att
from frameloop_run import q, raw, run, t_s, validated

AT_REST = {'q_orbit_body_xyzw': [0.0, 0.0, 0.0, 1.0], 'omega_body_orbit_body_deg_s': [0.0] * 3}


def _q321(roll_deg, pitch_deg, yaw_deg):
    return [float(c) for c in att.from_euler_321(*np.radians([roll_deg, pitch_deg, yaw_deg]))]


def test_a_target_replaced_mid_slew_is_where_the_slew_ends(tmp_path):
    """The graph test's goals (orbit frame): 60 deg of roll, replaced mid-slew by 10 deg of
    pitch (there: a second ``adcs slew`` goal preempting the first); the attitude ends within
    0.5 deg of the second target."""
    first, second = _q321(60.0, 0.0, 0.0), _q321(0.0, 10.0, 0.0)
    sc = raw('paper003_slew')
    sc['initial'] = dict(AT_REST)
    sc['guidance']['profile'] = [{'t_s': 0.0, 'type': 'hold', 'q_xyzw': first},
                                 {'t_s': 10.0, 'type': 'hold', 'q_xyzw': second}]
    out, _ = run(validated(tmp_path, sc, 'slew'), 100.0)
    states = {round(t_s(m), 6): m for m in out['sim/state']}
    to_first = np.degrees(att.angle_between(q(states[10.0].q_orbit_body), first))
    assert 1.0 < to_first < 59.0, to_first                  # replaced while under way
    assert {m.source for m in out['adcs/actuator_command']} == {'fuzzy'}
    final = out['sim/state'][-1].q_orbit_body
    assert np.degrees(att.angle_between(q(final), second)) < 0.5


def test_switching_to_fuzzy_mid_run_starts_a_slew_within_the_torque_limit(tmp_path):
    """reference_slew holds the start attitude (target = itself), then a scripted switch to
    fuzzy with a 20 deg target: one zero frame, then a slew; no command above 1 N m/axis."""
    sc = raw('paper003_slew')
    start = _q321(0.0, 0.0, 20.0)
    sc['initial'] = {'q_orbit_body_xyzw': start, 'omega_body_orbit_body_deg_s': [0.0] * 3}
    sc['guidance']['profile'] = [
        {'t_s': 0.0, 'type': 'hold', 'q_xyzw': start},
        {'t_s': 5.0, 'type': 'hold', 'q_xyzw': [0.0, 0.0, 0.0, 1.0]}]
    sc['manager'] = {'safe': 'reference_slew', 'initial': 'reference_slew',
                     'schedule': [{'t_s': 5.0, 'controller': 'fuzzy'}]}
    out, _ = run(validated(tmp_path, sc, 'switch'), 40.0)
    cmds = out['adcs/actuator_command']
    src = [m.source for m in cmds]
    assert src[:50] == ['reference_slew'] * 50 and src[50] == 'zero'
    assert set(src[51:]) == {'fuzzy'}
    torque = np.array([[m.torque_body.x, m.torque_body.y, m.torque_body.z] for m in cmds])
    assert np.max(np.abs(torque)) <= 1.0 + 1e-12          # no jump above the limit
    assert np.max(np.abs(torque[51:])) > 0.2                # the slew did start
    final = out['sim/state'][-1].q_orbit_body
    assert np.degrees(att.angle_between(q(final), att.identity())) < 2.0
