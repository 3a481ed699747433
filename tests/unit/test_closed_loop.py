"""Plain closed loop (sim_node.tools.closed_loop): scenario edits and a short run's series.

That it gives the graph's trajectory is checked against recorded bags in
tests/graph/test_montecarlo.py (test_plain_engine_gives_the_graph_trajectory)."""
import math
import os

import numpy as np
import pytest

from adcs_nodes.tools.scenario import load_scenario

closed_loop = pytest.importorskip('sim_node.tools.closed_loop')
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENARIO = os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')


def test_with_changes_copies_and_sets_dotted_keys():
    sc = {'a': {'b': 1, 'c': 2}}
    out = closed_loop.with_changes(sc, {'a.b': 5, 'a.c': None, 'x.y': [1.0]})
    assert out == {'a': {'b': 5}, 'x': {'y': [1.0]}} and sc == {'a': {'b': 1, 'c': 2}}


def test_misalignment_vector_has_the_asked_magnitude():
    for deg in (0.0, 0.5, 2.0):
        assert np.linalg.norm(closed_loop.misalignment_vector(deg)) == pytest.approx(deg)


def test_short_run_starts_at_the_papers_initial_attitude():
    sc = load_scenario(SCENARIO)
    series = closed_loop.ClosedLoop(sc, 20.0).run()
    assert series['t_s'].tolist() == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0,
                                      20.0]
    # Lambda(0) = (0.36, 0.48, -0.48, 0.64): rotation angle 2 acos(0.36)
    assert series['angle_deg'][0] == pytest.approx(math.degrees(2 * math.acos(0.36)), abs=1e-9)
    # omega(0) = (-3, 3, 3) deg/s absolute
    assert series['rate_deg_s'][0] == pytest.approx(3 * math.sqrt(3), abs=1e-9)
    # N(t0) = identity, then the t = 0 sample updates it: it moves away from 138 deg
    assert 0.0 < series['est_err_deg'][0] < series['angle_deg'][0]
    assert np.all(np.isfinite(series['angle_deg'])) and set(series['active']) == {'magnetic'}
